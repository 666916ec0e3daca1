"""Where a run's start-up seconds go: named stages, and JAX's own compile events.

A cold start spends its first seconds on model conversion, the physics build (MuJoCo Warp's
kernel compiles on a GPU), tracing and compiling the XLA programs (the reset, the training epoch
and the evaluation) and the first run of each. :class:`CompileReport` times named stages and
counts what JAX reports meanwhile through :mod:`jax.monitoring`: seconds of tracing, of lowering
to MLIR and of XLA backend compiles (per program; a program found in the persistent cache counts
its loading time), and the persistent cache's requests, hits and writes.
Training prints :meth:`CompileReport.summary` and saves :meth:`CompileReport.to_dict` in the
run directory (``compile.json``).

One figure is "the compile time" everywhere (the start-up line, the progress bar, ``compile_s``
in ``compile.json`` and :attr:`~mjx_arm.train.ppo.TrainResult.compile_seconds`): the wall
seconds of the stages in :data:`COMPILE_STAGES`, from the envs built to every program ready to
run. JAX's own per-program seconds are kept apart (``jax_seconds``): XLA compiles the programs
at the same time, so their sum exceeds the wall time they took.
"""

from __future__ import annotations

import json
import threading
import time
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any

TRACE = "/jax/core/compile/jaxpr_trace_duration"
LOWER = "/jax/core/compile/jaxpr_to_mlir_module_duration"
BACKEND = "/jax/core/compile/backend_compile_duration"
CACHE_HIT = "/jax/compilation_cache/cache_hits"
CACHE_MISS = "/jax/compilation_cache/cache_misses"  # a miss that was written to the cache
CACHE_USE = "/jax/compilation_cache/compile_requests_use_cache"

# The stages whose wall seconds make the compile time (they run one after another).
COMPILE_STAGES = ("learner init", "trace + lower", "XLA compile (in parallel)", "waited for Warp")

_ACTIVE: list[CompileReport] = []
# Wall clock times (``time.time()``) of the steps of this process's start before the trainer
# opens its report (:func:`mark`): where the seconds before training go.
_MARKS: dict[str, float] = {}
_LOCK = threading.Lock()
_INSTALLED = False


def mark(name: str) -> None:
    """Note that this process has just finished start-up step ``name`` (imports, reading the
    config, starting the devices); the next report opened takes the marks, so a second training
    in the same process records only the marks made since the first report opened."""
    _MARKS[name] = time.time()


def _on_duration(event: str, seconds: float, **kwargs: Any) -> None:
    for report in list(_ACTIVE):
        report._duration(event, seconds, str(kwargs.get("fun_name", "")))


def _on_event(event: str, **_: Any) -> None:
    for report in list(_ACTIVE):
        report._count(event)


def _install() -> None:
    """Register the module's JAX listeners once per process (JAX keeps them for good)."""
    global _INSTALLED
    with _LOCK:
        if _INSTALLED:
            return
        from jax import monitoring

        monitoring.register_event_duration_secs_listener(_on_duration)
        monitoring.register_event_listener(_on_event)
        _INSTALLED = True


class CompileReport:
    """Named stage times and JAX's compile events while the report is open.

    Stages may nest or overlap (the XLA compiles run beside MuJoCo Warp's kernel compiles);
    each stage's time is its own wall time. Typical use::

        report = CompileReport().open()
        with report.stage("build env"):
            env = make_env()
        report.close()
        print(report.summary())
    """

    def __init__(self) -> None:
        self.stages: dict[str, float] = {}
        # XLA backend seconds per program: compiling it, or loading it from the persistent cache
        self.programs: dict[str, float] = defaultdict(float)
        self.seconds: dict[str, float] = defaultdict(float)  # trace / lower / backend totals
        self.traced: dict[str, float] = defaultdict(float)  # trace + lower seconds per program
        self.counts: dict[str, int] = defaultdict(int)
        self.kept: list[str] = []  # what a warm trainer kept from a run before (train.warm)
        self.start = time.monotonic()
        self.opened_at = time.time()  # wall clock (s since the epoch), for other processes
        self.marks = dict(_MARKS)  # the start-up steps before it (wall clock), taken
        _MARKS.clear()

    def open(self) -> CompileReport:
        """Start listening to JAX's compile events; returns self."""
        _install()
        _ACTIVE.append(self)
        return self

    def close(self) -> None:
        """Stop listening."""
        if self in _ACTIVE:
            _ACTIVE.remove(self)

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """Time the block as stage ``name`` (added to any earlier time of that name)."""
        start = time.monotonic()
        try:
            yield
        finally:
            self.add(name, time.monotonic() - start)

    def add(self, name: str, seconds: float) -> None:
        """Add ``seconds`` to stage ``name``."""
        self.stages[name] = self.stages.get(name, 0.0) + float(seconds)

    def _duration(self, event: str, seconds: float, fun_name: str) -> None:
        key = {TRACE: "trace", LOWER: "lower", BACKEND: "backend_compile"}.get(event)
        if key is None:
            return
        self.seconds[key] += seconds
        if key != "backend_compile":  # JAX names a program "f" when tracing, "jit(f)" lowering
            self.traced[fun_name.removeprefix("jit(").removesuffix(")")] += seconds
        else:
            self.counts["programs"] += 1
            self.programs[fun_name] += seconds

    def _count(self, event: str) -> None:
        key = {CACHE_HIT: "cache_hits", CACHE_MISS: "cache_writes", CACHE_USE: "cache_requests"}
        if event in key:
            self.counts[key[event]] += 1

    @property
    def compile_seconds(self) -> float:
        """The run's compile time: wall seconds of the :data:`COMPILE_STAGES` it went through."""
        return sum(self.stages.get(name, 0.0) for name in COMPILE_STAGES)

    def top_programs(self, count: int = 5, traced: bool = False) -> dict[str, float]:
        """The ``count`` programs with the most XLA compile seconds (``traced``: the most
        seconds of tracing and lowering to MLIR): name -> seconds."""
        seconds = self.traced if traced else self.programs
        ranked = sorted(seconds.items(), key=lambda kv: -kv[1])
        return {name: round(s, 3) for name, s in ranked[:count]}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the compile time (s), when the report opened (``time.time()``, at the
        trainer's start) and the start-up steps before it were done (``marks``), stages (s),
        JAX totals (s, summed over programs compiled at the same time), counts and the slowest
        programs to compile and to trace and lower."""
        return {
            "compile_s": round(self.compile_seconds, 3),
            "opened_at": round(self.opened_at, 3),
            "marks": {k: round(v, 3) for k, v in self.marks.items()},
            "compile_stages": [name for name in COMPILE_STAGES if name in self.stages],
            "stages": {k: round(v, 3) for k, v in self.stages.items()},
            "jax_seconds": {k: round(v, 3) for k, v in self.seconds.items()},
            "jax_counts": dict(self.counts),
            "slowest_programs": self.top_programs(),
            "slowest_traces": self.top_programs(traced=True),
            **({"kept_warm": list(self.kept)} if self.kept else {}),
        }

    def summary(self) -> str:
        """One line: the compile time and its stages, the other start-up stages, the programs
        and the persistent cache's hits, e.g. ``compiled in 74.8 s (learner init 5.1,
        trace + lower 6.6, XLA compile (in parallel) 63.1); other start-up (s): build env 0.7,
        first epoch run 19.1; 22 programs, persistent cache 0 hits of 22 requests``."""
        parts = [(n, s) for n, s in self.stages.items() if n in COMPILE_STAGES]
        others = [(n, s) for n, s in self.stages.items() if n not in COMPILE_STAGES]
        line = f"compiled in {self.compile_seconds:.1f} s"
        if parts:
            line += " (" + ", ".join(f"{name} {s:.1f}" for name, s in parts) + ")"
        if others:
            line += "; other start-up (s): " + ", ".join(f"{n} {s:.1f}" for n, s in others)
        if self.kept:
            line += f"; kept warm from an earlier run: {', '.join(self.kept)}"
        return (
            f"{line}; {self.counts.get('programs', 0)} programs, persistent cache "
            f"{self.counts.get('cache_hits', 0)} hits of {self.counts.get('cache_requests', 0)} "
            "requests"
        )


# --------------------------------------------------------------------------- the last run's figure

TIMES_FILE = "compile_times.json"  # in the JAX cache folder: setup -> compile seconds


def _times_path() -> Path:
    from mjx_arm.jax_cache import cache_folder

    return cache_folder() / TIMES_FILE


def expected_compile(setup: str) -> float | None:
    """The compile time (s) the last run of ``setup`` took (:func:`remember_compile`), or None
    (none yet, or the file is unreadable)."""
    try:
        seconds = json.loads(_times_path().read_text()).get(setup)
    except (OSError, ValueError, AttributeError):
        return None
    return float(seconds) if isinstance(seconds, int | float) and seconds >= 0 else None


def remember_compile(setup: str, seconds: float) -> None:
    """Keep ``seconds`` as the compile time of ``setup`` for the next run's progress bar. A
    folder that cannot be written is skipped: the figure is a courtesy, not a result."""
    from mjx_arm.inputs import OutputWriteError, write_atomic

    path = _times_path()
    try:
        times = json.loads(path.read_text()) if path.is_file() else {}
    except (OSError, ValueError):
        times = {}
    times = times if isinstance(times, dict) else {}
    times[setup] = round(float(seconds), 1)
    with suppress(OutputWriteError):
        write_atomic(json.dumps(times, indent=1, sort_keys=True).encode(), path)
