"""Compile the MuJoCo Warp kernels a task model steps with, all at once, before its first step.

Warp compiles a module the first time one of its kernels launches, one module after another.
MuJoCo Warp generates most of its kernels for the model at hand (one module per kernel, named
with a hash of its code: collision, constraint and solver kernels sized to the model), so under
MJX a cold start compiled some thirty modules in a row inside the first physics call, and an arm
with mesh collisions spent most of its start there (its convex-collision kernels are the
largest).

:func:`step_loads` finds those modules without compiling anything: it runs MuJoCo Warp's
``forward`` and ``step`` once in Python on the model built as MJX builds it, with Warp's module
loader swapped for one that notes the module and its block size and loads nothing (a launch
whose module did not load returns without running). Conditional graph nodes take both branches
and loops one pass, so every kernel the step can launch is noted. :func:`precompile` then
compiles the noted modules on one thread pool, slowest first (NVRTC runs outside Python's
lock), and the first step finds them loaded. Training starts the compiles on a background thread
(:func:`start_precompile`) so that they run while the XLA programs trace and compile.
"""

from __future__ import annotations

import contextlib
import time
import warnings
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import mujoco

PACKAGE = "mujoco.mjx.third_party.mujoco_warp._src"

# block size -> the modules to build at it
Loads = dict[int, list[Any]]


def cuda_devices() -> list[Any]:
    """Warp's CUDA devices that JAX uses (every local GPU); empty without a GPU, where Warp is
    not imported."""
    import jax

    gpus = [d for d in jax.local_devices() if d.platform in ("gpu", "cuda")]
    if not gpus:
        return []
    import warp as wp

    return [wp.device_from_jax(d) for d in gpus]


@contextlib.contextmanager
def _noting_loads(noted: set[tuple[Any, int]]) -> Iterator[None]:
    """Within the block, Warp loads no module: each load is noted as (module, block size) and
    returns nothing, so launches return without running. Conditional graph nodes run both of
    their bodies and loops one pass, and occupancy queries answer (256, 1)."""
    import warp as wp
    from warp._src import context

    saved = (context.Module.load, wp.get_suggested_block_size, wp.capture_if, wp.capture_while)

    def load(module: Any, device: Any, block_dim: int | None = None, *_: Any, **__: Any) -> None:
        noted.add((module, int(block_dim or module.options.get("block_dim", 256))))

    def suggested_block_size(kernel: Any, device: Any = None) -> tuple[int, int]:
        load(kernel.module, device)
        return 256, 1

    def capture_if(condition: Any, on_true: Any = None, on_false: Any = None, **kwargs: Any):
        for body in (on_true, on_false):
            if callable(body):
                body(**kwargs)

    def capture_while(condition: Any, while_body: Any, stream: Any = None, **kwargs: Any):
        while_body(**kwargs)

    context.Module.load = load
    wp.get_suggested_block_size = suggested_block_size
    wp.capture_if, wp.capture_while = capture_if, capture_while
    try:
        yield
    finally:
        context.Module.load, wp.get_suggested_block_size, wp.capture_if, wp.capture_while = saved


def step_loads(mj_model: mujoco.MjModel, naconmax: int, njmax: int, device: Any) -> Loads:
    """The Warp modules that ``mjx.forward`` and ``mjx.step`` of ``mj_model`` launch on
    ``device``, found without compiling any (about a second).

    Args:
        mj_model: the model as handed to ``mjx.put_model(impl="warp")``.
        naconmax: contacts of the batch's shared pool; njmax: constraint rows per env.
        device: the Warp device the step will run on (its kind picks some kernels).

    Returns:
        Block size -> the modules launched at it, already loaded ones included.
    """
    import warp as wp
    from mujoco.mjx.third_party import mujoco_warp as mjw

    with wp.ScopedDevice("cpu"):  # as mjx.put_model and mjx.make_data build them
        model = mjw.put_model(mj_model)
        data = mjw.make_data(mj_model, nworld=1, naconmax=naconmax, njmax=njmax)
    model.opt.warn_overflow = 0  # as MjxPhysics sets it: the flag is compiled into kernels
    noted: set[tuple[Any, int]] = set()
    with wp.ScopedDevice(device), _noting_loads(noted):
        mjw.forward(model, data)
        mjw.step(model, data)
    loads: Loads = {}
    for module, block_dim in sorted(noted, key=lambda item: (item[1], item[0].name)):
        loads.setdefault(block_dim, []).append(module)
    return loads


def try_step_loads(mj_model: mujoco.MjModel, naconmax: int, njmax: int, device: Any) -> Loads:
    """:func:`step_loads`, or no loads with a warning where the dry pass fails (a MuJoCo Warp
    or Warp release that launches differently): the modules then compile on first use."""
    try:
        return step_loads(mj_model, naconmax, njmax, device)
    except Exception as error:  # any failure only costs the parallel compile
        warnings.warn(
            f"could not list MuJoCo Warp's kernels ahead of the first step ({error!r}); "
            "they compile one after another when it runs",
            RuntimeWarning,
            stacklevel=2,
        )
        return {}


def _targets(threads: int, loads: Loads, devices: list[Any] | None) -> list[Any]:
    """The devices to compile ``loads`` on: ``devices`` (None: :func:`cuda_devices`), or none
    where there is nothing to do (no threads or no loads)."""
    if threads <= 0 or not loads:
        return []
    return cuda_devices() if devices is None else devices


# MuJoCo Warp's module families whose compile took longest on an H100, slowest first
# (benchmarks/results/cold_start/warp_kernels_*.json: the convex-collision kernels about 50 s,
# the Newton solver's Cholesky update 22.7 s, the narrow and broad phase 19.2 and 18.5 s, the
# joint-limit constraints 16.6 s, the passive and smooth forces 15.7 and 15.6 s). Started first,
# they set the compile's critical path instead of joining it late.
SLOW_FIRST = (
    "ccd_kernel",
    "_update_gradient_cholesky",
    "_primitive_narrowphase",
    "_nxn_broadphase",
    "_limit_slide_hinge",
    "_qfrc_passive_kernel",
    "_qfrc_smooth",
)


def compile_order(loads: Loads) -> list[tuple[Any, int]]:
    """Every (module, block size) of ``loads`` in the order to compile them: the families of
    :data:`SLOW_FIRST` first (in its order), then the rest as listed."""
    jobs = [(module, block_dim) for block_dim, modules in loads.items() for module in modules]

    def rank(job: tuple[Any, int]) -> int:
        name = job[0].name
        return next((i for i, f in enumerate(SLOW_FIRST) if f in name), len(SLOW_FIRST))

    return sorted(jobs, key=rank)


def precompile(threads: int, loads: Loads, devices: list[Any] | None = None) -> float:
    """Compile and load ``loads`` on ``devices`` (default: every local GPU), ``threads`` at once.

    Every module of every block size goes to one thread pool, slowest first
    (:func:`compile_order`), so the longest compiles start at once (a block size at a time,
    each size's slowest module would add to the wall time). The first device compiles; the
    others then load the binaries from Warp's kernel cache.

    Args:
        threads: worker threads; 0 does nothing (modules compile on first use).
        loads: from :func:`step_loads`.
        devices: Warp devices; None takes :func:`cuda_devices`.

    Returns:
        Seconds spent (0.0 when skipped: no threads, no device or nothing to load).
    """
    devices = _targets(threads, loads, devices)
    if not devices:
        return 0.0
    start = time.perf_counter()
    jobs = compile_order(loads)
    with ThreadPoolExecutor(max_workers=threads, thread_name_prefix="warp-compile") as pool:
        for device in devices:  # the first compiles, the next find the cache filled
            list(pool.map(lambda job, device=device: job[0].load(device, job[1]), jobs))
    return time.perf_counter() - start


def start_precompile(threads: int, loads: Loads, devices: list[Any] | None = None) -> Future | None:
    """:func:`precompile` on a background thread, so that the XLA programs trace and compile
    meanwhile; None where there is nothing to compile (no threads, no device, no loads).

    The future's result is the seconds the compiles took. Call ``result()`` before the first
    physics step runs (:meth:`mjx_arm.envs.mjx_physics.MjxPhysics.wait_precompiled`).
    """
    devices = _targets(threads, loads, devices)
    if not devices:
        return None
    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="warp-precompile")
    future = pool.submit(precompile, threads, loads, devices)
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
