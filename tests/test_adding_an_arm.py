"""Adding an arm (docs/adding-an-arm.md): a URDF variant of the shipped arm and its arm file,
resolved once into an :class:`~mjx_arm.arm.resolve.ArmTask` and stepped in CPU MuJoCo; the
engines take that object as it is, and the trainer's resolution fits the task to the arm before
any env is built.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import mjx_arm  # noqa: F401  (registers the ids)
from mjx_arm.arm.info import arm_info
from mjx_arm.arm.resolve import ArmTask, TaskFitError, resolve_task
from mjx_arm.envs.mujoco_env import MujocoArmEnv
from mjx_arm.inputs import ConfigError
from mjx_arm.paths import default_arm_urdf
from mjx_arm.task import reach_config
from mjx_arm.task.lift import lift_config

FOREARM = 0.50  # m: the variant's upper arm (the shipped arm's is 0.425 m)


def _long_arm(folder: Path) -> Path:
    """The shipped arm with its elbow :data:`FOREARM` from the shoulder, written to ``folder``."""
    root = ET.parse(default_arm_urdf()).getroot()
    elbow = next(j for j in root.iter("joint") if j.get("name") == "elbow_joint")
    elbow.find("origin").set("xyz", f"{-FOREARM} 0.0 0.0")
    path = folder / "long_arm.urdf"
    ET.ElementTree(root).write(path)
    return path


@pytest.fixture(scope="module")
def long_arm(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, ArmTask]:
    """The variant's arm file (a URDF path relative to it) and Reach resolved on it."""
    folder = tmp_path_factory.mktemp("arm")
    _long_arm(folder)
    arm_file = folder / "long_arm.toml"
    arm_file.write_text('urdf = "long_arm.urdf"\nee_link = "ee_link"\n')
    return arm_file, resolve_task(reach_config(), arm_file)


def test_an_arm_file_resolves_to_the_arm_and_a_task_fitted_to_it(long_arm) -> None:
    arm_file, setup = long_arm
    assert setup.arm.urdf == (arm_file.parent / "long_arm.urdf").resolve()
    assert setup.arm.n_joints == 6 and setup.arm.ee_link == "ee_link"
    # a longer upper arm reaches farther than the shipped one, and its task area grows with it
    assert setup.arm.reach_scale > 1.05
    assert setup.task.workspace_scale > 1.0
    # the home pose is derived (no shipped home for a variant), one angle per joint
    assert len(setup.task.home_qpos) == 6
    assert setup.task.home_qpos != arm_info().home_qpos.tolist()
    assert setup.task.episode_steps >= reach_config().episode_steps


def test_an_env_takes_the_resolved_task_as_it_is_and_steps_it(long_arm) -> None:
    _, setup = long_arm
    env = gym.make("mjx_arm/Reach-v0", task=setup)
    inner = env.unwrapped
    try:
        assert inner.arm_task is setup and inner.task is setup.task and inner.arm is setup.arm
        obs, _ = env.reset(seed=0)
        home = np.asarray(setup.task.home_qpos)
        start = inner.get_ee_pose()
        assert np.abs(inner.data.qpos[inner.ids.qpos_adr] - home).max() <= setup.task.init_noise
        zero = np.zeros(6, np.float32)
        for step in range(1, setup.task.episode_steps + 1):
            obs, reward, terminated, truncated, _ = env.step(zero)
            assert obs in inner.observation_space and np.isfinite(reward)
            assert not terminated and truncated is (step == setup.task.episode_steps)
        # held still by its servos under gravity compensation: the ee stays within 1 cm
        assert np.linalg.norm(inner.get_ee_pose()[:3] - start[:3]) < 0.01
    finally:
        env.close()


def test_resolving_in_the_env_gives_the_same_numbers(long_arm) -> None:
    arm_file, setup = long_arm
    env = MujocoArmEnv(reach_config(), arm_file)
    try:
        assert env.arm is setup.arm and env.task == setup.task
    finally:
        env.close()
    with pytest.raises(ValueError, match="carries its arm"):
        MujocoArmEnv(setup, arm_file)


def test_a_task_that_does_not_fit_the_arm_is_refused_before_any_env(tmp_path: Path) -> None:
    from mjx_arm.train.ppo import resolve_run_task
    from mjx_arm.train.presets import load_config

    with pytest.raises(TaskFitError, match="needs an arm with a gripper"):
        resolve_task(lift_config(), _long_arm(tmp_path))
    config = load_config("cpu", None, ["backend=mujoco", f"arm.urdf={_long_arm(tmp_path)}"])
    assert resolve_run_task(config).arm.urdf == (tmp_path / "long_arm.urdf").resolve()
    with pytest.raises(ConfigError, match="home_qpos has 2 angles"):
        resolve_run_task(
            config.replace(task_settings=replace(config.task_settings, home_qpos=(0.0, 1.0)))
        )
