"""A training run whose updates blow up stops with one named error line (exit 2) that names the
setting to change, and leaves no checkpoint of the diverged params behind; a learning rate that
can never train is refused by the config's validation before anything runs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tiny_run import SETTINGS

from mjx_arm.cli import main
from mjx_arm.inputs import ConfigError
from mjx_arm.names import EXIT_INVALID
from mjx_arm.train.config import MAX_LEARNING_RATE, TrainConfig
from mjx_arm.train.divergence import TrainingDivergedError, check_epoch, non_finite_metrics
from mjx_arm.train.rundir import RunDir


def _error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    (line,) = [x for x in err.splitlines() if x.startswith("error:")]
    return line


@pytest.mark.parametrize("rate", ["1e308", "1.5", "inf"])
def test_a_learning_rate_that_can_never_train_is_refused(rate: str, tmp_path: Path, capsys):
    code = main(["train", "--run-dir", str(tmp_path / "run"), "--set", f"learning_rate={rate}"])
    assert code == EXIT_INVALID
    line = _error_line(capsys)
    assert "learning_rate must be" in line
    assert not (tmp_path / "run" / "checkpoints").exists()
    with pytest.raises(ConfigError):
        TrainConfig(learning_rate=float(rate))
    TrainConfig(learning_rate=MAX_LEARNING_RATE)  # the bound itself is allowed


def test_check_epoch_names_the_non_finite_parts_and_the_setting():
    config = TrainConfig(learning_rate=0.5, reward_scaling=1e30)
    finite = {"params": np.ones((3, 4), np.float32), "count": np.int32(5)}
    metrics = {"policy_loss": np.float32(0.1), "learning_rate": np.float32(np.inf)}
    check_epoch(config, 10, finite, metrics)  # the logged learning rate is a setting, not a loss
    broken = {**finite, "params": np.array([[1.0, np.nan]], np.float32)}
    with pytest.raises(TrainingDivergedError, match=r"step 10: non-finite params;") as err:
        check_epoch(config, 10, broken, metrics)
    text = str(err.value)
    assert "Lower learning_rate (now 0.5, default 0.0003)" in text
    assert "reward_scaling = 1e+30 (default 0.1)" in text
    nan_loss = {**metrics, "v_loss": np.array([1.0, np.inf])}
    assert non_finite_metrics(nan_loss) == ["v_loss"]
    with pytest.raises(TrainingDivergedError, match=r"non-finite 1 metrics \(v_loss\)"):
        check_epoch(config, 20, finite, nan_loss)


@pytest.mark.slow
def test_a_diverging_run_ends_in_one_error_line_and_no_checkpoint(tmp_path: Path, capsys):
    """``learning_rate=1`` with rewards scaled by 1e38: the value loss overflows float32 in the
    first update; the run stops after that epoch, before its checkpoint is written."""
    run_dir = tmp_path / "run"
    sets = [f"{k}={v}" for k, v in SETTINGS.items()]
    sets += ["learning_rate=1", "reward_scaling=1e38"]
    assert main(["train", "--run-dir", str(run_dir), "--set", *sets]) == EXIT_INVALID
    line = _error_line(capsys)
    assert "training diverged at step 640: non-finite params" in line
    assert "Lower learning_rate (now 1, default 0.0003)" in line
    assert len(line) <= 300
    assert RunDir(run_dir).latest_checkpoint() is None
    checkpoints = run_dir / "checkpoints"
    assert not checkpoints.exists() or not any(checkpoints.iterdir())


def test_a_nan_action_in_the_checkpoints_rollout_is_a_divergence():
    """The env's own check of a NaN action (what the checkpoint's rollout calls) inside the
    guard becomes the named error; another invalid action stays what it was."""
    from mjx_arm.envs.base import InvalidActionError, check_action
    from mjx_arm.train.divergence import rollout_guard

    config = TrainConfig(learning_rate=0.9)
    diverged = pytest.raises(TrainingDivergedError, match=r"step 64: the policy acted NaN or inf")
    with diverged, rollout_guard(config, 64):
        check_action(np.full(6, np.nan))
    with pytest.raises(InvalidActionError, match="must have shape"), rollout_guard(config, 64):
        check_action(np.zeros(5))
