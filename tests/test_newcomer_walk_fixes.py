"""Fixes from a newcomer's walk of the CPU docs: output that keeps moving during long steps,
and a clean exit."""

from __future__ import annotations

import io
import subprocess
import sys
import time

import pytest
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


def test_an_evaluation_says_how_far_it_has_come(capsys):
    """A long evaluation prints a line at most every 15 s (never in its first 15 s, never
    after its last episode): 50 PyBullet episodes with a video ran 51 s with nothing printed."""
    from mjx_arm.evaluate.runners import Heartbeat

    now = [0.0]
    beat = Heartbeat(50, "episodes", clock=lambda: now[0])
    for done, t in ((1, 5.0), (2, 14.9), (3, 15.0), (4, 20.0), (9, 31.0), (50, 60.0)):
        now[0] = t
        beat(done)
    lines = capsys.readouterr().err.splitlines()
    assert lines == ["  3 of 50 episodes (15 s)", "  9 of 50 episodes (31 s)"]


@pytest.mark.pybullet
def test_a_pybullet_env_left_open_exits_quietly(tmp_path):
    """A script that leaves a PyBullet env open beside a vector env (getting-started's example
    without its close calls) exits 0 with no traceback: the client printed a TypeError from its
    own ``__del__`` at exit."""
    script = tmp_path / "open_env.py"
    script.write_text(
        "import gymnasium as gym\n"
        "import mjx_arm  # noqa: F401\n"
        'env = gym.make("mjx_arm/Reach-v0", engine="pybullet")\n'
        "env.reset(seed=0)\n"
        'vec = gym.make_vec("mjx_arm/Reach-v0", num_envs=2)\n'
        "vec.reset(seed=0)\n"
    )
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "Traceback" not in done.stderr and "Exception ignored" not in done.stderr


def test_a_path_shortened_once_is_not_shortened_again():
    """``validate`` printed mesh paths as ``'....../meshes/x.dae'``: a long report line cut the
    tail of a path that was already cut. Paths are shortened where they start, once."""
    from mjx_arm.urdf.findings import Finding

    long_dir = "/opt/robots/" + "a_long_description_folder/" * 4
    problem = (
        f"mesh '.../kinova_description/meshes/base.dae' (from {long_dir}meshes/base.dae) is a "
        "Collada file that MuJoCo does not read and is converted to STL beside the URDF"
    )
    line = Finding("warning", 2, "robot.urdf", "link 'base'", problem, "nothing to do").line()
    assert "'.../kinova_description/meshes/base.dae'" in line
    assert "......" not in line and "(from .../" in line
