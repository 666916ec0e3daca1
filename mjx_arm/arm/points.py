"""The working points an arm derives from its model: where its tool presses (the ee point of
Reach and Touch) and where its gripper holds (the ee point of Lift), and the tool-down solver
they are measured with.

- **tool point**: where the tool, its gripper closed, meets a surface pressed against it along
  the tool axis (:meth:`~mjx_arm.arm.ik.ToolDownSolver.tool_protrusion` over the Touch box's
  top face): a jaw's tips, closed fingers' tips, the palm of an open hand. Where the tool
  cannot press the box on its axis (no shape there, or shapes beside the axis that straddle
  the box or reach :func:`~mjx_arm.urdf.scene_shapes.box_top_offset` deeper, so they would
  meet the table first: open fingers, finger blocks), the tool point is the tool's deepest
  point instead (:meth:`~mjx_arm.arm.ik.ToolDownSolver.deepest_point`): it meets the box
  first, with everything else behind it. The tool axis then stays the one found from the
  link's origin (:attr:`~mjx_arm.arm.facts.ArmInfo.tool_axis`), so tool-down means the same.
- **grip point**: where the pads hold the object: a parallel gripper's link origin (between
  its pads, as the URDF places its frame), a linkage's or a jaw's grasp centre
  (:func:`mjx_arm.urdf.grippers.grasp_centre`); a parallel or linkage gripper's moved towards
  its tips where they would otherwise reach the table under a held cube (:func:`_tips_clear`).

:func:`task_arm` gives the arm with the ee point of a task. A point within
:data:`MIN_EE_OFFSET` of the link's origin stays at the origin. Points are rounded to 1 um:
they come out of floating-point kinematics whose last bits differ between CPUs (a 1e-17 m
component would change the model hash that policy files check).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from mjx_arm.arm.config import resolve_arm
from mjx_arm.arm.facts import ArmInfo
from mjx_arm.arm.ik import ToolDownSolver
from mjx_arm.task.config import TaskConfig
from mjx_arm.task.wrench import tool_inertia
from mjx_arm.urdf.gripper_layout import TIP_CLEARANCE
from mjx_arm.urdf.scene_shapes import box_half_width, box_top_offset

# The smallest offset (m) a derived point moves the ee point by: closer, the link's origin is
# the tool's working point already.
MIN_EE_OFFSET = 0.005
# m: the most the tool's contact with the box top may move along its axis as the box turns
# about it (the published arms with a tool face: 3 mm or less; the finger blocks of the UR
# gripper URDFs, which straddle the box: 4.75 cm)
CONTACT_SPREAD = 0.01
# m: a gripper arm presses with its grip point where the tool meets the box this near it (half
# Touch's 5 cm success radius)
GRIP_PRESS = 0.025


def tool_down_solver(arm: ArmInfo) -> ToolDownSolver:
    """The arm's :class:`~mjx_arm.arm.ik.ToolDownSolver` (one per arm, file version and ee
    point): its model in the Reach scene with self-collision on, servo gain factor 1."""
    return _solver_cached(arm, arm.urdf.stat().st_mtime, tuple(arm.ee_offset))


@functools.cache
def _solver_cached(arm: ArmInfo, mtime: float, ee_offset: tuple) -> ToolDownSolver:
    from mjx_arm.urdf.convert import EE_SITE, load_model

    config = arm.convert_config(scene="reach", self_collision=True, kv_factor=1.0)
    model = load_model(arm.urdf, config)
    tool = None if arm.tool_axis is None else np.asarray(arm.tool_axis, float)
    return ToolDownSolver(model, arm.joint_names, arm.lower, arm.upper, EE_SITE, tool)


def _rounded(point: np.ndarray) -> np.ndarray:
    """``point (3,)`` rounded to 1 um, without negative zeros; the origin where it is within
    :data:`MIN_EE_OFFSET` of it."""
    if np.linalg.norm(point) < MIN_EE_OFFSET:
        return np.zeros(3)
    return np.round(np.asarray(point, float), 6) + 0.0


def derive_tool_point(arm: ArmInfo) -> tuple[np.ndarray, tuple[float, float, float] | None]:
    """The tool point in the ee link's frame, ``(3,)`` (module doc), of ``arm`` measured at
    the link's origin, and the tool axis to keep where the point is off the axis (else None).
    """
    solver = tool_down_solver(arm)
    q = solver.middle
    contact, spread = solver.tool_contact(q, box_half_width())
    beside = None if contact is None else solver.tool_reach(q) - contact
    if contact is not None and spread <= CONTACT_SPREAD and beside < box_top_offset():
        return _rounded(contact * solver.ik.tool), None
    deepest = solver.deepest_point(q)
    if deepest is None:
        return np.zeros(3), None
    return _rounded(deepest), tuple(float(v) for v in solver.ik.tool)


def grip_point(arm: ArmInfo) -> np.ndarray | None:
    """Where ``arm``'s gripper holds the object, in the ee link's frame, ``(3,)`` (module
    doc); None without a gripper."""
    gripper = arm.gripper
    if gripper is None:
        return None
    return _rounded(np.asarray(gripper.grasp_offset) * (gripper.kind != "parallel"))


def with_points(arm: ArmInfo) -> ArmInfo:
    """``arm`` (at the link's origin) with its derived tool point as its ee point, and its grip
    point where it has a gripper. A gripper arm whose grip point lies on the tool axis, where
    the tool meets the box within :data:`GRIP_PRESS` of it, keeps the grip point in every task
    (the Panda's TCP, 9.5 mm behind its closed fingertips)."""
    tool, axis = derive_tool_point(arm)
    grip = grip_point(arm)
    if grip is not None and axis is None:
        direction = tool_down_solver(arm).ik.tool
        on_axis = np.linalg.norm(grip - direction * (grip @ direction)) < MIN_EE_OFFSET
        if np.linalg.norm(tool - grip) < GRIP_PRESS and on_axis:
            tool = grip
        if arm.gripper.kind != "jaw":
            grip = _tips_clear(arm, tool, grip, direction)
    arm = dataclasses.replace(arm, tool_axis=axis)
    return dataclasses.replace(
        _at(arm, tool),
        tool_offset=tuple(float(v) for v in tool),
        grip_offset=None if grip is None else tuple(float(v) for v in grip),
    )


def _tips_clear(
    arm: ArmInfo, tool: np.ndarray, grip: np.ndarray, direction: np.ndarray
) -> np.ndarray:
    """``grip (3,)`` moved along the tool axis (the unit ``direction (3,)``) towards the closed
    tips (the tool point ``tool (3,)``, on the axis) until they lie at most the held cube's half
    edge less :data:`~mjx_arm.urdf.gripper_layout.TIP_CLEARANCE` beyond it: with the grip
    point at the centre of a cube resting on the table, the fingertips then stay that clearance
    above the table (a jaw's grasp centre keeps the same rule). The xArm6 gripper's tips reach
    3.9 cm past its pads' centre: held there, a 4.5 cm cube put them 1.6 cm into the table."""
    beyond = float((tool - grip) @ direction)
    room = arm.gripper.cube_half - TIP_CLEARANCE
    if beyond <= room:
        return grip
    return _rounded(grip + direction * (beyond - room))


def _at(arm: ArmInfo, point: np.ndarray) -> ArmInfo:
    """``arm`` with its ee point at ``point (3,)`` in the ee link's frame (and the tool's mass
    properties about it)."""
    model = resolve_arm(arm.config).model
    tool = tool_inertia(model, arm.ft_link, arm.ee_link, point)
    return dataclasses.replace(arm, ee_offset=np.asarray(point, float), tool=tool)


def task_arm(arm: ArmInfo, task: TaskConfig) -> ArmInfo:
    """``arm`` with the ee point of ``task``: its grip point in a gripper task, else its tool
    point (the arm itself where that is its ee point already; arms without derived points, as
    the shipped ones and arm files that set ``ee_offset``, keep theirs). The tool axis stays the
    tool point's."""
    grip = arm.grip_offset if task.spec.gripper else None
    want = grip if grip is not None else arm.tool_offset
    if want is None or np.allclose(want, arm.ee_offset, rtol=0.0, atol=1e-9):
        return arm
    return _task_arm_cached(arm, tuple(want))


@functools.cache
def _task_arm_cached(arm: ArmInfo, point: tuple[float, float, float]) -> ArmInfo:
    axis = arm.tool_axis or tuple(float(v) for v in tool_down_solver(arm).ik.tool)
    return _at(dataclasses.replace(arm, tool_axis=axis), np.asarray(point))
