"""Typed settings of the batched env: the MJX implementation and its buffers, and the domain
randomisation (:mod:`mjx_arm.envs.randomization` applies it).

Kept free of heavy imports so that configs load without JAX or MuJoCo.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from mjx_arm.inputs import ConfigError
from mjx_arm.names import IMPLS
from mjx_arm.settings import check_range, check_types, config_fields


@dataclass(frozen=True)
class PhysicsConfig:
    """How the MJX backend steps the task model. Saved with every run (``config.json``).

    Attributes:
        impl: "warp" (MuJoCo Warp kernels behind one FFI call), "jax" (MJX's XLA
            implementation) or "auto": warp where ``mujoco.mjx`` can load Warp and a GPU is
            present, jax otherwise.
        naconmax_per_env: Warp only. Contacts reserved per env in Warp's contact pool, which all
            envs of a batch share; 0 takes the model's bound (every collision pair the model
            allows, each with its largest contact count), so the pool cannot overflow.
        njmax: Warp only. Constraint rows per env; 0 takes the model's bound (all contacts
            and joint limits active at once).
        compile_threads: Warp only. Threads that compile MuJoCo Warp's kernels before the first
            step (:mod:`mjx_arm.envs.warp_compile`); 0 leaves Warp to compile each module on
            first use, one at a time.
    """

    impl: str = "auto"
    naconmax_per_env: int = 0
    njmax: int = 0
    compile_threads: int = 8

    def __post_init__(self) -> None:
        check_types(self, "physics.")
        if self.impl not in IMPLS:
            raise ConfigError(f"physics.impl must be one of {IMPLS}, got {self.impl!r}")
        check_range(self, ("naconmax_per_env", "njmax"), low=0, high=2**16, prefix="physics.")
        check_range(self, "compile_threads", low=0, high=256, prefix="physics.")

    def replace(self, **changes: Any) -> PhysicsConfig:
        """A copy with fields changed."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PhysicsConfig:
        """Inverse of :meth:`to_dict`; unknown keys are an error."""
        return cls(**config_fields(cls, data, "physics config"))


Range = tuple[float, float]


@dataclass(frozen=True)
class RandomizationConfig:
    """Ranges of the domain randomisation (multipliers are uniform in ``(low, high)``).

    Attributes:
        enabled: randomise at all (off: every env steps the nominal model, no noise or delay).
        friction: multiplier of every geom's friction.
        damping: multiplier of each joint's damping (drawn per joint).
        armature: multiplier of each joint's rotor inertia (per joint).
        gain: multiplier of each velocity servo's gain (per joint).
        box_offset: half-width (m) of the uniform x/y offset of the box from its observed place.
        ft_force_noise: standard deviation (N) of the noise on the observed force.
        ft_torque_noise: standard deviation (N m) of the noise on the observed torque.
        latency_prob: probability that an episode applies each action one control step late.
    """

    enabled: bool = False
    friction: Range = (0.7, 1.3)
    damping: Range = (0.7, 1.3)
    armature: Range = (0.7, 1.3)
    gain: Range = (0.8, 1.2)
    box_offset: float = 0.005
    ft_force_noise: float = 0.5
    ft_torque_noise: float = 0.02
    latency_prob: float = 0.3

    def __post_init__(self) -> None:
        check_types(self, "randomization.")
        ranges = ("friction", "damping", "armature", "gain")
        check_range(self, ranges, low=0, prefix="randomization.")
        for name in ranges:
            low, high = getattr(self, name)
            if low > high:
                raise ConfigError(f"randomization.{name} must be (low, high), low <= high")
        noises = ("box_offset", "ft_force_noise", "ft_torque_noise")
        check_range(self, noises, low=0, prefix="randomization.")
        check_range(self, "latency_prob", low=0, high=1, prefix="randomization.")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RandomizationConfig:
        """Inverse of :meth:`to_dict`; unknown keys are an error."""
        return cls(**config_fields(cls, data, "randomization config"))


def warp_available() -> bool:
    """True when ``mujoco.mjx`` can run its Warp implementation (warp-lang importable)."""
    import importlib.util

    if importlib.util.find_spec("warp") is None:  # checked first: mjx prints when it is absent
        return False
    from mujoco.mjx import warp as mjx_warp

    return bool(mjx_warp.WARP_INSTALLED)


def resolve_impl(impl: str) -> str:
    """``auto`` -> ``warp`` on a CUDA GPU with Warp installed, else ``jax``; checks names.

    Raises:
        ConfigError: an unknown name, or ``warp`` without warp-lang installed.
    """
    if impl not in IMPLS:
        raise ConfigError(f"physics.impl must be one of {IMPLS}, got {impl!r}")
    if impl == "auto":
        import jax

        on_gpu = jax.default_backend() in ("gpu", "cuda")
        return "warp" if on_gpu and warp_available() else "jax"
    if impl == "warp" and not warp_available():
        raise ConfigError(
            "physics.impl=warp needs warp-lang: pip install 'mjx_arm[gpu]' "
            "(or choose physics.impl=jax)"
        )
    return impl
