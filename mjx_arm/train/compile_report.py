"""Where a run's start-up seconds go: named stages, and JAX's own compile events.

A cold start spends its first seconds on model conversion, the physics build (MuJoCo Warp's
kernel compiles on a GPU), tracing and compiling the XLA programs (the reset, the training epoch
and the evaluation) and the first run of each. :class:`CompileReport` times named stages and
counts what JAX reports meanwhile through :mod:`jax.monitoring`: seconds of tracing, of lowering
to MLIR and of XLA backend compiles (per program; a program found in the persistent cache counts
its loading time), and the persistent cache's requests, hits and writes.
Training prints :meth:`CompileReport.summary` and saves :meth:`CompileReport.to_dict` in the
run directory (``compile.json``).
"""

from __future__ import annotations

import threading
import time
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

TRACE = "/jax/core/compile/jaxpr_trace_duration"
LOWER = "/jax/core/compile/jaxpr_to_mlir_module_duration"
BACKEND = "/jax/core/compile/backend_compile_duration"
CACHE_HIT = "/jax/compilation_cache/cache_hits"
CACHE_MISS = "/jax/compilation_cache/cache_misses"  # a miss that was written to the cache
CACHE_USE = "/jax/compilation_cache/compile_requests_use_cache"

_ACTIVE: list[CompileReport] = []
_LOCK = threading.Lock()
_INSTALLED = False


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
        self.counts: dict[str, int] = defaultdict(int)
        self.start = time.monotonic()

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
        if key == "backend_compile":
            self.counts["programs"] += 1
            self.programs[fun_name] += seconds

    def _count(self, event: str) -> None:
        key = {CACHE_HIT: "cache_hits", CACHE_MISS: "cache_writes", CACHE_USE: "cache_requests"}
        if event in key:
            self.counts[key[event]] += 1

    def top_programs(self, count: int = 5) -> dict[str, float]:
        """The ``count`` programs with the most XLA compile seconds: name -> seconds."""
        ranked = sorted(self.programs.items(), key=lambda kv: -kv[1])
        return {name: round(s, 3) for name, s in ranked[:count]}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: stages (s), JAX totals (s), counts and the slowest programs."""
        return {
            "stages": {k: round(v, 3) for k, v in self.stages.items()},
            "jax_seconds": {k: round(v, 3) for k, v in self.seconds.items()},
            "jax_counts": dict(self.counts),
            "slowest_programs": self.top_programs(),
        }

    def summary(self) -> str:
        """One line: every stage, then JAX's compile totals and cache counts."""
        stages = ", ".join(f"{name} {s:.1f}" for name, s in self.stages.items())
        jax_part = (
            f"XLA: {self.counts.get('programs', 0)} programs compiled or loaded in "
            f"{self.seconds.get('backend_compile', 0.0):.1f} s (trace "
            f"{self.seconds.get('trace', 0.0):.1f} s, lower {self.seconds.get('lower', 0.0):.1f}"
            f" s), persistent cache {self.counts.get('cache_hits', 0)} hits of "
            f"{self.counts.get('cache_requests', 0)} requests"
        )
        return f"start-up (s): {stages}; {jax_part}"
