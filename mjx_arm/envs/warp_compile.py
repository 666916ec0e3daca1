"""Compile MuJoCo Warp's kernels in parallel before the first physics step.

Warp compiles a module (a Python file's kernels, or one generated kernel) the first time one of
its kernels launches, one module after another. Under MJX that happens inside the first call of
the step, so a cold start compiles some twenty modules in a row. :func:`precompile` compiles the
modules that stepping the task model launches on a thread pool first; the step then finds them
in Warp's kernel cache. Kernels that MuJoCo Warp generates for a given model while it steps
(modules with a hashed name) are still compiled on first use. Training starts the compiles
on a background thread (:func:`start_precompile`) so that they run while the XLA programs
trace and compile.

:data:`STEP_MODULES` lists the modules, found by stepping the task models with an empty kernel
cache and reading which modules hold a loaded binary (``benchmarks/bench_cold_start.py``
records that list per start): the same eight for Reach and Touch. Collision detection runs in
generated kernels only, so the collision files are not listed. A module missing from the
installed MuJoCo Warp is skipped.
"""

from __future__ import annotations

import time
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

PACKAGE = "mujoco.mjx.third_party.mujoco_warp._src"

STEP_MODULES: tuple[str, ...] = (
    "constraint",
    "derivative",
    "forward",
    "passive",
    "sensor",
    "smooth",
    "solver",
    "support",
)


def _cuda_devices() -> list[Any]:
    """Warp's CUDA devices that JAX uses (every local GPU); empty without a GPU, where Warp is
    not imported."""
    import jax

    gpus = [d for d in jax.local_devices() if d.platform in ("gpu", "cuda")]
    if not gpus:
        return []
    import warp as wp

    return [wp.device_from_jax(d) for d in gpus]


def precompile(threads: int, names: tuple[str, ...] = STEP_MODULES) -> float:
    """Compile and load the named MuJoCo Warp modules on every local GPU, ``threads`` at once.

    Args:
        threads: worker threads; 0 does nothing (modules compile on first use).
        names: module names relative to MuJoCo Warp's ``_src`` package.

    Returns:
        Seconds spent (0.0 when skipped: no threads, no GPU or no module found).
    """
    devices = _cuda_devices() if threads > 0 else []
    if not devices:
        return 0.0
    import warp as wp
    from warp._src.context import user_modules  # Warp's registry of imported modules

    modules = [user_modules[f"{PACKAGE}.{n}"] for n in names if f"{PACKAGE}.{n}" in user_modules]
    if not modules:
        return 0.0
    start = time.perf_counter()
    wp.force_load(device=devices, modules=modules, max_workers=threads)
    return time.perf_counter() - start


def start_precompile(threads: int, names: tuple[str, ...] = STEP_MODULES) -> Future | None:
    """:func:`precompile` on a background thread, so that the XLA programs trace and compile
    meanwhile; None where there is nothing to compile (no threads, no GPU).

    The future's result is the seconds the compiles took. Call ``result()`` before the first
    physics step runs (:meth:`mjx_arm.envs.mjx_physics.MjxPhysics.wait_precompiled`).
    """
    if threads <= 0 or not _cuda_devices():
        return None
    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="warp-precompile")
    future = pool.submit(precompile, threads, names)
    pool.shutdown(wait=False)
    return future


def loaded_modules() -> dict[str, list[int]]:
    """Every Warp module with a loaded binary: name (relative to MuJoCo Warp's package where it
    is one of its files) -> the block sizes it was built for."""
    from warp._src.context import user_modules

    out = {}
    for name, module in sorted(user_modules.items()):
        dims = sorted({dim for (_, dim) in module.execs})
        if dims:
            out[name.removeprefix(PACKAGE + ".")] = dims
    return out
