"""A task and an arm, resolved once into one object before any engine is built.

:func:`resolve_task` is the one place where a task config meets an arm: the arm is validated
for an engine and read (:func:`~mjx_arm.arm.info.validated_arm_info`), and the task's
arm-dependent fields (home pose, workspace scale, episode length) are filled in from the arm's
setup (:func:`~mjx_arm.arm.setup.arm_setup`). The result, an :class:`ArmTask`, is what the
trainer, evaluation and the benchmarks hand to every engine (the CPU envs, the MJX env and its
batch physics); an engine given one takes it as it is. Given a task config and an arm instead
(a call from Python), an engine resolves them here, through :func:`as_arm_task`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mjx_arm.arm.config import ArmConfig, load_arm
from mjx_arm.arm.info import ArmInfo, arm_info, validate_arm
from mjx_arm.arm.points import task_arm
from mjx_arm.arm.setup import arm_setup
from mjx_arm.arm.verdict import task_verdict
from mjx_arm.engines import CONVERTER_ENGINE
from mjx_arm.inputs import ConfigError
from mjx_arm.task.config import TaskConfig


class TaskFitError(ConfigError):
    """A task that does not fit the arm: a gripper task on an arm without a gripper, a home
    pose with another number of angles than the arm has joints, or a task ``mjx-arm arm
    --check`` says the arm cannot do (a named input error, and a ``ValueError``)."""


@dataclass(frozen=True, eq=False)
class ArmTask:
    """A task on an arm, resolved once.

    Attributes:
        arm: the arm's facts (:class:`~mjx_arm.arm.info.ArmInfo`), its URDF validated, with
            the task's ee point (:func:`~mjx_arm.arm.points.task_arm`).
        task: the task config with the arm's fields filled in: ``home_qpos`` ``(n,)``,
            ``workspace_scale``, ``episode_steps`` and ``object_scale``
            (:meth:`TaskConfig.for_arm`).
    """

    arm: ArmInfo
    task: TaskConfig


def resolve_task(
    task: TaskConfig | None = None,
    arm: str | Path | ArmConfig | None = None,
    engine: str = CONVERTER_ENGINE,
) -> ArmTask:
    """The task on the arm: the arm validated for ``engine`` and read, the task filled in.

    Args:
        task: the task config (default: Touch).
        arm: a URDF, an arm file or an :class:`~mjx_arm.arm.config.ArmConfig` (default: the
            shipped arm; the gripper arm for a gripper task: :func:`default_arm`).
        engine: the engine the URDF is validated for ("mujoco", "pybullet", ...).

    Raises:
        UrdfError: the URDF does not validate for ``engine``.
        ArmConfigError: an arm file or config that does not resolve.
        TaskFitError: the task does not fit the arm.
    """
    from mjx_arm.task.touch import touch_config

    task = task or touch_config()
    config = load_arm(default_arm(task, arm))
    validate_arm(config, engine)
    info = arm_info(config)
    return ArmTask(task_arm(info, task), task_for_arm(task, info))


def as_arm_task(
    task: TaskConfig | ArmTask | None, arm: str | Path | ArmConfig | None, engine: str
) -> ArmTask:
    """``task`` where it is an :class:`ArmTask` already (its URDF validated for ``engine``
    too: a cached check), else :func:`resolve_task` of ``task`` and ``arm``.

    Raises:
        ValueError: an :class:`ArmTask` together with an ``arm`` (it carries its own).
    """
    if not isinstance(task, ArmTask):
        return resolve_task(task, arm, engine)
    if arm is not None:
        raise ValueError("an ArmTask carries its arm: pass arm=None with it")
    validate_arm(task.arm.config, engine)
    return task


def task_for_arm(task: TaskConfig, arm: ArmInfo, check: bool = True) -> TaskConfig:
    """``task`` with the arm's setup (:func:`mjx_arm.arm.setup.arm_setup`: home pose,
    workspace scale, episode length, a gripper task's cube) filled in where it leaves them
    empty.

    Args:
        task: the task config.
        arm: the arm's facts.
        check: refuse a task the arm cannot do (:func:`mjx_arm.arm.verdict.task_verdict`:
            what ``mjx-arm arm --check`` says no to); False fills the setup in regardless (a
            measurement on the arm, not an env).

    Raises:
        TaskFitError: a gripper task on an arm without a gripper, a home pose with another
            number of angles than the arm has joints, or (``check``) a task the arm cannot do.
    """
    if task.spec.gripper and arm.gripper is None:
        raise TaskFitError(
            f"task {task.task!r} needs an arm with a gripper (prismatic fingers, a linkage "
            f"coupled by <mimic> to one driven joint, or one driven jaw); {arm.urdf} has none. "
            "Try --arm assets/ur5e_gripper.urdf"
        )
    if len(task.home_qpos) not in (0, arm.n_joints):
        raise TaskFitError(
            f"home_qpos has {len(task.home_qpos)} angles; the arm has {arm.n_joints} joints"
        )
    if check:
        ok, why = task_verdict(arm, task)
        if not ok:
            raise TaskFitError(
                f"{arm.urdf.name} cannot do {task.task}: {why} (mjx-arm arm URDF --check)"
            )
    return arm_setup(arm, task).fill(task)


def default_arm(task: TaskConfig, arm: Any = None) -> Any:
    """``arm``, or where it is None the arm the task declares
    (:attr:`~mjx_arm.task.spec.Task.default_arm`; Lift: ``assets/ur5e_gripper.urdf``), else
    the shipped arm (None)."""
    if arm is None and task.spec.default_arm:
        from mjx_arm.paths import asset

        return asset(task.spec.default_arm)
    return arm
