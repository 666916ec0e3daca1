"""Checkpoints written on a thread beside training: in order, one at a time, their errors raised
in the training thread, the last one on disk before the run ends."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from mjx_arm.train.presets import load_config
from mjx_arm.train.saver import CheckpointSaver, host_copy


def test_jobs_run_in_order_one_at_a_time_off_the_calling_thread():
    """A job starts only after the one before it has finished, on another thread."""
    saver, log, threads = CheckpointSaver(), [], set()

    def job(name: str, seconds: float):
        def run():
            threads.add(threading.get_ident())
            log.append(f"{name} start")
            time.sleep(seconds)
            log.append(f"{name} end")

        return run

    saver.submit(job("a", 0.2))
    saver.submit(job("b", 0.0))
    saver.wait()
    assert log == ["a start", "a end", "b start", "b end"]
    assert threads and threading.get_ident() not in threads
    saver.close()


def test_a_failed_save_is_raised_at_the_next_submit_or_wait():
    """The error of a job comes out of the next ``submit`` (which then starts nothing) or of
    ``wait``; ``close`` after a failure raises nothing."""
    saver, ran = CheckpointSaver(), []

    def fail():
        raise OSError(28, "No space left on device")

    saver.submit(fail)
    with pytest.raises(OSError, match="No space left"):
        saver.submit(lambda: ran.append("next"))
    saver.wait()
    assert ran == []
    saver.submit(fail)
    with pytest.raises(OSError, match="No space left"):
        saver.wait()
    saver.submit(fail)
    saver.close()  # a run already ending on an error of its own


def test_host_copies_own_their_memory():
    """JAX arrays (a view of device memory on a CPU) become numpy arrays that own their memory,
    equal to them; arrays that already own theirs are not copied again."""
    owned = np.arange(3.0)
    tree = {"jax": jnp.arange(4.0), "numpy": owned, "nested": (jnp.ones((2, 2)),)}
    copied = host_copy(tree)
    assert copied["numpy"] is owned
    for leaf in (copied["jax"], copied["nested"][0]):
        assert isinstance(leaf, np.ndarray) and leaf.flags.owndata
    np.testing.assert_array_equal(copied["jax"], np.arange(4.0))


def test_a_checkpoint_that_fails_stops_the_run_at_the_next_one(tmp_path: Path):
    """_Progress: a save that fails in the background is raised by the next checkpoint, one
    evaluation later; the final checkpoint is on disk (its job done) when ``progress`` returns."""
    from mjx_arm.task.config import task_config
    from mjx_arm.train.progress import _Progress
    from mjx_arm.train.rundir import RunDir

    config = load_config("cpu", None, ["num_timesteps=30", "num_evals=4"])
    progress = _Progress(RunDir(tmp_path / "run"), config, task_config("reach"), 0, quiet=True)
    done = []

    def job(step, make_policy, params, meta, resume=None):
        def run():
            time.sleep(0.05)
            if step == 10:
                raise OSError(28, "No space left on device")
            done.append(step)

        return run

    progress._save_job = job
    metrics = {"eval/episode_success": 0.1, "training/sps": 1.0}
    progress.policy_params(10, None, {"w": np.zeros(2)})
    progress.progress(10, metrics)  # its save fails on the saver's thread
    progress.policy_params(20, None, {"w": np.zeros(2)})
    with pytest.raises(OSError, match="No space left"):
        progress.progress(20, metrics)
    progress.close()

    progress = _Progress(RunDir(tmp_path / "run2"), config, task_config("reach"), 0, quiet=True)
    progress._save_job = job
    for step in (20, 30):
        progress.policy_params(step, None, {"w": np.zeros(2)})
        progress.progress(step, metrics)
    assert done == [20, 30]  # the last (step >= the budget) waited for
    progress.close()
