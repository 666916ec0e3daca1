"""The observation contract: an ordered Dict of four keys and its flat 22-vector.

Functions take an array namespace ``xp`` (``numpy`` or ``jax.numpy``) so every engine, batched or
not, assembles observations with the same code.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces

# (key, size) in contract order. Brax and exported policies see the concatenation: state (22,).
OBS_LAYOUT: tuple[tuple[str, int], ...] = (
    ("ee_pose", 7),
    ("joint_angles", 6),
    ("target_rel", 3),
    ("contact_force", 6),
)
OBS_KEYS = tuple(key for key, _ in OBS_LAYOUT)
OBS_SIZE = sum(size for _, size in OBS_LAYOUT)
# Positions (m) are bounded well outside the arm's reach (about 1.1 m from the base).
POSITION_BOUND = 2.0


def obs_slices() -> dict[str, slice]:
    """Where each key sits in the flat vector."""
    out, start = {}, 0
    for key, size in OBS_LAYOUT:
        out[key] = slice(start, start + size)
        start += size
    return out


def _bounds(force_clip: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    pose_high = np.array([POSITION_BOUND] * 3 + [1.0] * 4, np.float32)
    pose_low = -pose_high.copy()
    pose_low[3] = 0.0  # quaternion w >= 0
    return {
        "ee_pose": (pose_low, pose_high),
        "joint_angles": (np.full(6, -math.pi, np.float32), np.full(6, math.pi, np.float32)),
        "target_rel": (
            np.full(3, -POSITION_BOUND, np.float32),
            np.full(3, POSITION_BOUND, np.float32),
        ),
        "contact_force": (np.full(6, -force_clip, np.float32), np.full(6, force_clip, np.float32)),
    }


def observation_space(force_clip: float = 100.0) -> spaces.Dict:
    """The Dict observation space, keys in contract order (built from a list: no sorting)."""
    bounds = _bounds(force_clip)
    return spaces.Dict(
        [
            (key, spaces.Box(*bounds[key], shape=(size,), dtype=np.float32))
            for key, size in OBS_LAYOUT
        ]
    )


def flat_observation_space(force_clip: float = 100.0) -> spaces.Box:
    """The flat ``state (22,)`` space: the Dict bounds concatenated in contract order."""
    bounds = _bounds(force_clip)
    low = np.concatenate([bounds[k][0] for k in OBS_KEYS])
    high = np.concatenate([bounds[k][1] for k in OBS_KEYS])
    return spaces.Box(low, high, dtype=np.float32)


def wrap_angle(xp: Any, q):
    """Wrap angles (rad) into [-pi, pi]; any shape."""
    return xp.arctan2(xp.sin(q), xp.cos(q))


def canonical_quat(xp: Any, quat):
    """Unit quaternion (w, x, y, z) with w >= 0, shape ``(..., 4)``."""
    quat = quat / xp.linalg.norm(quat, axis=-1, keepdims=True)
    sign = xp.where(quat[..., :1] < 0, -1.0, 1.0)
    return quat * sign


def assemble_obs(xp: Any, ee_pos, ee_quat, qpos, target_pos, wrench, force_clip: float) -> dict:
    """Build the observation dict from physics quantities (world frame = base frame).

    Args:
        xp: ``numpy`` or ``jax.numpy``.
        ee_pos: end-effector point (m), shape ``(..., 3)``.
        ee_quat: end-effector orientation (w, x, y, z), shape ``(..., 4)``.
        qpos: the six joint angles (rad), shape ``(..., 6)``.
        target_pos: target point (m), shape ``(..., 3)``.
        wrench: tared external wrench on the tool in the ee frame, shape ``(..., 6)``.
        force_clip: bound of each wrench component.

    Returns:
        Dict of float32 arrays in contract key order, each inside :func:`observation_space`.
    """
    b = POSITION_BOUND
    quat = xp.clip(canonical_quat(xp, ee_quat), -1.0, 1.0)
    pose = xp.concatenate([xp.clip(ee_pos, -b, b), quat], axis=-1)
    values = {
        "ee_pose": pose,
        "joint_angles": wrap_angle(xp, qpos),
        "target_rel": xp.clip(target_pos, -b, b),
        "contact_force": xp.clip(wrench, -force_clip, force_clip),
    }
    return {key: xp.asarray(values[key], dtype=xp.float32) for key in OBS_KEYS}


def flatten_obs(xp: Any, obs: dict):
    """Concatenate an observation dict into ``state``, shape ``(..., 22)``."""
    return xp.concatenate([obs[key] for key in OBS_KEYS], axis=-1)


def unflatten_obs(state) -> dict:
    """Split ``state (..., 22)`` back into the observation dict (views, no copy)."""
    return {key: state[..., s] for key, s in obs_slices().items()}
