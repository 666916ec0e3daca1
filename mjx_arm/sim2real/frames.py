"""Is the simulated base frame where the robot's is? A check against a tf lookup.

A policy acts on positions in the base frame (the target, the end-effector pose). If the robot's
base frame, as tf reports it in the world (or map) frame, is shifted or turned against the one
the simulation assumed, every target lands in the wrong place. :func:`check_frame_alignment`
measures that offset and names the axis that is off.

Quaternions here are in tf's order, ``(x, y, z, w)``; the task contract's observations use
``(w, x, y, z)`` (see :meth:`Pose.from_wxyz`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

AXES = ("x", "y", "z")
ROTATION_NAMES = ("roll (about x)", "pitch (about y)", "yaw (about z)")


class FrameAlignmentError(AssertionError):
    """The simulated and the robot's base frames differ by more than the tolerance."""


@dataclass(frozen=True)
class Pose:
    """A frame in a parent frame: position and unit quaternion in tf order.

    Attributes:
        position: origin (m), ``(3,)``.
        quat_xyzw: orientation, unit quaternion ``(x, y, z, w)``, ``(4,)``.
    """

    position: np.ndarray
    quat_xyzw: np.ndarray

    def __post_init__(self) -> None:
        position = np.array(self.position, dtype=np.float64)
        quat = np.array(self.quat_xyzw, dtype=np.float64)
        if position.shape != (3,) or quat.shape != (4,):
            raise ValueError(f"a pose needs 3 + 4 values, got {position.shape} and {quat.shape}")
        norm = float(np.linalg.norm(quat))
        if not (np.isfinite(position).all() and np.isfinite(quat).all() and norm > 1e-9):
            raise ValueError(f"a pose needs finite values and a non-zero quaternion: {quat}")
        object.__setattr__(self, "position", position)
        object.__setattr__(self, "quat_xyzw", quat / norm)

    @classmethod
    def from_wxyz(cls, position: Sequence[float], quat_wxyz: Sequence[float]) -> Pose:
        """A pose from the contract's quaternion order ``(w, x, y, z)``."""
        w, x, y, z = quat_wxyz
        return cls(np.asarray(position), np.array([x, y, z, w]))

    @classmethod
    def from_tf(cls, transform: Any) -> Pose:
        """A pose from a tf lookup: a ``geometry_msgs/Transform`` (or ``TransformStamped``)
        message or its dict form ``{"translation": {x, y, z}, "rotation": {x, y, z, w}}``."""
        if _get(transform, "transform") is not None:  # TransformStamped
            transform = _get(transform, "transform")
        t, r = _get(transform, "translation"), _get(transform, "rotation")
        if t is None or r is None:
            raise ValueError("a tf transform needs 'translation' and 'rotation'")
        position = [float(_get(t, k)) for k in AXES]
        quat = [float(_get(r, k)) for k in ("x", "y", "z", "w")]
        return cls(np.array(position), np.array(quat))


def _get(obj: Any, key: str) -> Any:
    return obj.get(key) if isinstance(obj, Mapping) else getattr(obj, key, None)


def as_pose(value: Any) -> Pose:
    """A :class:`Pose`, a tf transform (see :meth:`Pose.from_tf`), or 7 numbers
    ``(x, y, z, qx, qy, qz, qw)``, or a pair ``(position (3,), quat_xyzw (4,))``."""
    if isinstance(value, Pose):
        return value
    if isinstance(value, Mapping) or hasattr(value, "translation") or hasattr(value, "transform"):
        return Pose.from_tf(value)
    if isinstance(value, tuple | list) and len(value) == 2:
        return Pose(np.asarray(value[0]), np.asarray(value[1]))
    flat = np.asarray(value, dtype=np.float64).reshape(-1)
    if flat.shape != (7,):
        raise ValueError(f"a pose is 7 numbers (x, y, z, qx, qy, qz, qw), got {flat.shape}")
    return Pose(flat[:3], flat[3:])


@dataclass(frozen=True)
class FrameAlignment:
    """The offset of the robot's base frame from the simulated one.

    Attributes:
        translation: robot origin minus simulated origin, in the parent frame (m), ``(3,)``.
        translation_error: its norm (m).
        rotation: rotation vector (axis times angle, rad) turning the simulated frame into the
            robot's, about the simulated frame's axes: roll, pitch, yaw parts, ``(3,)``.
        rotation_error: its angle (rad), in [0, pi].
        tol_m, tol_rad: the tolerances checked.
    """

    translation: np.ndarray
    translation_error: float
    rotation: np.ndarray
    rotation_error: float
    tol_m: float
    tol_rad: float

    @property
    def translation_ok(self) -> bool:
        """The origins are within ``tol_m``."""
        return self.translation_error <= self.tol_m

    @property
    def rotation_ok(self) -> bool:
        """The orientations are within ``tol_rad``."""
        return self.rotation_error <= self.tol_rad

    @property
    def ok(self) -> bool:
        """Both within tolerance."""
        return self.translation_ok and self.rotation_ok

    def message(self) -> str:
        """One line per quantity, naming each axis that is off."""
        lines = [
            f"translation error {self.translation_error * 1000:.1f} mm "
            f"(tolerance {self.tol_m * 1000:.1f} mm)"
            + _axes_off(self.translation, self.tol_m, AXES, lambda v: f"{v:+.4f} m"),
            f"rotation error {math.degrees(self.rotation_error):.2f} deg "
            f"(tolerance {math.degrees(self.tol_rad):.2f} deg)"
            + _axes_off(
                self.rotation, self.tol_rad, ROTATION_NAMES, lambda v: f"{math.degrees(v):+.2f} deg"
            ),
        ]
        return "; ".join(lines)


def _axes_off(vector: np.ndarray, tol: float, names: Sequence[str], fmt) -> str:
    """``": x off by +0.3000 m"``-style text for the components that break the tolerance.

    When the norm is above ``tol``, at least one component is above ``tol / sqrt(3)``: those are
    named. Empty when the norm is within ``tol``.
    """
    if float(np.linalg.norm(vector)) <= tol:
        return ""
    off = [f"{names[i]} off by {fmt(vector[i])}" for i in range(3) if abs(vector[i]) > tol / 3**0.5]
    return ": " + ", ".join(off)


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` of quaternions in ``(x, y, z, w)`` order, ``(4,)``."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def quat_to_rotvec(q: np.ndarray) -> np.ndarray:
    """Rotation vector (axis times angle, rad, angle in [0, pi]) of a unit quaternion
    ``(x, y, z, w)``, ``(3,)``."""
    q = q if q[3] >= 0 else -q  # q and -q are the same rotation; take the shorter way round
    s = float(np.linalg.norm(q[:3]))
    if s < 1e-12:
        return 2.0 * q[:3]  # small-angle limit
    return 2.0 * math.atan2(s, q[3]) * q[:3] / s


def check_frame_alignment(
    sim_base_pose: Any,
    robot_base_pose: Any,
    tol_m: float = 0.005,
    tol_rad: float = 0.01,
    raise_on_failure: bool = True,
) -> FrameAlignment:
    """Compare the simulated base frame with the robot's, both in the same parent frame.

    Args:
        sim_base_pose: the base pose the simulation assumes (the contract puts the base at the
            world origin: ``Pose(np.zeros(3), [0, 0, 0, 1])``). A :class:`Pose`, a tf transform
            or 7 numbers ``(x, y, z, qx, qy, qz, qw)``.
        robot_base_pose: the robot's base pose as a tf lookup gives it (same forms).
        tol_m: largest allowed distance between the origins (m).
        tol_rad: largest allowed rotation angle between the frames (rad).
        raise_on_failure: raise when a tolerance is broken (else return the report).

    Returns:
        The measured offsets.

    Raises:
        FrameAlignmentError: a tolerance is broken (with ``raise_on_failure``); the message
            names each axis that is off and by how much.
    """
    sim, robot = as_pose(sim_base_pose), as_pose(robot_base_pose)
    translation = robot.position - sim.position
    conj = sim.quat_xyzw * np.array([-1.0, -1.0, -1.0, 1.0])
    rotation = quat_to_rotvec(quat_multiply(conj, robot.quat_xyzw))
    report = FrameAlignment(
        translation=translation,
        translation_error=float(np.linalg.norm(translation)),
        rotation=rotation,
        rotation_error=float(np.linalg.norm(rotation)),
        tol_m=float(tol_m),
        tol_rad=float(tol_rad),
    )
    if raise_on_failure and not report.ok:
        raise FrameAlignmentError(f"base frames do not line up: {report.message()}")
    return report
