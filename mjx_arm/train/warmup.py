"""Fill the compilation caches ahead of time: ``mjx-arm warmup --task T [--arm A]``.

A training run's start-up compiles its XLA programs (JAX's persistent cache keeps them) and,
on a GPU, MuJoCo Warp's kernels (Warp's kernel cache keeps them). :func:`warm_up` runs one
short training of the very same programs (the run's config, stopped after its first epoch
and evaluation) in a throw-away run directory, so both caches hold everything a later run of
that task, arm and preset needs; a new process then loads instead of compiling. Any seed
finds the same programs (seeds enter as keys, not as constants).

The caches are folders (:func:`cache_locations`) that can be copied into a container image or
shared by a cluster's jobs; each is moved with its environment variable.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from mjx_arm.jax_cache import cache_folder
from mjx_arm.train.config import TrainConfig

# Each cache a start-up fills: (what it holds, its environment variable).
CACHES = (
    ("JAX compiled programs (XLA)", "MJX_ARM_JAX_CACHE"),
    ("MuJoCo Warp kernels", "WARP_CACHE_PATH"),
    ("CUDA driver JIT cache", "CUDA_CACHE_PATH"),
)


def warp_cache_folder() -> str:
    """Warp's kernel cache folder: ``WARP_CACHE_PATH``, else Warp's default (where Warp is
    installed), else a note that Warp is not installed."""
    if os.environ.get("WARP_CACHE_PATH"):
        return os.environ["WARP_CACHE_PATH"]
    import importlib.util

    if importlib.util.find_spec("warp") is None:
        return "(warp-lang not installed: no Warp kernels)"
    import warp as wp

    wp.init()
    return str(wp.config.kernel_cache_dir)


def cache_locations() -> dict[str, str]:
    """Cache name -> ``folder (set VARIABLE to move it)`` for every cache a start-up fills."""
    folders = {
        "MJX_ARM_JAX_CACHE": str(cache_folder()),
        "WARP_CACHE_PATH": warp_cache_folder(),
        "CUDA_CACHE_PATH": os.environ.get(
            "CUDA_CACHE_PATH", str(Path.home() / ".nv" / "ComputeCache")
        ),
    }
    return {what: f"{folders[var]} (set {var} to move it)" for what, var in CACHES}


def warm_up(config: TrainConfig, quiet: bool = True):
    """Train ``config`` for one epoch in a temporary run directory: every program a run of it
    compiles lands in the caches. Returns the short run's
    :class:`~mjx_arm.train.ppo.TrainResult` (its ``compile_report`` says what was compiled).
    """
    from mjx_arm.train.ppo import train

    with tempfile.TemporaryDirectory(prefix="mjx_arm_warmup_") as folder:
        return train(config, Path(folder) / "run", quiet=quiet, stop_after=1)
