"""``mjx-arm arm --check`` and the envs agree: for every arm URDF of example-robot-data and
pybullet_data with 5 to 7 arm joints, and each task, the check's yes or no equals whether the CPU
MuJoCo env builds and steps, and an env refused is refused with the check's reason; every env
that builds lets each moving link collide with the scene.

An arm is checked as a user would: as published, and where that is a named error, with the
converter's repairs (``repair_inertia`` and default effort and velocity limits, as
``benchmarks/bench_arm_check.py`` does). Slow: about 50 env builds, most of them of mesh arms.
"""

from __future__ import annotations

import sysconfig
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import mjx_arm  # noqa: F401  (registers the ids)
from mjx_arm.arm.chain import MAX_JOINTS, MIN_JOINTS, arm_chain, default_ee_link
from mjx_arm.arm.config import ArmConfig, ArmConfigError
from mjx_arm.arm.info import validated_arm_info
from mjx_arm.arm.resolve import TaskFitError
from mjx_arm.arm.verdict import task_verdict
from mjx_arm.inputs import InputError
from mjx_arm.task.config import task_config
from mjx_arm.urdf.errors import UrdfError
from mjx_arm.urdf.model import parse_urdf

ROBOTS = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
REPAIRS = {"repair_inertia": True, "default_effort": 50.0, "default_velocity": 2.0}
TASKS = ("reach", "touch", "lift")
STEPS = 3  # control steps an env that builds takes


def _folders() -> list[Path]:
    folders = [ROBOTS] if ROBOTS.is_dir() else []
    try:
        import pybullet_data
    except ImportError:
        return folders
    return [*folders, Path(pybullet_data.getDataPath())]


def _arm_urdfs() -> list[Path]:
    """The URDFs under :func:`_folders` whose longest chain has 5 to 7 arm joints (a cheap
    look at the tree; the test resolves each as the check does)."""
    found = []
    for folder in _folders():
        for path in sorted(folder.rglob("*.urdf")):
            try:
                model = parse_urdf(path)
                joints = len(arm_chain(model, default_ee_link(model)))
            except Exception:  # not an arm: a scene, a broken file, ...
                continue
            if MIN_JOINTS <= joints <= MAX_JOINTS:
                found.append(path)
    return found


def _name(path: Path) -> str:
    """``path`` relative to the data folder it was found in."""
    for folder in _folders():
        if path.is_relative_to(folder):
            return str(path.relative_to(folder))
    return str(path)


def _arm(path: Path) -> ArmConfig | None:
    """The arm config of ``path`` as published, else repaired; None where neither resolves to
    an arm (a named error: not a question for the tasks)."""
    for repairs in ({}, REPAIRS):
        config = ArmConfig(urdf=str(path), **repairs)
        try:
            validated_arm_info(config, "mujoco")
        except (ArmConfigError, UrdfError, InputError):
            continue
        return config
    return None


def _disagreement(path: Path, task: str) -> str:
    """An empty string where ``--check``'s verdict on ``task`` and the CPU MuJoCo env agree on
    the arm of ``path``, else what differs."""
    config = _arm(path)
    if config is None:
        return ""  # no arm the tasks take (a named error)
    ok, why = task_verdict(validated_arm_info(config, "mujoco"), task_config(task))
    try:
        env = gym.make(f"mjx_arm/{task.capitalize()}-v0", engine="mujoco", arm=config)
    except TaskFitError as refused:
        if ok:
            return f"--check said yes, the env refused: {refused}"
        same = why in str(refused) or str(refused).startswith(f"task {task!r} needs an arm")
        return "" if same else f"refused for another reason: {refused} (--check: {why})"
    try:
        if not ok:
            return f"--check said no ({why}), the env built"
        if moving := _excluded_from_the_world(env.unwrapped.model):
            return f"links excluded from the world body (the table, the box): {moving}"
        env.reset(seed=0)
        for _ in range(STEPS):
            _, reward, *_ = env.step(np.zeros(env.action_space.shape, np.float32))
            if not np.isfinite(reward):
                return "the env built but its reward is not finite"
    finally:
        env.close()
    return ""


def _excluded_from_the_world(model) -> list[str]:
    """The moving bodies of a MuJoCo model with a contact exclusion against the world body,
    which holds the scene (a link of UR5's and xArm6's that overlapped the table at all-zero
    angles once was, and passed through the table)."""
    bodies = [s & 0xFFFF for s in model.exclude_signature if s >> 16 == 0]
    return [model.body(b).name for b in bodies if model.body_weldid[b] != 0]


@pytest.mark.slow
def test_check_says_yes_exactly_when_the_env_builds_and_steps() -> None:
    arms = _arm_urdfs()
    if not arms:
        pytest.skip("neither example-robot-data nor pybullet_data is installed")
    assert len(arms) >= 20  # example-robot-data 6.0.0 has 17 such URDFs, pybullet_data 9
    problems = {
        f"{_name(path)} {task}": problem
        for path in arms
        for task in TASKS
        if (problem := _disagreement(path, task))
    }
    assert not problems, problems
