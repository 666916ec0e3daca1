"""Forward kinematics of a parsed URDF in numpy: the pose of every link for joint positions ``q``.

A link's frame is its parent's frame times the joint origin times the joint motion: a rotation
by ``q`` about the joint axis (revolute, continuous) or a translation by ``q`` along it
(prismatic). Fixed joints (and floating or planar ones, which this package does not move) add
only their origin.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from mjx_arm.urdf.model import Joint, RobotModel

JointPositions = Mapping[str, float] | np.ndarray


def joint_motion(joint: Joint, value: float) -> np.ndarray:
    """Transform of ``joint`` moved by ``value`` (rad or m) in its own frame, shape ``(4, 4)``."""
    t = np.eye(4)
    axis = np.asarray(joint.axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    if joint.type in ("revolute", "continuous"):
        x, y, z = axis
        c, s = np.cos(value), np.sin(value)
        k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
        t[:3, :3] = np.eye(3) + s * k + (1.0 - c) * (k @ k)  # Rodrigues
    elif joint.type == "prismatic":
        t[:3, 3] = value * axis
    return t


def joint_positions(model: RobotModel, q: JointPositions) -> dict[str, float]:
    """Joint positions by name.

    Args:
        model: the parsed URDF.
        q: a mapping from joint name to position, or an array of shape ``(n,)`` in
            ``model.actuated_joints`` order. A mapping may leave out a ``<mimic>`` joint, which
            then follows its leader: ``multiplier * q_leader + offset``.

    Raises:
        ValueError: an array of the wrong length, or a mapping without a movable joint.
    """
    joints = model.actuated_joints
    if not isinstance(q, Mapping):
        values = np.asarray(q, dtype=float).reshape(-1)
        if values.shape != (len(joints),):
            raise ValueError(f"expected {len(joints)} joint positions, got shape {values.shape}")
        return {j.name: float(v) for j, v in zip(joints, values, strict=True)}
    out = {name: float(v) for name, v in q.items()}
    for j in joints:
        if j.name not in out and j.mimic is not None and j.mimic in out:
            out[j.name] = j.mimic_multiplier * out[j.mimic] + j.mimic_offset
    missing = [j.name for j in joints if j.name not in out]
    if missing:
        raise ValueError(f"no position given for joints {missing}")
    return out


def link_frames(model: RobotModel, q: JointPositions) -> dict[str, np.ndarray]:
    """Pose of every link in the root link's frame.

    Args:
        model: the parsed URDF.
        q: joint positions, see :func:`joint_positions`; shape ``(n,)`` as an array.

    Returns:
        Link name -> homogeneous transform, shape ``(4, 4)``, root link first.
    """
    values = joint_positions(model, q)
    frames = {model.root_link: np.eye(4)}
    for joint in model.joints_in_tree_order():
        motion = joint_motion(joint, values[joint.name]) if joint.movable else np.eye(4)
        frames[joint.child] = frames[joint.parent] @ joint.origin.matrix() @ motion
    return frames


def link_pose(model: RobotModel, q: JointPositions, link: str) -> np.ndarray:
    """Pose of ``link`` in the root link's frame, shape ``(4, 4)``.

    Args:
        model: the parsed URDF.
        q: joint positions, see :func:`joint_positions`.
        link: name of the link.

    Raises:
        KeyError: ``link`` is not a link of ``model``.
    """
    if link not in model.links:
        raise KeyError(f"no link named {link!r}")
    frame = np.eye(4)
    values = joint_positions(model, q)
    for joint in model.chain_to(link):
        motion = joint_motion(joint, values[joint.name]) if joint.movable else np.eye(4)
        frame = frame @ joint.origin.matrix() @ motion
    return frame
