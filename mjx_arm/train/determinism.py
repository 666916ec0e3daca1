"""Same seed, same run: what ``deterministic = true`` switches on, and the check that a run
repeats.

A training run on a CPU (the C MuJoCo batch, or MJX's JAX physics under XLA's CPU backend) is
already the same from run to run: its floating-point sums happen in a fixed order. On a GPU two
things reorder sums from run to run:

- XLA's GPU kernels that reduce with atomics (scatter-adds, some reductions):
  ``--xla_gpu_deterministic_ops=true`` picks deterministic kernels for them;
- MuJoCo Warp's kernels, which allocate contacts and constraint rows and sum forces with
  atomics: Warp's ``wp.config.deterministic = wp.DeterministicMode.RUN_TO_RUN`` orders those
  atomics.

Both must be set before the GPU backend starts and before Warp builds its modules, so
:func:`enable` runs at the start of a training, before any device is touched. The guarantee is
for the same seed, config, GPU model, device count and package versions; another GPU model or
another version is not covered.
"""

from __future__ import annotations

import os
import warnings

XLA_FLAG = "--xla_gpu_deterministic_ops=true"


def enable() -> dict[str, str]:
    """Switch deterministic execution on for this process (idempotent).

    Returns:
        What was set: ``{"xla": flag state, "warp": mode or why not}``.
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
    return {"xla": XLA_FLAG, "warp": _warp_deterministic()}


def _gpu_backend_started() -> bool:
    """Whether JAX already made a GPU backend in this process (too late for XLA_FLAGS)."""
    try:
        from jax._src import xla_bridge
    except ImportError:  # pragma: no cover - JAX's internals moved
        return False
    backends = getattr(xla_bridge, "_backends", {}) or {}
    return any(name in ("cuda", "gpu", "rocm") for name in backends)


def _warp_deterministic() -> str:
    """Set Warp's run-to-run deterministic atomics where Warp is installed; what was done."""
    try:
        import warp as wp
    except ImportError:
        return "not installed"
    mode = getattr(wp, "DeterministicMode", None)
    if mode is None:
        return f"not supported by warp {getattr(wp, '__version__', '?')}"
    wp.config.deterministic = mode.RUN_TO_RUN
    return "RUN_TO_RUN"
