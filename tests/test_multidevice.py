"""Training on several devices: the same run as on one, and a run that learns and resumes.

Two CPU devices stand in for two GPUs (``--xla_force_host_platform_device_count=2``, set in a
fresh process by ``multidevice_worker.py``). The env batch is split over them and the gradient
is reduced across them, exactly as on GPUs; the physics is the C MuJoCo backend.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import jax
import pytest

from mjx_arm.train.config import TrainConfig, load_config
from mjx_arm.train.learner import local_devices
from mjx_arm.train.loop import resolve_partition

WORKER = Path(__file__).with_name("multidevice_worker.py")
LEARN_STEPS = 160_000  # the cpu preset reaches 100% Reach success at ~123k steps (2 devices)


@pytest.fixture(scope="module")
def figures(tmp_path_factory: pytest.TempPathFactory) -> dict:
    out = tmp_path_factory.mktemp("multidevice")
    env = {
        **os.environ,
        "XLA_FLAGS": "--xla_force_host_platform_device_count=2",
        "JAX_PLATFORMS": "cpu",
    }
    done = subprocess.run(
        [sys.executable, str(WORKER), str(out), str(LEARN_STEPS)],
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0, done.stderr[-4000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_two_devices_compute_what_one_does(figures: dict) -> None:
    """The PPO loss gradient of one minibatch, split over 2 devices, equals the one of 1 device
    up to the order of its float32 sums: within 1e-5 of each array's largest entry (measured:
    5e-7, a few ulps).

    Params after a training step are not compared: Adam divides each gradient entry by the
    root of its own running square, so an entry near zero whose sign the sum order flips moves
    a whole learning-rate step either way (measured on a 2-core CPU: 1.3e-3 = 1.3 steps of
    lr 1e-3, 3.4e-3 of the array's largest entry, after 8 updates, and as much after one).
    How far that goes depends on the machine's XLA code, not on the code under test; the
    learning check below covers the Adam-trained run.
    """
    assert figures["device_count"] == 2
    assert figures["gradient_max_rel"] < 1e-5


def test_two_devices_learn_reach(figures: dict) -> None:
    """The cpu preset on 2 devices: 100% eval success from 123k steps (measured), as on 1."""
    assert figures["success"] >= 0.8
    assert figures["partition"] == "per_device"  # C MuJoCo: each device steps its own envs
    assert figures["rows"] == 6  # num_evals of the cpu preset
    for key in ("eval/episode_success", "training/sps", "training/policy_loss"):
        assert key in figures["columns"]


def test_a_two_device_run_resumes_on_one(figures: dict) -> None:
    """Checkpoints hold params only: a run saved on 2 devices goes on on 1."""
    assert figures["kept_step"] < figures["steps"]
    assert figures["resumed_steps"] == figures["steps"]  # the same epochs as without a stop
    assert figures["resumed_success"] >= 0.8


def test_too_many_devices_is_a_clear_error() -> None:
    with pytest.raises(ValueError, match="devices"):
        local_devices(jax.local_device_count() + 1)


def test_a_batch_that_does_not_split_is_a_clear_error() -> None:
    config = load_config("cpu", None, ["num_envs=63", "batch_size=63", "num_minibatches=8"])
    with pytest.raises(ValueError, match="num_envs \\(63\\) must be a multiple of the device"):
        config.check_devices(2)


def test_partition_follows_the_physics() -> None:
    auto = TrainConfig()
    assert resolve_partition(auto, "jax") == "xla"
    assert resolve_partition(auto, "warp") == "per_device"
    assert resolve_partition(auto, "c") == "per_device"
    assert resolve_partition(auto.replace(partition="xla"), "warp") == "xla"
    with pytest.raises(ValueError, match="partition"):
        auto.replace(partition="pmap").validate()


def test_old_configs_name_the_device_count_max_devices() -> None:
    assert TrainConfig.from_dict({"max_devices": 2}).devices == 2
