"""Helpers shared by the benchmark scripts: timing, plus the package's run metadata and result
files (:mod:`mjx_arm.bench.results`).

Every benchmark saves two files under ``benchmarks/results/``: ``<name>.json`` (the numbers and
:func:`environment_metadata`) and ``<name>.md`` (the table it printed). Typical use::

    from benchmarks.common import environment_metadata, save_results, time_repeats, summarize

    seconds = time_repeats(lambda: run(1000), repeats=5)
    rate = summarize([1000 / s for s in seconds])
    table = markdown_table(["what", "steps/s"], [["run", f"{rate['median']:.0f}"]])
    save_results("my_bench", {"meta": environment_metadata(), "rate": rate}, table)

The scripts run from the repository root as ``python -m benchmarks.<script>`` or
``python benchmarks/<script>.py``; both work.
"""

from __future__ import annotations

import gc
import os
import statistics
import subprocess
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from mjx_arm.bench.results import (  # noqa: F401  (the scripts import these from here)
    DEFAULT_PACKAGES,
    accelerator_metadata,
    cpu_model,
    environment_metadata,
    git_commit,
    markdown_table,
    package_versions,
    usable_cores,
)
from mjx_arm.bench.results import save_results as _save_results

RESULTS_DIR = Path(__file__).resolve().parent / "results"


# --------------------------------------------------------------------------- timing


def time_repeats(
    fn: Callable[[], Any],
    repeats: int,
    warmup: int = 1,
    setup: Callable[[], Any] | None = None,
) -> list[float]:
    """Wall-clock seconds of ``repeats`` calls of ``fn`` after ``warmup`` untimed calls.

    Args:
        fn: the work to time.
        repeats: timed calls.
        warmup: untimed calls first (compilation, caches).
        setup: run untimed before every call of ``fn`` (e.g. an env reset).

    The garbage collector is paused during each timed call, as :mod:`timeit` does.
    """
    return time_interleaved({"fn": fn}, repeats, warmup, {"fn": setup} if setup else None)["fn"]


def time_interleaved(
    fns: Mapping[str, Callable[[], Any]],
    repeats: int,
    warmup: int = 1,
    setups: Mapping[str, Callable[[], Any]] | None = None,
) -> dict[str, list[float]]:
    """Like :func:`time_repeats` for several functions, run side by side.

    Round ``r`` times every function once, so slow phases of a noisy machine hit all of them
    alike and the medians stay comparable.

    Args:
        fns: name -> work to time.
        repeats: timed rounds.
        warmup: untimed rounds first.
        setups: name -> untimed preparation before each call of that function.

    Returns:
        Seconds per call, per name, ``repeats`` values each.
    """
    setups = setups or {}
    for _ in range(warmup):
        for name, fn in fns.items():
            _timed(fn, setups.get(name))
    seconds: dict[str, list[float]] = {name: [] for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            seconds[name].append(_timed(fn, setups.get(name)))
    return seconds


def _timed(fn: Callable[[], Any], setup: Callable[[], Any] | None = None) -> float:
    if setup is not None:
        setup()
    enabled = gc.isenabled()
    gc.disable()
    try:
        start = time.perf_counter()
        fn()
        return time.perf_counter() - start
    finally:
        if enabled:
            gc.enable()


def compile_and_time(fn: Callable[[Any], Any], arg: Any) -> tuple[Any, float, float]:
    """Run a jitted ``fn`` twice, feeding the first output into the second call.

    Returns:
        (second output, seconds of the first call: compilation plus one run, seconds of the
        second call), each call waited for with ``jax.block_until_ready``.
    """
    import jax

    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(arg))
    compile_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(out))
    return out, compile_s, time.perf_counter() - t0


def summarize(values: Sequence[float]) -> dict[str, Any]:
    """Median, min, max and every value (in run order) of repeated measurements."""
    return {
        "median": statistics.median(values),
        "min": min(values),
        "max": max(values),
        "repeats": list(values),
    }


def rss_mb() -> float:
    """This process's resident memory (MiB), from ``/proc/self/statm`` (Linux) or ``ps``."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
        return pages * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        out = subprocess.run(
            ["ps", "-o", "rss=", "-p", str(os.getpid())], capture_output=True, text=True
        )
        return int(out.stdout.strip()) / 1024


def empty_cache_env() -> dict[str, str]:
    """Environment variables that point every compilation cache at a new, empty folder: this
    project's JAX cache, Warp's kernel cache and the CUDA driver's JIT cache (a cold start as on
    a fresh machine). Set them before JAX first touches a device."""
    import tempfile

    folders = {"MJX_ARM_JAX_CACHE": "jax", "WARP_CACHE_PATH": "warp", "CUDA_CACHE_PATH": "cuda"}
    return {var: tempfile.mkdtemp(prefix=f"{kind}_cache_") for var, kind in folders.items()}


# --------------------------------------------------------------------------- output


def save_results(
    name: str, payload: Mapping[str, Any], table_md: str, results_dir: Path | None = None
) -> tuple[Path, Path]:
    """:func:`mjx_arm.bench.results.save_results` into ``results_dir`` (default
    ``benchmarks/results``)."""
    return _save_results(name, payload, table_md, results_dir or RESULTS_DIR)
