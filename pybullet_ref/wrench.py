"""The wrist F/T reading of the PyBullet env: the tared sensor, or the tool's contacts.

Wrist F/T: ``enableJointForceTorqueSensor`` on the fixed joint ``ft_sensor_joint``. Found with
the tool hanging at rest in several orientations: ``getJointState(ft)[2]`` is the force the arm
exerts on the tool subtree, in the tool link frame (the contract's sign), with the torque taken
about the tool link's centre of mass, not the joint; it is moved to the joint here. The tare
(:func:`tared_wrench`) is :func:`mjx_arm.task.wrench.external_wrench`'s, with accelerations by
finite differences over the last substep, in Python floats (:mod:`pybullet_ref.fast.vec3`) and
one array at the end. In fast free motion the tared reading stays below 0.6 N and 0.04 N m:
Bullet's joint reaction carries a small velocity-product term when several joints turn at once.

An arm without a fixed F/T joint takes its reading at the last arm joint. PyBullet's reaction
at a motorised joint carries the motor torque and Bullet's own constraint terms: tared, it
still read up to 50 N m on a Panda in free motion. There the reading is instead the sum of
the contact forces on the links of the tool subtree (normal and friction, about the ee point,
:func:`contact_wrench`): zero in free motion, as MuJoCo's tared sensor reads.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pybullet_ref.quiet import STDERR, STDOUT, native_output_silenced

with native_output_silenced((STDOUT, STDERR)):  # "pybullet build time: ..."
    import pybullet

from mjx_arm.task.wrench import external_wrench_features
from pybullet_ref.fast.vec3 import Vec3, add, cross, rate, rotate, rotate_back

GRAVITY = (0.0, 0.0, -9.81)
_UP = tuple(-g for g in GRAVITY)  # minus gravity


@dataclass(frozen=True)
class ToolTare:
    """What the tare needs of the tool, fixed for an env.

    Attributes:
        com: the tool link's centre of mass in the tool link frame (m), 3 floats: PyBullet
            reports the F/T torque about this point.
        com_offset: from the tool link's centre of mass to the tool subtree's (m), 3 floats,
            in the tool link frame.
        dt: the physics step (s) the accelerations are differenced over.
        wrench_matrix: the tool's :attr:`~mjx_arm.task.wrench.ToolInertia.wrench_matrix`.
    """

    com: Vec3
    com_offset: Vec3
    dt: float
    wrench_matrix: np.ndarray


def tared_wrench(
    tare: ToolTare,
    reaction: Sequence[float],
    before: tuple[Sequence[float], Sequence[float]],
    tool_state: Sequence,
) -> np.ndarray:
    """Tared external wrench on the tool in the ee frame, ``(6,)``, from PyBullet's F/T.

    Args:
        tare: the tool's constants.
        reaction: ``getJointState(ft)[2]``: the force the arm exerts on the tool link, in the
            tool link frame, and the torque about the tool link's centre of mass.
        before: the world velocity of the tool link's centre of mass and its angular velocity
            before the last substep, 3 floats each.
        tool_state: ``getLinkState(tool)`` with velocities, after the step.
    """
    rot, dt = pybullet.getMatrixFromQuaternion(tool_state[5]), tare.dt
    force = reaction[:3]
    torque = add(reaction[3:], cross(tare.com, force))  # about the origin
    (v0, w0), v1, w1 = before, tool_state[6], tool_state[7]
    alpha = rate(w0, w1, dt)
    offset = rotate(rot, tare.com_offset)  # link com -> subtree com
    a_com = add(add(rate(v0, v1, dt), cross(alpha, offset)), cross(w1, cross(w1, offset)))
    acc = rotate_back(rot, add(a_com, _UP))  # a_com - g
    x = external_wrench_features(force, torque, acc, rotate_back(rot, w1), rotate_back(rot, alpha))
    return np.array(x).dot(tare.wrench_matrix)  # external_wrench's value


def contact_wrench(
    body: int,
    tool_links: frozenset[int],
    ee_pos: np.ndarray,
    ee_xyzw: Sequence[float],
    contacts: Sequence[tuple],
) -> np.ndarray:
    """External wrench on the tool in the ee frame about the ee point, ``(6,)``: the sum of the
    contact forces (normal and friction) on the ``tool_links`` of the arm ``body``.

    Args:
        body: the arm's body id.
        tool_links: the links of the tool subtree.
        ee_pos: the ee point (m), ``(3,)``.
        ee_xyzw: the ee orientation (x, y, z, w).
        contacts: the arm's ``getContactPoints(bodyA=arm)`` rows.
    """
    force, torque = np.zeros(3), np.zeros(3)
    for contact in contacts:
        if contact[2] == body or contact[3] not in tool_links:
            continue
        f = contact[9] * np.array(contact[7])  # normal force along the normal on B (to A)
        f += contact[10] * np.array(contact[11]) + contact[12] * np.array(contact[13])
        force += f
        torque += cross(np.array(contact[5]) - ee_pos, f)
    rot = np.array(pybullet.getMatrixFromQuaternion(ee_xyzw)).reshape(3, 3)
    return np.concatenate([rot.T @ force, rot.T @ torque])
