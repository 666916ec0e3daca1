"""What every engine needs to know about the arm, as one record (:class:`ArmInfo`); how it is
read from a config and its URDF is :mod:`mjx_arm.arm.info`."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mjx_arm.arm.config import ArmConfig
from mjx_arm.arm.gripper import Gripper
from mjx_arm.task.config import TaskConfig
from mjx_arm.task.observation import JointCoding, joint_coding
from mjx_arm.task.wrench import ToolInertia
from mjx_arm.urdf.convert_config import ConvertConfig


@dataclass(frozen=True, eq=False)
class ArmInfo:
    """Joint names and limits, tool frames, home pose and reach of an arm of n joints.

    Attributes:
        config: the arm config as given (saved with runs and policy files).
        urdf: path of the URDF.
        joint_names: the n actuated joints, base to wrist (n from 5 to 7).
        lower, upper: position limits (rad), shape ``(n,)``.
        v_max: velocity limits (rad/s), shape ``(n,)``.
        effort: torque limits (N m), shape ``(n,)``.
        home_qpos: home joint angles (rad), shape ``(n,)``.
        ee_link: the end-effector link.
        ft_joint: the fixed joint of the F/T reading, or "" when it is taken at the last arm
            joint; ft_link: the root link of the tool the reading weighs.
        tool: mass properties of the tool below the F/T point.
        reach_scale: the arm's horizontal reach over the shipped arm's (1.0 for the shipped
            arm): task targets are drawn in a box scaled by it.
        gripper: the arm's gripper, when it has one (:class:`~mjx_arm.arm.gripper.Gripper`).
        full_turn: which joints turn without limits (URDF ``continuous``), bool ``(n,)``.
        kv_factor: the servos' velocity gain factor the arm's models are converted with
            (the config's, else :func:`press_kv_factor`).
        ee_offset: the ee point in the ee link's frame (m), ``(3,)`` (the config's, else
            :func:`mjx_arm.arm.points.derive_tool_point`).
        grip_offset: a gripper arm's ee point in the gripper tasks (Lift), where the pads
            hold the object, ``(3,)``; None: ``ee_offset`` (:func:`task_arm` picks the point of
            a task).
        tool_offset: the ee point of the other tasks (Reach, Touch), ``(3,)``; None:
            ``ee_offset``.
        tool_axis: the tool axis in the ee link's frame, ``(3,)``, where the derivation fixed
            it (an ee point off the axis); None: :func:`~mjx_arm.arm.ik.tool_axis` finds it.
    """

    config: ArmConfig
    urdf: Path
    joint_names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    v_max: np.ndarray
    effort: np.ndarray
    home_qpos: np.ndarray
    ee_link: str
    ft_joint: str
    ft_link: str
    tool: ToolInertia
    reach_scale: float
    gripper: Gripper | None = None
    full_turn: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0, bool))
    kv_factor: float = 1.0
    ee_offset: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    grip_offset: tuple[float, float, float] | None = None
    tool_offset: tuple[float, float, float] | None = None
    tool_axis: tuple[float, float, float] | None = None

    @property
    def n_joints(self) -> int:
        """Number of actuated joints."""
        return len(self.joint_names)

    def convert_config(self, **fields) -> ConvertConfig:
        """Conversion settings that put the ee site and F/T sensors where this arm says, with
        its servo gain; a gripper starts closed (a gripper task opens it; the shipped gripper
        arm's fingers start at 0) and its mesh pads are fitted boxes."""
        fields.setdefault("kv_factor", self.kv_factor)
        fields.setdefault("ee_offset", tuple(float(v) for v in self.ee_offset))
        gripper = self.gripper
        if gripper is not None and gripper.rests_closed:  # Touch and Reach: held closed
            closed = gripper.positions(gripper.closed_q)
            fields.setdefault("rest_qpos", tuple(closed.items()))
        if gripper is not None and gripper.fitted.replaced:
            fields.setdefault("pads", gripper.fitted)
        if gripper is not None and gripper.effort_cap:
            fields.setdefault("effort_caps", ((gripper.joint, gripper.effort_cap),))
        return self.config.convert_config(self.ee_link, self.ft_joint, **fields)

    def joint_coding(self, task: TaskConfig) -> JointCoding:
        """How ``task``'s observation encodes this arm's joint angles (its ``joint_encoding``;
        a full-turn joint is centred on ``task``'s home angle, which must be filled in)."""
        home = task.home_qpos or tuple(self.home_qpos)
        return joint_coding(task.joint_encoding, self.lower, self.upper, self.full_turn, home)
