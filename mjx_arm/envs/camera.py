"""The render camera of a task on its arm, the same in every engine.

It looks along the scene's view direction (from :data:`~mjx_arm.urdf.scene_shapes.CAMERA_EYE`
towards ``CAMERA_TARGET``, with ``CAMERA_FOVY``) at the arm in the task's home pose and at the
task's target area, from just far enough to hold them all (:func:`mjx_arm.video.frame_points`):
a tall arm is not cut at the top, a small one is not lost in the table.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import numpy as np

from mjx_arm.urdf.kinematics import link_frames
from mjx_arm.urdf.model import parse_urdf
from mjx_arm.urdf.scene_shapes import CAMERA_EYE, CAMERA_FOVY, CAMERA_TARGET
from mjx_arm.video import CameraView, frame_points

if TYPE_CHECKING:
    from mjx_arm.arm.resolve import ArmTask

# Room (m) around each link's origin for the link's own bulk (the UR5e's shoulder and elbow
# housings are about 0.075 m in radius).
LINK_RADIUS = 0.09
# The scene's view: its direction and field of view; the eye's distance is framed per arm.
SCENE_VIEW = CameraView(CAMERA_EYE, CAMERA_TARGET, CAMERA_FOVY)


def task_camera(arm_task: ArmTask, aspect: float) -> CameraView:
    """The camera that frames ``arm_task``'s arm in its home pose and its target area in a
    frame of ``aspect`` (width over height)."""
    task = arm_task.task
    low, high = task.target_box()
    corners = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1])
                        for z in (low[2], high[2])])  # fmt: skip
    links = arm_points(str(arm_task.arm.urdf), arm_task.arm.joint_names, task.home_qpos)
    return frame_points(np.concatenate([corners, links]), aspect, SCENE_VIEW)


@functools.cache
def arm_points(urdf: str, joints: tuple[str, ...], qpos: tuple[float, ...]) -> np.ndarray:
    """Points around every link of the arm in ``urdf`` with ``joints`` at ``qpos`` (rad) and
    any other joint at 0 (or its nearest limit): each link's origin and the six points
    :data:`LINK_RADIUS` from it along the axes, ``(7 * links, 3)`` (m, base frame)."""
    model = parse_urdf(urdf)
    q = dict(zip(joints, qpos, strict=True))
    for joint in model.actuated_joints:
        if joint.name not in q and joint.mimic is None:
            limit = joint.limit
            low, high = (limit.lower, limit.upper) if limit is not None else (0.0, 0.0)
            q[joint.name] = float(np.clip(0.0, low, high)) if low <= high else 0.0
    origins = np.array([frame[:3, 3] for frame in link_frames(model, q).values()])
    offsets = np.vstack([np.zeros(3), LINK_RADIUS * np.eye(3), -LINK_RADIUS * np.eye(3)])
    return (origins[:, None, :] + offsets[None, :, :]).reshape(-1, 3)
