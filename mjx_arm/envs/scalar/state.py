"""One env's flat state in Python floats: the observation, distance and force of a reading.

The values of :func:`mjx_arm.task.observation.raw_state` and
:func:`~mjx_arm.task.observation.clip_state`, and of the reward's
:func:`~mjx_arm.task.reward.target_distance` and
:func:`~mjx_arm.task.reward.contact_force_norm`, for one env at a time (the CPU envs).
On vectors of 3 to 30 entries numpy's cost per call (a few microseconds once a physics step
has filled the caches with its own data) was most of an env step; a float operation costs tens
of nanoseconds. The operations are the same IEEE ones: a quaternion divided by its norm
carrying the sign of ``w``, sums of squares added left to right, clipping by comparison. numpy
adds a short vector's squares in the order of the CPU's vector unit (left to right on AVX2;
on AVX-512 the norm can end 2 ulp away), so the quaternion agrees with numpy's within a few
ulp and everything else exactly (the tests say how closely). One array is built at the
end: the observation.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mjx_arm.task import observation as obs_lib


class ScalarState:
    """The flat state of an env's task and arm, one reading at a time.

    Args:
        force_clip: bound of each wrench component.
        coding: the joint encoding (:class:`~mjx_arm.task.observation.JointCoding`).
        extra: the task's extra observation keys, ``(key, size)`` pairs.
    """

    def __init__(self, force_clip: float, coding: obs_lib.JointCoding, extra=()) -> None:
        n = len(coding.centre)
        low, high = obs_lib.state_bounds(force_clip, n, tuple(extra), coding)
        self.low, self.high = low.tolist(), high.tolist()
        self.coding, self.centre, self.wraps = coding, list(coding.centre), any(coding.wrap)
        self.size = obs_lib.obs_size(n, tuple(extra))
        self.force = obs_lib.force_slice(n)
        self.keys = tuple(obs_lib.obs_slices(n, tuple(extra)).items())
        self.target = slice(7 + n, 10 + n)  # the target point in the flat state

    def measure(self, ee_pos, ee_quat, qpos, target_pos, wrench, extra=None) -> tuple:
        """The raw and clipped flat states of one reading (:meth:`raw`, :meth:`clip`), the
        distance (m) from the ee point to the target and the contact force norm (N) of the
        clipped state: ``(raw, state, d, force)``."""
        raw = self.raw(ee_pos, ee_quat, qpos, target_pos, wrench, extra)
        state = [
            low if v < low else high if v > high else v
            for v, low, high in zip(raw, self.low, self.high, strict=True)
        ]
        (ax, ay, az), (bx, by, bz) = raw[:3], raw[self.target]
        dx, dy, dz = ax - bx, ay - by, az - bz
        fx, fy, fz = state[self.force]
        return (
            raw,
            state,
            math.sqrt(dx * dx + dy * dy + dz * dz),
            math.sqrt(fx * fx + fy * fy + fz * fz),
        )

    def raw(self, ee_pos, ee_quat, qpos, target_pos, wrench, extra=None) -> list[float]:
        """:func:`~mjx_arm.task.observation.raw_state` of one reading (arrays ``(3,)``,
        ``(4,)``, ``(n,)``, ``(3,)``, ``(6,)`` and the extra keys ``(k,)`` or None), as a
        list of ``16 + n + k`` floats."""
        w, x, y, z = ee_quat.tolist()
        # canonical_quat: the norm carries the sign of w (-0.0 counts as positive); a zero
        # quaternion gives NaN, as numpy's 0 / 0 does
        norm = math.copysign(math.sqrt(w * w + x * x + y * y + z * z), w + 0.0) or math.nan
        state = ee_pos.tolist()
        state += (w / norm, x / norm, y / norm, z / norm)
        if self.wraps:  # sines and cosines: numpy's, as the other engines take them
            state += obs_lib.encode_joints(np, qpos, self.coding).tolist()
        else:
            state += [q - c for q, c in zip(qpos.tolist(), self.centre, strict=True)]
        state += target_pos.tolist()
        state += wrench.tolist()
        if extra is not None:
            state += extra.tolist()
        return state

    def clip(self, raw: list[float]) -> list[float]:
        """:func:`~mjx_arm.task.observation.clip_state` of a raw state (NaN stays NaN)."""
        return [
            low if v < low else high if v > high else v
            for v, low, high in zip(raw, self.low, self.high, strict=True)
        ]

    def force_norm(self, state: list[float]) -> float:
        """The contact force norm (N) of a clipped state."""
        fx, fy, fz = state[self.force]
        return math.sqrt(fx * fx + fy * fy + fz * fz)

    def observation(self, state: list[float]) -> dict[str, np.ndarray]:
        """The observation dict of a clipped state: float32 views of one new array."""
        flat = np.fromiter(state, np.float32, self.size)
        return {key: flat[part] for key, part in self.keys}


def finite(values: list[float]) -> bool:
    """Whether every value is finite (a sum is finite exactly when every term is, barring
    overflow, which the exact test then rules out)."""
    return math.isfinite(sum(values)) or all(map(math.isfinite, values))


def distance(a: Any, b: Any) -> float:
    """The distance (m) between two points ``(3,)``."""
    (ax, ay, az), (bx, by, bz) = a.tolist(), b.tolist()
    dx, dy, dz = ax - bx, ay - by, az - bz
    return math.sqrt(dx * dx + dy * dy + dz * dz)
