"""Typed settings of the batched physics: which MJX implementation steps it, and its buffers.

Kept free of heavy imports so that configs load without JAX or MuJoCo.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

IMPLS = ("auto", "jax", "warp")


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
    """

    impl: str = "auto"
    naconmax_per_env: int = 0
    njmax: int = 0

    def __post_init__(self) -> None:
        if self.impl not in IMPLS:
            raise ValueError(f"physics.impl must be one of {IMPLS}, got {self.impl!r}")
        if self.naconmax_per_env < 0 or self.njmax < 0:
            raise ValueError("physics.naconmax_per_env and physics.njmax must be >= 0")

    def replace(self, **changes: Any) -> PhysicsConfig:
        """A copy with fields changed."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PhysicsConfig:
        """Inverse of :meth:`to_dict`; unknown keys are an error."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"unknown physics config keys: {sorted(unknown)}")
        return cls(**data)


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
        ValueError: an unknown name, or ``warp`` without warp-lang installed.
    """
    if impl not in IMPLS:
        raise ValueError(f"physics.impl must be one of {IMPLS}, got {impl!r}")
    if impl == "auto":
        import jax

        on_gpu = jax.default_backend() in ("gpu", "cuda")
        return "warp" if on_gpu and warp_available() else "jax"
    if impl == "warp" and not warp_available():
        raise ValueError(
            "physics.impl=warp needs warp-lang: pip install 'mjx_arm[gpu]' "
            "(or choose physics.impl=jax)"
        )
    return impl
