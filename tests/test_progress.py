"""The training progress bar and the compile figure: the bar's total is the step the run ends
on, it says that the run compiles (and how long the last run took), and the start-up line,
``compile.json`` and the bar give the same compile time."""

from __future__ import annotations

import io
import time
from pathlib import Path

import pytest

from mjx_arm.train.compile_report import (
    COMPILE_STAGES,
    TIMES_FILE,
    CompileReport,
    expected_compile,
    remember_compile,
)
from mjx_arm.train.learner import EpochSizes
from mjx_arm.train.presets import load_config
from mjx_arm.train.progress import CompileClock, compiling_text, planned_steps


def _loop_end(num_timesteps: int, epoch: int, offset: int) -> int:
    """The step the training loop (``run_ppo``) stops on: whole epochs until the budget."""
    step = offset
    while step < num_timesteps:
        step += epoch
    return step


@pytest.mark.parametrize("timesteps", [300_000, 122_880, 1_000])
def test_the_bar_total_is_the_step_the_run_ends_on(timesteps: int) -> None:
    config = load_config("cpu", None, [f"num_timesteps={timesteps}", "num_evals=6"])
    epoch = EpochSizes.of(config, timesteps).env_steps_per_epoch
    total = planned_steps(config)
    assert total == _loop_end(timesteps, epoch, 0)
    assert total % epoch == 0 and timesteps <= total < timesteps + epoch
    resumed = planned_steps(config, step_offset=epoch)  # a resumed run ends on the same step
    assert resumed == total == _loop_end(timesteps, epoch, epoch)


def test_a_progress_bar_counts_to_the_rounded_total(tmp_path: Path) -> None:
    from mjx_arm.task.config import task_config
    from mjx_arm.train.progress import _Progress
    from mjx_arm.train.rundir import RunDir

    config = load_config("cpu", None, ["num_timesteps=300000", "num_evals=6"])
    progress = _Progress(RunDir(tmp_path / "run"), config, task_config("reach"), 0, quiet=False)
    try:
        assert progress.bar.total == planned_steps(config) > config.num_timesteps
    finally:
        progress.close()


def test_the_compile_figure_is_the_same_in_the_line_and_the_json() -> None:
    report = CompileReport()
    for name, seconds in (
        ("build env", 0.7),
        ("learner init", 5.1),
        ("trace + lower", 6.6),
        ("XLA compile (in parallel)", 63.1),
        ("first epoch run", 19.1),
    ):
        report.add(name, seconds)
    report.seconds["backend_compile"] = 168.0  # summed over programs compiled at once
    assert report.compile_seconds == pytest.approx(5.1 + 6.6 + 63.1, abs=1e-9)
    line = report.summary()
    assert line.startswith("compiled in 74.8 s (learner init 5.1, trace + lower 6.6, XLA")
    assert "other start-up (s): build env 0.7, first epoch run 19.1" in line
    assert "168" not in line  # the per-program sum is kept apart, in the JSON only
    saved = report.to_dict()
    assert saved["compile_s"] == pytest.approx(74.8, abs=1e-9)
    assert saved["compile_stages"] == [s for s in COMPILE_STAGES if s != "waited for Warp"]


def test_the_last_compile_time_is_kept_per_setup(monkeypatch, tmp_path: Path) -> None:
    monkeypatch.setenv("MJX_ARM_JAX_CACHE", str(tmp_path / "jax"))
    assert expected_compile("reach mujoco 64/64 envs ur5e.urdf cpu") is None
    remember_compile("reach mujoco 64/64 envs ur5e.urdf cpu", 74.84)
    remember_compile("touch mjx 4096/128 envs ur5e.urdf H100", 31.0)
    assert expected_compile("reach mujoco 64/64 envs ur5e.urdf cpu") == 74.8
    assert expected_compile("touch mjx 4096/128 envs ur5e.urdf H100") == 31.0
    (tmp_path / "jax" / TIMES_FILE).write_text("not json")
    assert expected_compile("touch mjx 4096/128 envs ur5e.urdf H100") is None


def test_compiling_text_names_the_last_run() -> None:
    assert compiling_text(12.4, None) == "compiling 12 s"
    assert compiling_text(12.4, 74.8) == (
        "compiling 12 s; the last run of this setup compiled in 75 s"
    )


def test_the_bar_says_it_compiles_until_the_first_program_runs() -> None:
    """Within 3 s of the compile's end (the clock looks once a second) the bar's name is back."""
    from tqdm import tqdm

    bar = tqdm(total=10, desc="train reach", file=io.StringIO())
    report = CompileReport()
    clock = CompileClock(bar, "train reach", report, 40.0).begin()
    try:
        assert bar.desc.startswith("train reach: compiling 0 s; the last run")
        report.add("XLA compile (in parallel)", 1.0)
        report.add(CompileClock.DONE, 0.0)
        deadline = time.monotonic() + 3.0
        while bar.desc != "train reach" and time.monotonic() < deadline:
            time.sleep(0.05)
        assert bar.desc == "train reach"
    finally:
        clock.stop()
        bar.close()


def test_a_setup_names_the_backend_the_run_resolves() -> None:
    """``auto`` and the backend it picks on this device share one remembered compile time."""
    from mjx_arm.envs.backend import resolve_backend
    from mjx_arm.train.progress import compile_setup

    auto = load_config("cpu", None, ["backend=auto"])
    picked = load_config("cpu", None, [f"backend={resolve_backend('auto')}"])
    assert compile_setup(auto) == compile_setup(picked)
    assert compile_setup(auto).startswith(f"reach {resolve_backend('auto')} 64/64 envs ur5e.urdf")


def test_each_report_takes_only_the_start_up_marks_made_since_the_last() -> None:
    """Trainings in turn in one process (seeds in turn, ``--check-repeat``): the first report
    records the process's start-up marks, the second only those made after the first opened."""
    from mjx_arm.train.compile_report import mark

    mark("command read")
    mark("devices started")
    first = CompileReport()
    mark("arm and task resolved")
    second = CompileReport()
    assert set(first.marks) == {"command read", "devices started"}
    assert set(second.marks) == {"arm and task resolved"}
    assert CompileReport().marks == {}
