"""The arm as PyBullet drives it: the MuJoCo model's joint servo (applied by
:mod:`pybullet_ref.drive`), the self-collision filter and the tool subtree, all looked up from the
loaded multibody.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import combinations
from typing import NamedTuple

import mujoco
import numpy as np

from pybullet_ref.quiet import STDERR, STDOUT, native_output_silenced

with native_output_silenced((STDOUT, STDERR)):  # "pybullet build time: ..."
    import pybullet
    from pybullet_utils.bullet_client import BulletClient

from mjx_arm.arm.config import ArmConfig
from mjx_arm.arm.info import ArmInfo, arm_info
from mjx_arm.urdf.convert import load_model
from pybullet_ref.drive import JointLimits

BASE = -1  # PyBullet's link index of a multibody's base


class FingerDrive(NamedTuple):
    """The driven finger's servo in the MuJoCo model.

    Attributes:
        kv: velocity gain (N s/m).
        cap: force cap (N).
        damping: the joint damping (N s/m) it drives against: its own plus each ``<mimic>``
            follower's times the multiplier squared (MuJoCo's joint equality moves them
            together).
    """

    kv: float
    cap: float
    damping: float


@dataclass(frozen=True)
class JointServo:
    """The joint drive of the converted MuJoCo model, per actuated joint in contract order.

    Attributes:
        kv: velocity gain of the actuator (N m s/rad), ``(n,)``.
        damping: joint damping (N m s/rad), ``(n,)``.
        effort: torque cap of the actuator (N m), ``(n,)``.
        armature: reflected rotor inertia (kg m^2), ``(n,)``.
        finger: the driven finger's servo, for an arm with a parallel gripper; else None.
    """

    kv: tuple[float, ...]
    damping: tuple[float, ...]
    effort: tuple[float, ...]
    armature: tuple[float, ...]
    finger: FingerDrive | None = None

    def finger_force(self, speed: float) -> float:
        """The force cap (N) of the finger's velocity motor at command ``speed`` (m/s): the
        MuJoCo servo's press when the finger is blocked, ``kv |speed|``, at most its cap."""
        return min(self.finger.kv * abs(speed), self.finger.cap)

    def finger_speed(self, speed: float) -> float:
        """The target (m/s) of the finger's velocity motor at command ``speed`` (m/s): the
        MuJoCo servo's free speed, where its push ``kv (speed - v)`` meets the fingers' damping
        ``d v``: ``speed kv / (kv + d)`` (0.89 ``speed`` on the shipped gripper; a motor at
        ``speed`` itself closed the fingers 12 % faster than MuJoCo)."""
        kv = self.finger.kv
        return speed * kv / (kv + self.finger.damping)


@functools.cache
def _servo_cached(config: ArmConfig, mtime: float, sim_dt: float) -> JointServo:
    del mtime  # part of the cache key only
    arm = arm_info(config)
    model = load_model(arm.urdf, arm.convert_config(sim_dt=sim_dt))
    names = arm.joint_names
    actuators = [model.actuator(name) for name in names]
    joints = [model.joint(name) for name in names]
    finger = None
    if arm.gripper is not None:
        act = model.actuator(arm.gripper.joint)
        damping = _drive_damping(model, model.joint(arm.gripper.joint).id)
        finger = FingerDrive(float(act.gainprm[0]), float(act.forcerange[1]), damping)
    return JointServo(
        kv=tuple(float(a.gainprm[0]) for a in actuators),
        damping=tuple(float(j.damping[0]) for j in joints),
        effort=tuple(float(a.forcerange[1]) for a in actuators),
        armature=tuple(float(j.armature[0]) for j in joints),
        finger=finger,
    )


def _drive_damping(model, joint: int) -> float:
    """The damping (N s/m or N m s/rad) a drive on ``joint`` meets: the joint's own plus, for
    each active joint equality that makes another joint follow it (``q_f = c0 + c1 q + ...``),
    that joint's times ``c1 ** 2`` (its damping force mapped onto ``joint``'s coordinate)."""
    damping = float(model.dof_damping[model.jnt_dofadr[joint]])
    for i in range(model.neq):
        joint_eq = model.eq_type[i] == mujoco.mjtEq.mjEQ_JOINT and model.eq_active0[i]
        if joint_eq and model.eq_obj2id[i] == joint and model.eq_obj1id[i] >= 0:
            follower = model.jnt_dofadr[model.eq_obj1id[i]]
            damping += float(model.eq_data[i][1]) ** 2 * float(model.dof_damping[follower])
    return damping


def joint_servo(arm: ArmInfo, sim_dt: float) -> JointServo:
    """The servo of the MuJoCo model converted from ``arm.urdf`` with its gains computed for
    ``sim_dt`` (a task's servo step; cached per file version)."""
    return _servo_cached(arm.config, arm.urdf.stat().st_mtime, sim_dt)


@dataclass(frozen=True)
class ArmIds:
    """PyBullet indices of the arm, looked up by name (link index = joint index).

    Attributes:
        joints: the n actuated joints, contract order.
        ft: the joint of the wrist F/T reading (the fixed F/T joint, or the last arm joint);
            its child link is the tool link.
        ee: the end-effector link.
        read: what one ``getJointStates`` call reads: ``joints`` then ``ft``.
        dofs: every moving joint (the arm's and a gripper's): inverse dynamics needs them all.
        arm_in_dofs: where each of ``joints`` sits in ``dofs``.
        tool_links: where the F/T point is an arm joint (no fixed F/T joint), the links of the
            tool subtree, whose contacts make the reading; else empty (the F/T sensor reads).
        tool_com: the tool link's centre of mass in the tool link frame (m), ``(3,)``; PyBullet
            reports the F/T torque about this point.
        limits: the position limits of ``joints``.
        self_collision_off: arm link pairs whose contacts are disabled (empty: no self-collision).
        finger, finger_lower, pads, pad_regions, gripper_start: see
            :func:`pybullet_ref.gripper.gripper_ids`.
    """

    joints: tuple[int, ...]
    ft: int
    ee: int
    read: tuple[int, ...]
    dofs: tuple[int, ...]
    arm_in_dofs: tuple[int, ...]
    tool_links: frozenset[int]
    tool_com: np.ndarray
    limits: JointLimits
    self_collision_off: tuple[tuple[int, int], ...]
    finger: int = -1
    finger_lower: float = 0.0
    pads: tuple[int, ...] = ()
    pad_regions: tuple = ()
    gripper_start: tuple[tuple[int, float], ...] = ()


def subtree_links(infos: Sequence[tuple], root: int) -> frozenset[int]:
    """Link ``root`` and every link below it, from ``getJointInfo`` rows (index 16: parent)."""
    links = {root}
    for info in infos:  # parents come before their children
        if info[16] in links:
            links.add(info[0])
    return frozenset(links)


def excluded_pairs(client: BulletClient, arm: int) -> tuple[tuple[int, int], ...]:
    """Arm link pairs whose contacts are disabled, mirroring MuJoCo's filtering.

    MuJoCo skips contacts inside one rigid group of links joined by fixed joints (a weld) and
    between a weld and its parent weld (``filterparent``); the converter adds excludes for link
    pairs in contact in the reference pose q = 0. The same rules here: welds and parents from the
    joint tree, contacts at q = 0 from ``getClosestPoints`` (penetration only). Call it with the
    arm at q = 0.

    Returns:
        Sorted pairs of link indices (-1 = base), each ``(i, j)`` with ``i < j``.
    """
    n = client.getNumJoints(arm)
    infos = [client.getJointInfo(arm, j) for j in range(n)]

    def weld(link: int) -> int:
        while link != BASE and infos[link][2] == pybullet.JOINT_FIXED:
            link = infos[link][16]
        return link

    def parent_weld(link: int) -> int | None:
        w = weld(link)
        return None if w == BASE else weld(infos[w][16])

    def touching(i: int, j: int) -> bool:
        points = client.getClosestPoints(arm, arm, 0.0, linkIndexA=i, linkIndexB=j)
        return any(point[8] < 0.0 for point in points)

    off = set()
    for i, j in combinations(range(BASE, n), 2):
        wi, wj = weld(i), weld(j)
        if wi == wj or parent_weld(i) == wj or parent_weld(j) == wi or touching(i, j):
            off.add((i, j))
    return tuple(sorted(off))
