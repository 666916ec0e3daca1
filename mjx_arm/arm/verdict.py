"""Whether an arm can do a task, and why not: what ``mjx-arm arm --check`` prints and what
building a task's env refuses (:func:`mjx_arm.arm.resolve.task_for_arm`), one verdict for both.

A task is refused where the arm has no gripper that holds the task's cube (gripper tasks), where
its tool cannot press the box (Touch), where no tool-down home reaches every target of the task
area, where the farthest target is too slow to reach, or where the task's model does not build
and step: the same conversion, sensor and gripper look-ups and physics steps a CPU MuJoCo env
runs (:func:`build_problem`). So "yes" means the env builds and steps, and "no" means it refuses
with the same reason.
"""

from __future__ import annotations

import functools

import mujoco
import numpy as np

from mjx_arm.arm.facts import ArmInfo
from mjx_arm.arm.points import CONTACT_SPREAD, task_arm
from mjx_arm.arm.setup import MIN_OBJECT_SCALE, ArmSetup, arm_setup
from mjx_arm.task.config import TaskConfig
from mjx_arm.urdf.grippers import CUBE_CLEARANCE
from mjx_arm.urdf.scene_shapes import CUBE_HALF, box_top_offset

MAX_EPISODE_SECONDS = 15.0  # an arm that needs a longer episode is too slow for the task
BUILD_STEPS = 3  # control steps the build check takes from the home pose


def task_verdict(arm: ArmInfo, task: TaskConfig) -> tuple[bool, str]:
    """Whether ``arm`` can do ``task`` as derived, and why not (or a short summary)."""
    if task.spec.gripper:
        reason = gripper_problem(arm)
        if reason:
            return False, reason
    setup = arm_setup(arm, task)
    problem = press_problem(setup, task) if task.uses_contact and not task.spec.gripper else ""
    if problem:
        return False, problem
    how = " with the tool down" if task.uses_contact else ""
    if setup.reached == 0:
        return False, "no tool-down pose over the task area (limits or reach block it)"
    if not setup.covers_area:
        missing = setup.targets - setup.reached
        return False, f"{missing} of {setup.targets} targets out of reach{how}"
    seconds = setup.episode_steps * task.ctrl_dt
    lengthened = setup.episode_steps > task.episode_steps  # the arm's speed asked for it
    if lengthened and seconds > MAX_EPISODE_SECONDS:
        return False, (
            f"too slow: the farthest target takes {setup.travel_time:.1f} s from home at the "
            f"task's joint speeds (an episode of {seconds:.0f} s)"
        )
    problem = build_problem(arm, task)
    if problem:
        return False, problem
    return True, (
        f"every target reachable{how}; area x{setup.workspace_scale:.2f}, episode {seconds:.1f} s"
    )


def press_problem(setup: ArmSetup, task: TaskConfig) -> str:
    """Why the tool cannot press the box top with the ee point on it ("" where it can): no
    shape on the tool axis, a contact too far from the ee point, or shapes around it that
    reach deeper than the box is tall (they meet the table first)."""
    contact = setup.contact_offset
    if contact is None:
        return "no collision shape of the tool on its axis: nothing presses the box"
    if abs(contact) >= task.success_distance:
        return (
            f"the tool meets the box {abs(contact) * 100:.1f} cm from the ee point, beyond the "
            f"{task.success_distance * 100:.0f} cm success radius: set ee_offset in an arm file"
        )
    if setup.contact_spread > CONTACT_SPREAD:
        return (
            f"where the tool meets the box moves {setup.contact_spread * 100:.1f} cm along its "
            "axis as the box turns about it (shapes beside the axis straddle the box at one "
            "turn and land on it at another): a press's depth depends on the turn"
        )
    depth = setup.tool_reach - contact
    if depth >= box_top_offset():
        return (
            f"shapes beside the tool axis reach {depth * 100:.1f} cm past where it meets the box "
            f"(the box is {box_top_offset() * 100:.0f} cm tall): they meet the table first"
        )
    return ""


def gripper_problem(arm: ArmInfo) -> str:
    """Why the arm's gripper cannot hold a gripper task's cube ("" where it can): no gripper,
    or one that opens too little even for the smallest cube (:data:`MIN_OBJECT_SCALE` of the
    shipped one)."""
    if arm.gripper is None:
        return (
            "no gripper: neither prismatic fingers (one driven, the others its <mimic>), nor a "
            "linkage (one driven revolute joint, <mimic> knuckles), nor a jaw (one driven "
            "revolute jaw against the hand)"
        )
    gripper = arm.gripper
    smallest = CUBE_HALF * MIN_OBJECT_SCALE
    if gripper.opening < 2 * smallest + CUBE_CLEARANCE or gripper.cube_half < smallest - 1e-9:
        held = (
            f"holds at most a {gripper.cube_half * 200:.1f} cm cube"
            if gripper.cube_half > 0
            else "holds no cube"
        )
        square = " square (its pads' faces within 10 degrees of parallel)" * (gripper.kind == "jaw")
        return (
            f"the gripper opens {max(gripper.opening, 0.0) * 100:.1f} cm and {held}{square}, "
            f"less than the smallest Lift cube ({smallest * 200:.2f} cm)"
        )
    return ""


def build_problem(arm: ArmInfo, task: TaskConfig) -> str:
    """Why ``task``'s CPU MuJoCo model of ``arm`` does not build or step ("" where it does):
    the task model converted with the task's scene and pads, the ee, F/T and gripper sensors
    looked up, then :data:`BUILD_STEPS` control steps from the derived home at rest; cached
    per arm and task config."""
    return _build_cached(task_arm(arm, task), task)


@functools.cache
def _build_cached(arm: ArmInfo, task: TaskConfig) -> str:
    from mjx_arm.arm.model_io import GripReader, SensorReader, arm_model
    from mjx_arm.urdf.errors import UrdfError

    filled = arm_setup(arm, task).fill(task)
    try:
        model = arm_model(arm, filled)
        reader = SensorReader(model, arm)
        if filled.spec.gripper:
            GripReader(model, arm)
        data = mujoco.MjData(model)
        data.qpos[reader.qpos_adr] = filled.home_qpos
        for _ in range(BUILD_STEPS * filled.n_substeps):
            mujoco.mj_step(model, data)
    except (UrdfError, ValueError, KeyError, mujoco.FatalError) as exc:
        line = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        return f"the task's model does not build: {line[:200]}"
    if not (np.isfinite(data.qpos).all() and np.isfinite(data.qvel).all()):
        return "the task's model does not step: its state is not finite after the first steps"
    return ""
