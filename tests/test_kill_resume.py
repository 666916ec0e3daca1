"""Training that survives being killed, and a run directory that cannot take a run.

A run of 12 epochs is killed with SIGKILL three times at seeded random points (wherever it is:
in an epoch, an evaluation or a checkpoint save) and resumed with ``--resume`` each time.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mjx_arm.train import ppo
from mjx_arm.train.presets import load_config
from mjx_arm.train.rundir import RunDir, RunDirError

EPOCHS = 12
EPOCH_STEPS = 3 * 640  # 3 training steps of 32 envs x 4 unrolls x 5 steps
SETTINGS = {
    "task": "reach",
    "backend": "mujoco",
    "num_timesteps": EPOCHS * EPOCH_STEPS,
    "num_envs": 32,
    "batch_size": 32,
    "num_minibatches": 4,
    "unroll_length": 5,
    "num_updates_per_batch": 2,
    "num_evals": EPOCHS + 1,
    "num_eval_envs": 16,
    "policy_hidden": "32,32",
    "value_hidden": "32,32",
    "checkpoint_every": 1,
}


def _start(args: list[str]) -> subprocess.Popen:
    command = [sys.executable, "-m", "mjx_arm.cli", "train", "--quiet", *args]
    return subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def _rows(run_dir: Path) -> list[dict[str, float]]:
    return RunDir(run_dir).read_metrics()


def _kill_after(process: subprocess.Popen, run_dir: Path, rows: int, delay: float) -> None:
    """SIGKILL ``process`` ``delay`` seconds after ``metrics.csv`` holds ``rows`` rows."""
    deadline = time.monotonic() + 300
    while len(_rows(run_dir)) < rows:
        assert process.poll() is None, process.stderr.read().decode()[-2000:]
        assert time.monotonic() < deadline, "the run made no progress"
        time.sleep(0.05)
    time.sleep(delay)
    process.send_signal(signal.SIGKILL)
    process.wait()


@pytest.mark.slow
def test_killed_three_times_the_run_finishes_as_if_never_stopped(tmp_path: Path) -> None:
    rng = random.Random(7)
    run_dir = tmp_path / "run"
    sets = [f"{k}={v}" for k, v in SETTINGS.items()]
    process = _start(["--run-dir", str(run_dir), "--set", *sets])
    lost = []
    for rows in sorted(rng.sample(range(2, EPOCHS), 3)):
        _kill_after(process, run_dir, rows, rng.uniform(0.0, 1.0))
        done = max(int(r["step"]) for r in _rows(run_dir))
        latest = RunDir(run_dir).latest_checkpoint()
        saved = int(RunDir.load_meta(latest)["step"]) if latest else 0
        lost.append(done - saved)
        process = _start(["--resume", str(run_dir)])
    assert process.wait(timeout=300) == 0, process.stderr.read().decode()[-2000:]

    steps = [int(r["step"]) for r in _rows(run_dir)]
    assert steps == [i * EPOCH_STEPS for i in range(EPOCHS + 1)]  # none lost, none twice
    latest = RunDir(run_dir).latest_checkpoint()
    assert int(RunDir.load_meta(latest)["step"]) == EPOCHS * EPOCH_STEPS
    assert RunDir.load_params(latest) is not None
    assert all(0 <= n <= EPOCH_STEPS for n in lost), lost  # at most one checkpoint interval


def test_a_half_written_checkpoint_is_never_the_latest(tmp_path: Path) -> None:
    run = RunDir(tmp_path / "run")
    params = ({"mean": [0.0]}, {"w": [1.0]}, {"v": [2.0]})
    run.save_checkpoint(100, params, {"task": "reach"})
    partial = run.checkpoint_dir(200).with_name(".partial-step_000000000200")
    (partial / "params").mkdir(parents=True)  # a save killed before its rename
    assert run.latest_checkpoint() == run.checkpoint_dir(100)
    run.save_checkpoint(200, params, {"task": "reach"})  # the next save clears it
    assert run.latest_checkpoint() == run.checkpoint_dir(200)
    assert not partial.exists()


def test_rows_after_the_checkpoint_and_cut_rows_are_dropped(tmp_path: Path) -> None:
    run = RunDir(tmp_path / "run")
    for step in (0, 10, 20, 30):
        run.log_metrics(step, {"eval/episode_reward": float(step)})
    with (run.path / "metrics.csv").open("a") as f:
        f.write("40,17000")  # a row cut short by a kill
    assert run.truncate_metrics(20) == 2
    assert [int(r["step"]) for r in run.read_metrics()] == [0, 10, 20]


def test_an_unwritable_run_directory_fails_before_compiling(tmp_path: Path, monkeypatch) -> None:
    def no_envs(*_):
        raise AssertionError("envs were built: the error came too late")

    monkeypatch.setattr(ppo, "make_envs", no_envs)
    config = load_config("cpu", None, ["backend=mujoco"])
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(RunDirError, match="cannot create the run directory"):
        ppo.train(config, blocker / "run", quiet=True)


def test_a_full_disk_fails_before_compiling(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setattr(ppo, "make_envs", lambda *_: pytest.fail("envs were built"))
    usage = os.statvfs(tmp_path)
    full = type("Usage", (), {"free": 10 * 2**20, "total": usage.f_blocks, "used": 0})
    monkeypatch.setattr("mjx_arm.train.rundir.shutil.disk_usage", lambda _: full)
    config = load_config("cpu", None, ["backend=mujoco"])
    with pytest.raises(RunDirError, match="10 MiB free"):
        ppo.train(config, tmp_path / "run", quiet=True)
