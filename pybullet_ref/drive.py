"""The joint drive that makes PyBullet's step the MuJoCo model's.

MuJoCo steps the arm's joints by ``(M + A + dt K) qddot = servo - d qdot + tau_ext``: the
armature ``A`` only on the diagonal, the velocity servo ``clip(kv (u - qdot), +-effort)`` and
the joint damping ``d`` implicit (``implicitfast``: ``K = kv + d``, or ``d`` alone for a servo
at its cap). PyBullet has neither an armature nor an implicit servo, so :func:`drive_torque`
solves for MuJoCo's ``qddot`` and returns the torque that gives it on PyBullet's own mass
matrix, ``M qddot - tau_ext + g(q)``.

``tau_ext`` (contacts, Coriolis and centrifugal terms) is not known before the step:
:class:`ExternalTorque` takes it from the last substep, ``M (qdot - qdot_before) / dt - drive``.
A joint blocked by the box then ends up pushing ``kv u``, as MuJoCo's does. That residual also
holds the reaction of a joint limit, which acts on its own joint only: taken for an external
torque, the drive pushed back against it and hammered joints passed their limits by 0.10-0.24
rad. So a joint at a limit (within :data:`LIMIT_MARGIN`) drops the share of the residual that
pushes it away from the limit; PyBullet's limit constraint then stops it alone, as MuJoCo's
limit constraint does.

The alternative, the armature as a rotor disc on each child link and the explicit servo law,
couples parallel joints through the discs (a disc turns with every joint above it): on the
Unitree Z1 that law was unstable at ``sim_dt`` and shook the pitch joints while holding still.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from pybullet_ref.fast.calls import HotCalls

__all__ = [
    "LIMIT_MARGIN",
    "ArmDrive",
    "DriveGains",
    "ExternalTorque",
    "JointLimits",
    "drive_torque",
]

# How close (rad or m) a joint must be to a limit for its residual to count as the limit's.
# Bullet's limit constraint acts only on a step that would cross the limit, and leaves the joint
# on it (within its error reduction, well under this).
LIMIT_MARGIN = 1e-3


@dataclass(frozen=True)
class JointLimits:
    """Position limits of the actuated joints (rad or m), ``(n,)`` each; an unlimited joint
    has ``-inf`` and ``inf``.

    Attributes:
        lower: lower limits, ``(n,)``.
        upper: upper limits, ``(n,)``.
    """

    lower: np.ndarray
    upper: np.ndarray

    @classmethod
    def of(cls, lower: Sequence[float], upper: Sequence[float]) -> JointLimits:
        """From PyBullet's ``getJointInfo`` limits (a joint with ``lower > upper`` is free)."""
        lo, hi = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
        free = lo > hi
        return cls(np.where(free, -np.inf, lo), np.where(free, np.inf, hi))

    def without_reaction(self, q: np.ndarray, residual: np.ndarray) -> np.ndarray:
        """``residual`` (N m), ``(n,)``, less the share a limit could have made: zero where a
        joint at ``q`` ``(n,)`` sits on a limit and the residual pushes it off."""
        on_limit = ((q <= self.lower + LIMIT_MARGIN) & (residual > 0.0)) | (
            (q >= self.upper - LIMIT_MARGIN) & (residual < 0.0)
        )
        return np.where(on_limit, 0.0, residual) if on_limit.any() else residual


@dataclass(frozen=True)
class DriveGains:
    """The MuJoCo model's drive per actuated joint, ``(n,)`` arrays.

    Attributes:
        kv: velocity gain of the actuator (N m s/rad).
        damping: joint damping (N m s/rad).
        effort: torque cap of the actuator (N m).
        armature: reflected rotor inertia (kg m^2).
    """

    kv: np.ndarray
    damping: np.ndarray
    effort: np.ndarray
    armature: np.ndarray

    @classmethod
    def of(cls, kv, damping, effort, armature) -> DriveGains:
        """From sequences of floats."""
        arrays = (np.asarray(x, dtype=np.float64) for x in (kv, damping, effort, armature))
        return cls(*arrays)

    @classmethod
    def of_servo(cls, servo) -> DriveGains:
        """From a :class:`~pybullet_ref.arm_model.JointServo`."""
        return cls.of(servo.kv, servo.damping, servo.effort, servo.armature)


def drive_torque(
    gains: DriveGains,
    u: Sequence[float],
    qdot: np.ndarray,
    gravity: Sequence[float],
    mass: np.ndarray,
    external: np.ndarray,
    dt: float,
) -> np.ndarray:
    """Joint torques (N m), ``(n,)``, that make PyBullet's step the MuJoCo model's.

    Args:
        gains: the MuJoCo model's drive.
        u: velocity targets (rad/s), ``(n,)``.
        qdot: joint velocities (rad/s), ``(n,)``.
        gravity: gravity compensation torques (N m), ``(n,)``.
        mass: PyBullet's joint-space mass matrix of the actuated joints (kg m^2), ``(n, n)``.
        external: the other generalized forces on the joints (N m), ``(n,)``.
        dt: the physics step (s).
    """
    # fewest numpy calls on the common path (no servo at its cap): this runs every substep
    kv, damping, effort = gains.kv, gains.damping, gains.effort
    servo = kv * (np.array(u, dtype=np.float64) - qdot)
    stiffness = kv + damping
    capped = np.abs(servo) > effort
    if capped.any():
        servo = np.minimum(np.maximum(servo, -effort), effort)
        stiffness = np.where(capped, damping, stiffness)
    lhs = mass + np.diag(gains.armature + dt * stiffness)
    qddot = np.linalg.solve(lhs, servo - damping * qdot + external)
    return mass @ qddot - external + np.array(gravity, dtype=np.float64)


@dataclass
class ExternalTorque:
    """The joints' generalized force that the drive did not apply, seen in the last substep.

    Forget it (:meth:`reset`) whenever the joints are set from outside.

    Attributes:
        limits: the joints' limits, whose reactions are kept out.
    """

    limits: JointLimits
    _last: tuple[np.ndarray, np.ndarray, np.ndarray] | None = field(default=None, repr=False)

    def reset(self) -> None:
        """Forget the last substep (a reset, a joint state set by hand)."""
        self._last = None

    def estimate(self, q: np.ndarray, qdot: np.ndarray, dt: float) -> np.ndarray:
        """The last substep's external torque (N m), ``(n,)``, without joint-limit reactions,
        from the joints' state now, ``q`` and ``qdot`` ``(n,)``; zero after a reset."""
        if self._last is None:
            return np.zeros_like(qdot)
        mass, qdot_before, drive = self._last
        residual = mass @ (qdot - qdot_before) / dt - drive
        return self.limits.without_reaction(q, residual)

    def applied(self, mass: np.ndarray, qdot: np.ndarray, torque, gravity) -> None:
        """Note the substep about to run: its mass matrix ``(n, n)``, velocities ``(n,)`` and
        torques ``(n,)`` (the drive's and the gravity compensation in it)."""
        self._last = (mass, qdot, np.asarray(torque) - np.asarray(gravity))


@dataclass
class ArmDrive:
    """The drive of one PyBullet arm: its gains, its observer and where the arm's joints sit
    among the multibody's dofs.

    Attributes:
        gains: the MuJoCo model's drive.
        external: the observer of the last substep's external torque.
        arm_in_dofs: where each actuated joint sits among the dofs (None: they are the dofs).
        dt: the physics step (s).
    """

    gains: DriveGains
    external: ExternalTorque
    arm_in_dofs: tuple[int, ...] | None
    dt: float

    @classmethod
    def of(cls, servo, limits: JointLimits, arm_in_dofs, dt: float) -> ArmDrive:
        """From a :class:`~pybullet_ref.arm_model.JointServo` and the joints' limits."""
        return cls(DriveGains.of_servo(servo), ExternalTorque(limits), arm_in_dofs, dt)

    def reset(self) -> None:
        """Forget the last substep (call it whenever the joints are set from outside)."""
        self.external.reset()

    def torques(
        self,
        calls: HotCalls,
        body: int,
        states: Sequence[tuple],
        target: Callable[[list[float]], Sequence[float]],
    ) -> list[float]:
        """The actuated joints' torques (N m) for the next substep.

        Args:
            calls: the client's bound calls.
            body: the arm's multibody.
            states: every dof's ``getJointStates`` row, now.
            target: the velocity targets (rad/s), ``(n,)``, at the joints' angles ``q``.
        """
        q_dofs = [s[0] for s in states]
        zeros = [0.0] * len(q_dofs)
        gravity = calls.inverse_dynamics(body, q_dofs, zeros, zeros)
        mass = np.asarray(calls.mass_matrix(body, q_dofs))
        if self.arm_in_dofs is not None:  # the arm's joints among the dofs
            pick = self.arm_in_dofs
            states, gravity = [states[i] for i in pick], [gravity[i] for i in pick]
            mass = mass[np.ix_(pick, pick)]
        q = [s[0] for s in states]
        qdot = np.array([s[1] for s in states])
        external = self.external.estimate(np.array(q), qdot, self.dt)
        torque = drive_torque(self.gains, target(q), qdot, gravity, mass, external, self.dt)
        self.external.applied(mass, qdot, torque, gravity)
        return torque.tolist()
