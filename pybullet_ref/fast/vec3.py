"""Three-vectors and rotations in Python floats, for one env's read-out at every step.

Bullet hands out tuples of floats; on 3-vectors numpy's cost per call (a few microseconds for
a 3x3 product or a cross product, more than the arithmetic) is most of the work. The PyBullet
env composes the tared wrench's inputs with these and builds one array at the end.

A rotation is PyBullet's ``getMatrixFromQuaternion``: 9 floats, row-major.
"""

from __future__ import annotations

from collections.abc import Sequence

Vec3 = tuple[float, float, float]


def cross(a: Sequence[float], b: Sequence[float]) -> Vec3:
    """``a x b`` (the products and differences of ``np.cross``)."""
    a0, a1, a2 = a
    b0, b1, b2 = b
    return (a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)


def add(a: Sequence[float], b: Sequence[float]) -> Vec3:
    """``a + b``."""
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def rate(before: Sequence[float], after: Sequence[float], dt: float) -> Vec3:
    """``(after - before) / dt``: a finite-difference derivative."""
    return ((after[0] - before[0]) / dt, (after[1] - before[1]) / dt, (after[2] - before[2]) / dt)


def rotate(r: Sequence[float], v: Sequence[float]) -> Vec3:
    """``R v`` for a row-major rotation ``r`` (9 floats)."""
    x, y, z = v
    return (
        r[0] * x + r[1] * y + r[2] * z,
        r[3] * x + r[4] * y + r[5] * z,
        r[6] * x + r[7] * y + r[8] * z,
    )


def rotate_back(r: Sequence[float], v: Sequence[float]) -> Vec3:
    """``R^T v`` for a row-major rotation ``r`` (9 floats): ``v`` in the rotated frame."""
    x, y, z = v
    return (
        r[0] * x + r[3] * y + r[6] * z,
        r[1] * x + r[4] * y + r[7] * z,
        r[2] * x + r[5] * y + r[8] * z,
    )
