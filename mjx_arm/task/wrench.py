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
ee frame. Every engine feeds its own measurements through :func:`external_wrench` (or, for
MuJoCo's sensor block, :func:`sensor_wrench`).

Evaluation: the wrench is linear in ``(F_s, tau_s, acc, alpha)`` plus the gyroscopic term
``omega x (I omega)``, which is linear in the nine products ``omega_j omega_k``. Both are folded
into one constant matrix per tool (:attr:`ToolInertia.wrench_matrix`), so a reading costs one
outer product, one concatenation and one matrix product in ``numpy`` as in ``jax.numpy``.
MuJoCo reports the angular acceleration in the world frame; rotating it into the sensor frame is
quadratic in the sensor quaternion, so :func:`sensor_wrench` adds the products
``q_j q_k alpha_a`` to the features (:attr:`ToolInertia.sensor_wrench_matrix`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

from mjx_arm.urdf.model import RobotModel

# Layout of the MuJoCo sensor block read by :func:`sensor_wrench`, shape ``(..., 19)``.
SENSOR_BLOCK: tuple[tuple[str, int], ...] = (
    ("force", 3),  # force the arm exerts on the tool at the sensor (N), sensor frame
    ("torque", 3),  # torque about the sensor point (N m), sensor frame
    ("acc", 3),  # accelerometer at the tool's centre of mass, a_c - g (m/s^2), sensor frame
    ("gyro", 3),  # angular velocity (rad/s), sensor frame
    ("angacc", 3),  # angular acceleration (rad/s^2), world frame
    ("quat", 4),  # sensor frame orientation in the world (w, x, y, z), unit
)
SENSOR_BLOCK_SIZE = sum(size for _, size in SENSOR_BLOCK)

# Index pairs (j <= k) of the distinct products of 3 (omega) and 4 (quaternion) components.
_PAIRS3 = [(j, k) for j in range(3) for k in range(j, 3)]
_PAIRS4 = [(j, k) for j in range(4) for k in range(j, 4)]
# external_wrench: x = (force, torque, acc, alpha, omega) (15); products omega_j omega_k (6)
_EXT_OMEGA = 12
_EXT_I = np.array([_EXT_OMEGA + j for j, _ in _PAIRS3])
_EXT_J = np.array([_EXT_OMEGA + k for _, k in _PAIRS3])
_EXT_PAIRS = tuple(zip(_EXT_I.tolist(), _EXT_J.tolist(), strict=True))
# sensor_wrench: block (19); products p = (omega_j omega_k (6), q_j q_k (10)); then
# q_j q_k alpha_a (30, row 3 * pair + a)
_BLK_OMEGA, _BLK_ALPHA, _BLK_QUAT = 9, 12, 15
_BLK_I = np.array([_BLK_OMEGA + j for j, _ in _PAIRS3] + [_BLK_QUAT + j for j, _ in _PAIRS4])
_BLK_J = np.array([_BLK_OMEGA + k for _, k in _PAIRS3] + [_BLK_QUAT + k for _, k in _PAIRS4])
_BLK_K = np.repeat(np.arange(len(_PAIRS3), len(_PAIRS3) + len(_PAIRS4)), 3)
_BLK_L = np.tile(np.arange(_BLK_ALPHA, _BLK_ALPHA + 3), len(_PAIRS4))


def _skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix ``(3, 3)``: ``_skew(v) @ u == np.cross(v, u)``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _levi_civita() -> np.ndarray:
    """The permutation symbol ``eps[i, j, k]``, shape ``(3, 3, 3)``."""
    eps = np.zeros((3, 3, 3))
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        eps[i, j, k], eps[i, k, j] = 1.0, -1.0
    return eps


def _inverse_rotation_tensor() -> np.ndarray:
    """Quadratic part of rotating a vector by the inverse of a quaternion, ``(3, 4, 4, 3)``.

    For a unit quaternion ``q = (w, u)`` the inverse rotation of ``v`` is
    ``v - 2 w (u x v) + 2 u x (u x v)``; the entry ``[b, j, k, a]`` is the coefficient of
    ``q_j q_k v_a`` in component ``b``, so the rotation is ``v + C : (q x q x v)``.
    """
    eps = _levi_civita()
    c = np.zeros((3, 4, 4, 3))
    for b in range(3):
        c[b, 0, 1:, :] -= 2.0 * eps[b]  # -2 w (u x v)_b
        for a in range(3):
            c[b, b + 1, a + 1, a] += 2.0  # 2 u_b (u . v)
            c[b, a + 1, a + 1, b] -= 2.0  # -2 |u|^2 v_b
    return c


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

    @functools.cached_property
    def wrench_matrix(self) -> np.ndarray:
        """The tare as one matrix, shape ``(21, 6)``: ``wrench = features @ wrench_matrix``.

        Feature rows (see :func:`external_wrench`): ``force_s, torque_s, acc, alpha, omega``
        (3 each), then the products ``omega_j omega_k`` for ``j <= k`` (6). With ``R = ee_rot``,
        ``e = ee_pos``, ``c = com``, Newton-Euler gives ``F_ee = R (m acc - F_s)`` and
        ``tau_ee = R (I alpha + omega x I omega - tau_s + e x F_s + m (c - e) x acc)``.
        """
        rot, m = np.asarray(self.ee_rot, float), float(self.mass)
        com, ee = np.asarray(self.com, float), np.asarray(self.ee_pos, float)
        inertia = np.asarray(self.inertia, float)
        zero = np.zeros((3, 3))
        force = np.hstack([-rot, zero, m * rot, zero, zero])
        torque = np.hstack([rot @ _skew(ee), -rot, m * rot @ _skew(com - ee), rot @ inertia, zero])
        # (omega x I omega)_i = sum_jk (eps_ijl I_lk) omega_j omega_k
        gyro = rot @ _fold_pairs(np.einsum("ijl,lk->ijk", _levi_civita(), inertia), _PAIRS3)
        out = np.vstack([np.hstack([force, np.zeros((3, 6))]), np.hstack([torque, gyro])])
        return _frozen(out.T)

    @functools.cached_property
    def sensor_wrench_matrix(self) -> np.ndarray:
        """:attr:`wrench_matrix` for MuJoCo's sensor block, shape ``(65, 6)``.

        Feature rows (see :func:`sensor_wrench`): the block (19: force, torque, acc, omega,
        world angular acceleration, quaternion), the products ``omega_j omega_k`` (6) and
        ``q_j q_k`` (10, no weight) for ``j <= k``, and ``q_j q_k alpha_a`` (30). The world
        angular acceleration is rotated into the sensor frame by the inverse of the sensor
        quaternion ``q``, which is ``alpha + C : (q q alpha)`` (:func:`_inverse_rotation_tensor`).
        """
        w = self.wrench_matrix
        f_tau_acc, alpha, gyro = w[:9], w[9:12], w[15:]
        rot = np.einsum("bjka,bi->jkai", _inverse_rotation_tensor(), alpha)  # (4, 4, 3, 6)
        rotated = _fold_pairs(rot.transpose(2, 3, 0, 1), _PAIRS4)  # (3, 6, 10)
        rotated = rotated.transpose(2, 0, 1).reshape(3 * len(_PAIRS4), 6)
        out = np.vstack(
            [f_tau_acc, np.zeros((3, 6)), alpha, np.zeros((4, 6)), gyro, np.zeros((10, 6)), rotated]
        )
        return _frozen(out)


def _fold_pairs(tensor: np.ndarray, pairs: list[tuple[int, int]]) -> np.ndarray:
    """Coefficients of ``x_j x_k`` over the distinct pairs: ``(..., n, n) -> (..., len(pairs))``."""
    return np.stack(
        [tensor[..., j, k] + (tensor[..., k, j] if j != k else 0.0) for j, k in pairs], axis=-1
    )


def _frozen(a: np.ndarray) -> np.ndarray:
    """A read-only, contiguous float64 copy of ``a``."""
    out = np.ascontiguousarray(a, dtype=np.float64)
    out.setflags(write=False)
    return out


def tool_inertia(
    model: RobotModel, root: str, ee_link: str, ee_offset=(0.0, 0.0, 0.0)
) -> ToolInertia:
    """Mass properties of link ``root`` and everything below it (the tool the F/T reading
    weighs), from the URDF, in ``root``'s frame (the sensor frame); the ee point is
    ``ee_offset`` (m) in ``ee_link``'s frame."""
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
    point = ee[:3, 3] + ee[:3, :3] @ np.asarray(ee_offset, dtype=float)
    return ToolInertia(mass, com, inertia, point, ee[:3, :3].T.copy())


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

    All inputs share one leading shape ``(...)``.

    Returns:
        The wrench, shape ``(..., 6)``, not yet clipped.
    """
    x = xp.concatenate([force_s, torque_s, acc, alpha, omega], axis=-1)
    products = x.take(_EXT_I, axis=-1) * x.take(_EXT_J, axis=-1)
    return _times(xp, xp.concatenate([x, products], axis=-1), tool.wrench_matrix)


def external_wrench_features(force_s, torque_s, acc, omega, alpha) -> list[float]:
    """The features :func:`external_wrench` multiplies with :attr:`ToolInertia.wrench_matrix`,
    for one env, in Python floats: ``force_s, torque_s, acc, alpha, omega`` (3 floats each,
    the arguments of :func:`external_wrench`) and the products ``omega_j omega_k``, 21 floats.
    ``np.array(features).dot(tool.wrench_matrix)`` is :func:`external_wrench`'s value, bit for
    bit (the same products), in two numpy calls against its seven."""
    x = [*force_s, *torque_s, *acc, *alpha, *omega]
    return x + [x[i] * x[j] for i, j in _EXT_PAIRS]


def sensor_wrench(xp: Any, block, tool: ToolInertia):
    """:func:`external_wrench` from MuJoCo's wrist sensor block.

    Args:
        xp: ``numpy`` or ``jax.numpy``.
        block: the sensors in :data:`SENSOR_BLOCK` order, shape ``(..., 19)``: force, torque,
            accelerometer, gyro (sensor frame), angular acceleration (world frame), sensor
            quaternion (w, x, y, z).
        tool: the tool's mass properties.

    Returns:
        The wrench, shape ``(..., 6)``, not yet clipped.
    """
    # ``.take`` (one gather) and ``.dot`` (a matrix product for a 2-D right operand, batched
    # over the leading axes) are the cheapest numpy calls for this and plain XLA ops in JAX
    pairs = block.take(_BLK_I, axis=-1) * block.take(_BLK_J, axis=-1)
    triples = pairs.take(_BLK_K, axis=-1) * block.take(_BLK_L, axis=-1)
    features = xp.concatenate([block, pairs, triples], axis=-1)
    return _times(xp, features, tool.sensor_wrench_matrix)


def _times(xp: Any, features, matrix: np.ndarray):
    """``features @ matrix``, ``(..., k) @ (k, 6) -> (..., 6)``; under JAX at full float32
    precision.

    The tare takes the tool's weight and inertia (raw readings of up to 19 N in the parity's
    free motion) out of the reading, so what is left in free motion is the operands'
    rounding. JAX's default precision lets a GPU round float32 operands to TF32 (10 mantissa
    bits): the tared free-motion force of the parity read 2.4 to 4.5 mN on an H100 and an H200,
    MJX on Warp and on JAX alike, against 1e-6 N in float32 on a CPU; C MuJoCo's sensor
    readings of those runs with the operands rounded to TF32 give 1e-2 N.
    """
    if xp is np:
        return features.dot(matrix)
    return xp.dot(features, matrix, precision="highest")


def sensor_feature_factors(one: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The features of :func:`sensor_wrench` as the product of three gathers (one env).

    Over a vector ``v`` that holds the sensor block at ``v[:19]`` and ``1.0`` at ``v[one]``,
    ``v[a] * v[b] * v[c]`` (left to right) is the ``(65,)`` feature vector that
    :func:`sensor_wrench` multiplies with :attr:`ToolInertia.sensor_wrench_matrix`, bit for
    bit: an entry times 1 times 1, a pair times 1, and ``(q_j q_k) alpha_a`` in that order.
    Three gathers and two products in numpy, against eight calls in :func:`sensor_wrench`.

    Returns:
        The index arrays ``(a, b, c)``, ``(65,)`` each.
    """
    block, ones = np.arange(SENSOR_BLOCK_SIZE), np.full(SENSOR_BLOCK_SIZE, one)
    a = np.concatenate([block, _BLK_I, _BLK_I[_BLK_K]])
    b = np.concatenate([ones, _BLK_J, _BLK_J[_BLK_K]])
    c = np.concatenate([ones, np.full(len(_BLK_I), one), _BLK_L])
    return a, b, c
