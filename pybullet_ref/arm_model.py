"""The arm as PyBullet drives it: the MuJoCo model's joint servo and its joint-space step, the
self-collision filter and the tool subtree, all looked up from the loaded multibody.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import combinations

import numpy as np

from pybullet_ref.quiet import STDERR, STDOUT, native_output_silenced

with native_output_silenced((STDOUT, STDERR)):  # "pybullet build time: ..."
    import pybullet
    from pybullet_utils.bullet_client import BulletClient

from mjx_arm.envs.arm import ArmInfo, arm_info
from mjx_arm.urdf.arm_config import ArmConfig
from mjx_arm.urdf.convert import load_model

BASE = -1  # PyBullet's link index of a multibody's base


@dataclass(frozen=True)
class JointServo:
    """The joint drive of the converted MuJoCo model, per actuated joint in contract order.

    Attributes:
        kv: velocity gain of the actuator (N m s/rad), ``(n,)``.
        damping: joint damping (N m s/rad), ``(n,)``.
        effort: torque cap of the actuator (N m), ``(n,)``.
        armature: reflected rotor inertia (kg m^2), ``(n,)``.
        finger: the driven finger's velocity gain (N s/m) and force cap (N), for an arm with a
            parallel gripper; else empty.
    """

    kv: tuple[float, ...]
    damping: tuple[float, ...]
    effort: tuple[float, ...]
    armature: tuple[float, ...]
    finger: tuple[float, ...] = ()

    def finger_force(self, speed: float) -> float:
        """The force cap (N) of the finger's velocity motor at command ``speed`` (m/s): the
        MuJoCo servo's press when the finger is blocked, ``kv |speed|``, at most its cap."""
        kv, cap = self.finger
        return min(kv * abs(speed), cap)

    def torque(
        self,
        u: Sequence[float],
        qdot: np.ndarray,
        gravity: Sequence[float],
        mass: np.ndarray,
        external: np.ndarray,
        dt: float,
    ) -> np.ndarray:
        """Joint torques (N m) that make PyBullet's step the MuJoCo model's.

        MuJoCo steps the arm's joints by ``(M + A + dt K) qddot = clip(kv (u - qdot), +-effort)
        - d qdot + tau_ext``: the armature ``A`` only on the diagonal, and the servo's and the
        damping's derivative ``K = kv + d`` implicit (``implicitfast``; a servo at its cap keeps
        ``d`` only). PyBullet has neither, so this solves for MuJoCo's ``qddot`` and returns
        the torque that gives it on PyBullet's own mass matrix:
        ``M qddot - tau_ext + g(q)``. ``tau_ext`` (contacts, Coriolis terms) comes from the
        last substep (:class:`ExternalTorque`): a joint blocked by the box ends up pushing
        ``kv u``, as MuJoCo's does.

        Args:
            u: velocity targets (rad/s), ``(n,)``.
            qdot: joint velocities (rad/s), ``(n,)``.
            gravity: gravity compensation torques (N m), ``(n,)``.
            mass: PyBullet's joint-space mass matrix of the arm joints (kg m^2), ``(n, n)``.
            external: the other generalized forces on the joints (N m), ``(n,)``.
            dt: the physics step (s).

        Returns:
            The torques, ``(n,)``.
        """
        kv, d, effort, armature = self._arrays
        servo = kv * (np.asarray(u, dtype=np.float64) - qdot)
        capped = np.abs(servo) > effort
        servo = np.clip(servo, -effort, effort)
        stiffness = np.where(capped, d, kv + d)
        lhs = mass + np.diag(armature + dt * stiffness)
        qddot = np.linalg.solve(lhs, servo - d * qdot + external)
        return mass @ qddot - external + np.asarray(gravity)

    @functools.cached_property
    def _arrays(self) -> tuple[np.ndarray, ...]:
        return tuple(
            np.array(x, dtype=np.float64)
            for x in (self.kv, self.damping, self.effort, self.armature)
        )


@dataclass
class ExternalTorque:
    """The joints' generalized force that the drive did not apply (contacts, Coriolis and
    centrifugal terms), seen in the last substep: ``M (qdot - qdot_prev) / dt - (tau - g)``.

    Forget it (:meth:`reset`) whenever the joints are set from outside.
    """

    _last: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def reset(self) -> None:
        """Forget the last substep (a reset, a joint state set by hand)."""
        self._last = None

    def estimate(self, qdot: np.ndarray, dt: float) -> np.ndarray:
        """The last substep's external torque (N m), ``(n,)``; zero after a reset."""
        if self._last is None:
            return np.zeros_like(qdot)
        mass, qdot_before, drive = self._last
        return mass @ (qdot - qdot_before) / dt - drive

    def applied(self, mass: np.ndarray, qdot: np.ndarray, torque, gravity) -> None:
        """Note the substep about to run: its mass matrix, velocities and net drive torque."""
        self._last = (mass, qdot, np.asarray(torque) - np.asarray(gravity))


@functools.cache
def _servo_cached(config: ArmConfig, mtime: float, sim_dt: float) -> JointServo:
    del mtime  # part of the cache key only
    arm = arm_info(config)
    model = load_model(arm.urdf, arm.convert_config(sim_dt=sim_dt))
    names = arm.joint_names
    actuators = [model.actuator(name) for name in names]
    joints = [model.joint(name) for name in names]
    finger = ()
    if arm.gripper is not None:
        act = model.actuator(arm.gripper.joint)
        finger = (float(act.gainprm[0]), float(act.forcerange[1]))
    return JointServo(
        kv=tuple(float(a.gainprm[0]) for a in actuators),
        damping=tuple(float(j.damping[0]) for j in joints),
        effort=tuple(float(a.forcerange[1]) for a in actuators),
        armature=tuple(float(j.armature[0]) for j in joints),
        finger=finger,
    )


def joint_servo(arm: ArmInfo, sim_dt: float) -> JointServo:
    """The servo of the MuJoCo model converted from ``arm.urdf`` with its gains computed for
    ``sim_dt`` (a task's servo step; cached per file version)."""
    return _servo_cached(arm.config, arm.urdf.stat().st_mtime, sim_dt)


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
