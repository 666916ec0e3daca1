"""Fixes from a newcomer's walk of the CPU docs: output that keeps moving during long steps."""

from __future__ import annotations

import io
import time

from tqdm import tqdm

from mjx_arm.train.compile_report import CompileReport
from mjx_arm.train.progress import CompileClock


def _wait_for(condition, seconds: float = 3.0) -> bool:
    deadline = time.monotonic() + seconds
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.02)
    return condition()


def test_the_bar_is_redrawn_between_evaluations(monkeypatch) -> None:
    """An epoch of Touch's cpu preset runs for a minute on 2 cores and the bar moves only at an
    evaluation: after the compile the clock redraws it (its elapsed time) until stopped."""
    monkeypatch.setattr(CompileClock, "HEARTBEAT_S", 0.05)
    out = io.StringIO()
    bar = tqdm(total=10, desc="train touch", file=out, mininterval=0)
    report = CompileReport()
    clock = CompileClock(bar, "train touch", report, None).begin()
    try:
        clock.compiled()  # the first epoch ran
        assert _wait_for(lambda: bar.desc == "train touch")
        drawn = len(out.getvalue())
        assert _wait_for(lambda: len(out.getvalue()) > drawn)  # no update(), yet redrawn
    finally:
        clock.stop()
    stopped = len(out.getvalue())
    time.sleep(0.2)
    assert len(out.getvalue()) == stopped  # stop() ends the redraws
    bar.close()


def test_the_compile_stage_ends_the_compiling_text_and_starts_the_redraws(monkeypatch) -> None:
    monkeypatch.setattr(CompileClock, "HEARTBEAT_S", 0.05)
    out = io.StringIO()
    bar = tqdm(total=10, desc="train reach", file=out, mininterval=0)
    report = CompileReport()
    clock = CompileClock(bar, "train reach", report, 40.0).begin()
    try:
        assert bar.desc.startswith("train reach: compiling 0 s")
        report.add(CompileClock.DONE, 0.0)
        assert _wait_for(lambda: bar.desc == "train reach")
        drawn = len(out.getvalue())
        assert _wait_for(lambda: len(out.getvalue()) > drawn)
    finally:
        clock.stop()
        bar.close()
