"""Same seed, same run: what ``deterministic = true`` switches on, and the check that a run
repeats.

A training run on a CPU (the C MuJoCo batch, or MJX's JAX physics under XLA's CPU backend) is
already the same from run to run: its floating-point sums happen in a fixed order. On a GPU two
things reorder sums from run to run:

- XLA's GPU kernels that reduce with atomics (scatter-adds, some reductions):
  ``--xla_gpu_deterministic_ops=true`` picks deterministic kernels for them;
- MuJoCo Warp's kernels, which allocate contacts and constraint rows and sum forces with
  atomics. Warp 1.19 has a run-to-run deterministic mode for atomics
  (``wp.config.deterministic``), but it refuses a kernel of the MuJoCo Warp that mujoco-mjx
  3.17 ships (:data:`WARP_REFUSAL`), so a deterministic run steps MJX's JAX physics instead
  (:func:`check_physics` says so before anything compiles).

XLA's flag must be set before the GPU backend starts, so :func:`enable` runs at the start of a
training, before any device is touched. The guarantee is for the same seed, config, GPU model,
device count and package versions; another GPU model or another version is not covered.
"""

from __future__ import annotations

import os
import warnings
from typing import Any

from mjx_arm.inputs import ConfigError

XLA_FLAG = "--xla_gpu_deterministic_ops=true"

# What Warp 1.19's deterministic mode said of mujoco-mjx 3.17's MuJoCo Warp (measured on H200s,
# benchmarks/results/determinism/repeat_touch_fast.json).
WARP_REFUSAL = (
    "Warp's deterministic mode refuses MuJoCo Warp's line-search kernel (mujoco_warp "
    "solver.py:1407: efc_Ma_out is updated atomically and read directly in one kernel)"
)


def enable() -> dict[str, str]:
    """Switch deterministic execution on for this process (idempotent).

    Returns:
        What was set: ``{"xla": the flag}``.
    """
    flags = os.environ.get("XLA_FLAGS", "")
    if XLA_FLAG not in flags:
        if _gpu_backend_started():
            warnings.warn(
                "deterministic: the GPU backend started before XLA's deterministic ops could be "
                "set; set XLA_FLAGS=--xla_gpu_deterministic_ops=true before running",
                stacklevel=2,
            )
        os.environ["XLA_FLAGS"] = f"{flags} {XLA_FLAG}".strip()
    return {"xla": XLA_FLAG}


def deterministic_physics(config: Any) -> Any:
    """``config`` (a deterministic training config) on physics that repeats: MJX's JAX physics
    where ``physics.impl=auto`` would pick MuJoCo Warp.

    Raises:
        ConfigError: MuJoCo Warp asked for by name (``physics.impl=warp``).
    """
    from mjx_arm.envs.backend import resolve_backend
    from mjx_arm.envs.physics_config import resolve_impl

    if resolve_backend(config.backend) != "mjx" or resolve_impl(config.physics.impl) != "warp":
        return config
    if config.physics.impl == "auto":
        print("deterministic: MJX steps the JAX physics (MuJoCo Warp cannot repeat a run)")
        return config.replace(physics=config.physics.replace(impl="jax"))
    check_physics("mjx", "warp")
    return config


def check_physics(backend: str, impl: str) -> None:
    """Refuse a deterministic run on physics that cannot repeat.

    Args:
        backend: the resolved backend ("mjx" or "mujoco").
        impl: the resolved MJX implementation ("warp" or "jax").

    Raises:
        ConfigError: MJX on MuJoCo Warp.
    """
    if backend == "mjx" and impl == "warp":
        raise ConfigError(
            f"--deterministic cannot run on MuJoCo Warp: {WARP_REFUSAL}; add --set "
            "physics.impl=jax (MJX's JAX physics repeats bit for bit, at about half Warp's "
            "speed) or drop --deterministic"
        )


def _gpu_backend_started() -> bool:
    """Whether JAX already made a GPU backend in this process (too late for XLA_FLAGS)."""
    try:
        from jax._src import xla_bridge
    except ImportError:  # pragma: no cover - JAX's internals moved
        return False
    backends = getattr(xla_bridge, "_backends", {}) or {}
    return any(name in ("cuda", "gpu", "rocm") for name in backends)
