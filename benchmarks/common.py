"""Helpers shared by the benchmark scripts: run metadata, timing, tables and result files.

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

import datetime as _dt
import gc
import importlib.metadata
import json
import os
import platform
import statistics
import subprocess
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

RESULTS_DIR = Path(__file__).resolve().parent / "results"
DEFAULT_PACKAGES = (
    "mujoco",
    "mujoco-mjx",
    "warp-lang",
    "pybullet",
    "gymnasium",
    "numpy",
    "jax",
    "brax",
)

# --------------------------------------------------------------------------- metadata


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo`` on Linux, else :func:`platform.processor`)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def usable_cores() -> int:
    """CPU cores this process may run on (affinity mask where available)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def package_versions(packages: Iterable[str] = DEFAULT_PACKAGES) -> dict[str, str | None]:
    """Installed version of each distribution, ``None`` where it is not installed."""
    versions: dict[str, str | None] = {}
    for name in packages:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def git_commit() -> str | None:
    """The checkout's commit (with ``-dirty`` when files changed), or None outside git."""
    root = Path(__file__).resolve().parent.parent
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain"], cwd=root, capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return f"{commit}-dirty" if dirty else commit


def accelerator_metadata() -> dict[str, Any]:
    """JAX's backend and devices (kind, count); imports jax, so call it only for JAX runs."""
    import jax

    devices = jax.devices()
    return {
        "backend": jax.default_backend(),
        "device_kind": devices[0].device_kind,
        "device_count": len(devices),
    }


def environment_metadata(
    packages: Iterable[str] = DEFAULT_PACKAGES, accelerator: bool = False
) -> dict[str, Any]:
    """What a result needs to be compared later: machine, software versions, date, commit.

    Args:
        packages: distributions whose versions to record.
        accelerator: also record JAX's devices (imports jax).

    Returns:
        A JSON-ready dict: ``device`` (kind, CPU model, cores), ``python``, ``packages``,
        ``platform``, ``load_average_1min``, ``date`` (UTC, ISO 8601), ``git_commit``.
    """
    meta: dict[str, Any] = {
        "device": {
            "kind": "cpu",
            "cpu_model": cpu_model(),
            "cores": usable_cores(),
            "cpu_count": os.cpu_count(),
        },
        "python": platform.python_version(),
        "packages": package_versions(packages),
        "platform": platform.platform(),
        # 1-minute load average at the start: other work on the machine skews CPU timings
        "load_average_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
        "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "git_commit": git_commit(),
    }
    if accelerator:
        acc = accelerator_metadata()
        meta["accelerator"] = acc
        if acc["backend"] != "cpu":
            meta["device"]["kind"] = acc["device_kind"]
    return meta


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


# --------------------------------------------------------------------------- output


def markdown_table(headers: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    """A GitHub markdown table; cells are formatted with ``str``."""
    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def save_results(
    name: str, payload: Mapping[str, Any], table_md: str, results_dir: Path | None = None
) -> tuple[Path, Path]:
    """Write ``<name>.json`` (``payload``) and ``<name>.md`` (``table_md``) to the results folder.

    Args:
        name: file stem, e.g. ``"cpu_envs"``.
        payload: JSON-serialisable numbers (numpy scalars are converted).
        table_md: the markdown the benchmark printed.
        results_dir: where to write (default ``benchmarks/results``).

    Returns:
        The paths of the JSON and markdown files.
    """
    folder = Path(results_dir or RESULTS_DIR)
    folder.mkdir(parents=True, exist_ok=True)
    json_path, md_path = folder / f"{name}.json", folder / f"{name}.md"
    json_path.write_text(json.dumps(payload, indent=2, default=_json_default) + "\n")
    md_path.write_text(table_md if table_md.endswith("\n") else table_md + "\n")
    return json_path, md_path


def _json_default(value: Any) -> Any:
    """numpy scalars and arrays, paths: the JSON encoder's fallback."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
