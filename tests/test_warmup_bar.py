"""``mjx-arm warmup`` trains one epoch: its progress bar ends there, at 100 %, not at the
fifth of the whole run it stops at (:class:`mjx_arm.train.progress._Progress`)."""

from __future__ import annotations

import pytest

from mjx_arm.task.config import task_config
from mjx_arm.train.learner import EpochSizes
from mjx_arm.train.presets import preset_config
from mjx_arm.train.progress import _Progress, planned_steps


@pytest.mark.parametrize("stop_after", [0, 1, 2])
def test_a_run_stopped_after_its_first_epochs_has_a_bar_that_ends_there(stop_after: int):
    config = preset_config("cpu", "reach")
    epoch = EpochSizes.of(config, config.num_timesteps).env_steps_per_epoch
    progress = _Progress(None, config, task_config("reach"), 0, True, stop_after)
    try:
        expected = stop_after * epoch if stop_after else planned_steps(config)
        assert progress.bar.total == expected
        assert planned_steps(config) == 5 * epoch  # the cpu preset: 5 epochs, warmup's is 1
    finally:
        progress.close()
