"""What a gripper task reads from the physics, and the quaternion algebra it needs, written once
against an array namespace ``xp``.

Every engine fills one flat ``grip`` vector per reading (:data:`GRIP_LAYOUT`, 10 entries): the
driven finger's closure (0 open, 1 closed), the object's centre (m, world frame) and orientation
(w, x, y, z), and the normal contact force on each of two finger pads (N). The task turns it into
observation keys and its success measures (:mod:`mjx_arm.task.lift`).
"""

from __future__ import annotations

from typing import Any, NamedTuple

GRIP_LAYOUT = (("closure", 1), ("object_pos", 3), ("object_quat", 4), ("pad_force", 2))


def _slices() -> dict[str, slice]:
    out, start = {}, 0
    for key, size in GRIP_LAYOUT:
        out[key] = slice(start, start + size)
        start += size
    return out


GRIP_SLICES = _slices()


class ObjectStart(NamedTuple):
    """A gripper task's object at the start of an episode (drawn by the task).

    Attributes:
        quat: orientation (w, x, y, z), ``(..., 4)``.
        mass: mass (kg), ``(...)``.
        friction: sliding friction of the object and the finger pads, ``(...)``: MuJoCo takes
            the larger of two geoms' values, so both carry it; PyBullet multiplies them, so it
            sets the object's and keeps the pads' 1.0.
    """

    quat: Any
    mass: Any
    friction: Any


def split_grip(grip) -> dict[str, Any]:
    """The named parts of a ``grip (..., 10)`` vector (views)."""
    return {key: grip[..., s] for key, s in GRIP_SLICES.items()}


def quat_mul(xp: Any, a, b):
    """Hamilton product ``a * b`` of quaternions (w, x, y, z), ``(..., 4)``."""
    aw, ax, ay, az = (a[..., i] for i in range(4))
    bw, bx, by, bz = (b[..., i] for i in range(4))
    return xp.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def rotate_inverse(xp: Any, q, v):
    """``v (..., 3)`` expressed in the frame of unit quaternion ``q (..., 4)``: ``R(q)^T v``."""
    w, u = q[..., :1], q[..., 1:]
    # R^T v = v + 2 w (v x u) + 2 u x (u x v)  (the rotation by the conjugate)
    uv = xp.cross(u, v)
    return v - 2.0 * w * uv + 2.0 * xp.cross(u, uv)


def yaw_quat(xp: Any, yaw):
    """Quaternion (w, x, y, z) of a rotation by ``yaw (...)`` (rad) about z, ``(..., 4)``."""
    zero = 0.0 * yaw
    return xp.stack([xp.cos(yaw / 2), zero, zero, xp.sin(yaw / 2)], axis=-1)
