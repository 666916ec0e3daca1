"""The tared wrist force/torque reading: the external wrench on the tool, in the ee frame.

A wrist F/T sensor between the flange and the tool measures what the arm exerts on the tool. The
tool's own weight and inertia are in that reading; a tared sensor removes them, so it reads zero
when nothing touches the tool. With the tool subtree of mass ``m``, centre of mass ``c`` and
inertia ``I`` (about ``c``), Newton-Euler gives, in the sensor frame:

    F_ext = m * acc - F_s
    tau_ext(c) = I @ alpha + omega x (I @ omega) - tau_s - (s - c) x F_s

where ``F_s, tau_s`` is the sensor reading (force and torque about the sensor point ``s``),
``acc = a_c - g`` is what an accelerometer at ``c`` reads, ``omega`` and ``alpha`` the tool's
angular velocity and acceleration. The wrench is then moved to the ee point and rotated into the
ee frame. Every engine feeds its own measurements through :func:`external_wrench`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from mjx_arm.urdf.model import RobotModel


@dataclass(frozen=True)
class ToolInertia:
    """Mass properties of the tool subtree below the F/T joint, in the sensor (tool) frame.

    Attributes:
        mass: subtree mass (kg).
        com: centre of mass (m), shape ``(3,)``.
        inertia: inertia about the centre of mass (kg m^2), shape ``(3, 3)``.
        ee_pos: the ee point (m), shape ``(3,)``.
        ee_rot: rotation from the sensor frame to the ee frame, shape ``(3, 3)``; a vector
            ``v_s`` in the sensor frame is ``ee_rot @ v_s`` in the ee frame.
    """

    mass: float
    com: np.ndarray
    inertia: np.ndarray
    ee_pos: np.ndarray
    ee_rot: np.ndarray


def tool_inertia(model: RobotModel, ft_joint: str, ee_link: str) -> ToolInertia:
    """Mass properties of everything below ``ft_joint``, from the URDF, in the sensor frame."""
    root = model.joints[ft_joint].child
    frames = {root: np.eye(4)}
    for joint in model.joints_in_tree_order():
        if joint.parent in frames:
            frames[joint.child] = frames[joint.parent] @ joint.origin.matrix()
    mass, first = 0.0, np.zeros(3)
    parts = []
    for name, frame in frames.items():
        inertial = model.links[name].inertial
        if inertial is None or inertial.mass <= 0:
            continue
        pose = frame @ inertial.origin.matrix()
        rot = pose[:3, :3]
        parts.append((inertial.mass, pose[:3, 3], rot @ inertial.inertia @ rot.T))
        mass += inertial.mass
        first += inertial.mass * pose[:3, 3]
    com = first / mass
    inertia = np.zeros((3, 3))
    for m, p, i_local in parts:
        r = p - com
        inertia += i_local + m * (np.dot(r, r) * np.eye(3) - np.outer(r, r))  # parallel axis
    ee = frames[ee_link]
    return ToolInertia(mass, com, inertia, ee[:3, 3].copy(), ee[:3, :3].T.copy())


def external_wrench(xp: Any, force_s, torque_s, acc, omega, alpha, tool: ToolInertia):
    """External wrench on the tool (fx, fy, fz, tx, ty, tz) in the ee frame about the ee point.

    Args:
        xp: ``numpy`` or ``jax.numpy``.
        force_s: force the arm exerts on the tool at the sensor (N), sensor frame, ``(..., 3)``.
        torque_s: torque the arm exerts on the tool about the sensor point (N m), ``(..., 3)``.
        acc: accelerometer reading at the tool's centre of mass, ``a_c - g`` (m/s^2), ``(..., 3)``.
        omega: tool angular velocity (rad/s), sensor frame, ``(..., 3)``.
        alpha: tool angular acceleration (rad/s^2), sensor frame, ``(..., 3)``.
        tool: the tool's mass properties.

    Returns:
        The wrench, shape ``(..., 6)``, not yet clipped.
    """
    com = xp.asarray(tool.com)
    inertia = xp.asarray(tool.inertia)
    f_ext = tool.mass * acc - force_s
    i_alpha = xp.einsum("ij,...j->...i", inertia, alpha)
    i_omega = xp.einsum("ij,...j->...i", inertia, omega)
    tau_c = i_alpha + xp.cross(omega, i_omega) - torque_s - xp.cross(-com, force_s)
    # moment about the ee point: tau_ee = tau_c + (c - ee) x F_ext
    tau_ee = tau_c + xp.cross(com - xp.asarray(tool.ee_pos), f_ext)
    rot = xp.asarray(tool.ee_rot)
    f_ee = xp.einsum("ij,...j->...i", rot, f_ext)
    t_ee = xp.einsum("ij,...j->...i", rot, tau_ee)
    return xp.concatenate([f_ee, t_ee], axis=-1)
