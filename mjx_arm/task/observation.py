"""The observation contract: an ordered Dict of four keys and its flat vector (22 entries for
a 6-joint arm: ``16 + n``), then the keys a task adds (``extra``: ``(key, size)`` pairs, e.g.
Lift's gripper, object and pad keys, :attr:`mjx_arm.task.spec.Task.extra_obs`).

Functions take an array namespace ``xp`` (``numpy`` or ``jax.numpy``) so every engine, batched or
not, assembles observations with the same code.
"""

from __future__ import annotations

import functools
import math
from typing import Any, NamedTuple

import numpy as np
from gymnasium import spaces

SHIPPED_JOINTS = 6
# Sizes of the keys that do not depend on the arm; ``joint_angles`` has one entry per joint.
FIXED_SIZES = {"ee_pose": 7, "target_rel": 3, "contact_force": 6}
OBS_KEYS = ("ee_pose", "joint_angles", "target_rel", "contact_force")
# Positions (m) are bounded well outside the reach of the arms the tasks drive (up to 1.3 m).
POSITION_BOUND = 2.0


Extra = tuple[tuple[str, int], ...]


class JointCoding(NamedTuple):
    """How ``joint_angles`` encodes the joint angles: ``angle = q - centre``, wrapped into
    [-pi, pi] where ``wrap``; each entry bounded by ``bound``. Tuples of n (hashable).

    ``centred`` (the default encoding): a limited joint relative to the middle of its range,
    never wrapped, so the value moves without a jump over the whole range (also over ranges
    beyond a full turn); a full-turn joint without limits relative to its home angle, wrapped
    (the jump sits half a turn from home). ``wrapped`` (files from before the encoding was
    recorded): every angle wrapped into [-pi, pi], centre 0.
    """

    centre: tuple[float, ...]
    wrap: tuple[bool, ...]
    bound: tuple[float, ...]


JOINT_ENCODINGS = ("centred", "wrapped")


def joint_coding(encoding: str, lower, upper, full_turn, home) -> JointCoding:
    """The :class:`JointCoding` of ``encoding`` for joints of limits ``lower``/``upper``
    (rad), ``full_turn`` (bool: no limits) and ``home`` angles, ``(n,)`` each.

    Raises:
        ValueError: an unknown encoding.
    """
    if encoding == "wrapped":
        return wrapped_coding(len(lower))
    if encoding != "centred":
        raise ValueError(f"joint_encoding must be one of {JOINT_ENCODINGS}, got {encoding!r}")
    centre, wrap, bound = [], [], []
    for lo, hi, turn, q in zip(lower, upper, full_turn, home, strict=True):
        centre.append(float(q) if turn else 0.5 * (float(lo) + float(hi)))
        wrap.append(bool(turn))
        bound.append(math.pi if turn else 0.5 * (float(hi) - float(lo)))
    return JointCoding(tuple(centre), tuple(wrap), tuple(bound))


def wrapped_coding(n_joints: int) -> JointCoding:
    """The ``wrapped`` encoding of ``n_joints`` joints (every angle in [-pi, pi])."""
    return JointCoding((0.0,) * n_joints, (True,) * n_joints, (math.pi,) * n_joints)


def encode_joints(xp: Any, qpos, coding: JointCoding | None):
    """``joint_angles`` of joint angles ``qpos (..., n)`` (rad); None codes as ``wrapped``."""
    if coding is None:
        return wrap_angle(xp, qpos)
    shifted = qpos - xp.asarray(coding.centre)
    if not any(coding.wrap):
        return shifted
    if all(coding.wrap):
        return wrap_angle(xp, shifted)
    return xp.where(xp.asarray(coding.wrap), wrap_angle(xp, shifted), shifted)


def decode_joints(angles, coding: JointCoding | None) -> np.ndarray:
    """Joint angles (rad) of ``joint_angles (..., n)`` (a wrapped entry: the angle within
    half a turn of its centre)."""
    return np.asarray(angles, dtype=np.float64) + (0.0 if coding is None else coding.centre)


def obs_layout(n_joints: int = SHIPPED_JOINTS, extra: Extra = ()) -> tuple[tuple[str, int], ...]:
    """(key, size) in contract order for an arm of ``n_joints``, then the task's ``extra``
    keys; Brax and exported policies see the concatenation, ``state (16 + n_joints + k,)``."""
    base = tuple((key, FIXED_SIZES.get(key, n_joints)) for key in OBS_KEYS)
    return base + tuple(extra)


def obs_size(n_joints: int = SHIPPED_JOINTS, extra: Extra = ()) -> int:
    """Length of the flat ``state``: 22 for a 6-joint arm (plus the extra keys' sizes)."""
    return sum(size for _, size in obs_layout(n_joints, extra))


# The shipped arm's layout and size.
OBS_LAYOUT = obs_layout()
OBS_SIZE = obs_size()


def force_slice(n_joints: int = SHIPPED_JOINTS) -> slice:
    """The force part (fx, fy, fz) of ``contact_force`` in the flat state (the extra keys come
    after it)."""
    start = obs_size(n_joints) - 6
    return slice(start, start + 3)


def n_joints_of(state_size: int, extra: Extra = ()) -> int:
    """The joint count of a flat ``state`` of ``state_size`` entries (with ``extra`` keys)."""
    n = state_size - obs_size(0, extra)
    if n < 1:
        raise ValueError(f"a flat state of {state_size} entries holds no joint angles")
    return n


@functools.lru_cache(maxsize=16)
def _slices(n_joints: int, extra: Extra = ()) -> tuple[tuple[str, slice], ...]:
    """(key, slice of the flat vector) in contract order."""
    out, start = [], 0
    for key, size in obs_layout(n_joints, extra):
        out.append((key, slice(start, start + size)))
        start += size
    return tuple(out)


def obs_slices(n_joints: int = SHIPPED_JOINTS, extra: Extra = ()) -> dict[str, slice]:
    """Where each key sits in the flat vector."""
    return dict(_slices(n_joints, tuple(extra)))


def _pose_bounds(dtype: Any) -> tuple[np.ndarray, np.ndarray]:
    """A position (+-:data:`POSITION_BOUND`) and a quaternion with ``w >= 0``, ``(7,)`` each."""
    high = np.array([POSITION_BOUND] * 3 + [1.0] * 4, dtype)
    low = -high.copy()
    low[3] = 0.0  # quaternion w >= 0
    return low, high


# Bounds of the extra keys tasks may add: a function of (force_clip, dtype).
EXTRA_BOUNDS = {
    "gripper": lambda clip, dtype: (np.zeros(1, dtype), np.ones(1, dtype)),
    "object_rel": lambda clip, dtype: _pose_bounds(dtype),
    "pad_force": lambda clip, dtype: (np.zeros(2, dtype), np.full(2, clip, dtype)),
}


def _bounds(
    force_clip: float,
    n_joints: int,
    dtype: Any = np.float32,
    extra: Extra = (),
    coding: JointCoding | None = None,
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """(low, high) of each key, arrays of ``dtype``."""
    joint = np.asarray((coding or wrapped_coding(n_joints)).bound, dtype)
    if joint.shape != (n_joints,):
        raise ValueError(f"the joint coding has {joint.shape[0]} joints, not {n_joints}")
    bounds = {
        "ee_pose": _pose_bounds(dtype),
        "joint_angles": (-joint, joint.copy()),
        "target_rel": (np.full(3, -POSITION_BOUND, dtype), np.full(3, POSITION_BOUND, dtype)),
        "contact_force": (np.full(6, -force_clip, dtype), np.full(6, force_clip, dtype)),
    }
    for key, size in extra:
        if key not in EXTRA_BOUNDS:
            raise ValueError(f"no bounds for observation key {key!r}; add it to EXTRA_BOUNDS")
        low, high = EXTRA_BOUNDS[key](force_clip, dtype)
        if low.shape != (size,):
            raise ValueError(f"observation key {key!r} has {low.shape[0]} entries, not {size}")
        bounds[key] = (low, high)
    return bounds


def _concat(bounds: dict, layout) -> tuple[np.ndarray, np.ndarray]:
    low = np.concatenate([bounds[k][0] for k, _ in layout])
    high = np.concatenate([bounds[k][1] for k, _ in layout])
    return low, high


@functools.lru_cache(maxsize=16)
def state_bounds(
    force_clip: float,
    n_joints: int = SHIPPED_JOINTS,
    extra: Extra = (),
    coding: JointCoding | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of the flat ``state`` (float64, read-only), low and high, each ``(16 + n,)``.

    The float64 twins of :func:`flat_observation_space`'s bounds: clipping with them leaves
    wrapped joint angles (already inside [-pi, pi]) and canonical quaternions unchanged.
    ``coding``: the joint encoding (None: ``wrapped``).
    """
    bounds = _bounds(force_clip, n_joints, np.float64, extra, coding)
    low, high = _concat(bounds, obs_layout(n_joints, extra))
    low.setflags(write=False)
    high.setflags(write=False)
    return low, high


def observation_space(
    force_clip: float = 100.0,
    n_joints: int = SHIPPED_JOINTS,
    extra: Extra = (),
    coding: JointCoding | None = None,
) -> spaces.Dict:
    """The Dict observation space, keys in contract order (built from a list: no sorting);
    ``coding``: the joint encoding (None: ``wrapped``)."""
    bounds = _bounds(force_clip, n_joints, extra=extra, coding=coding)
    return spaces.Dict(
        [
            (key, spaces.Box(*bounds[key], shape=(size,), dtype=np.float32))
            for key, size in obs_layout(n_joints, extra)
        ]
    )


def flat_observation_space(
    force_clip: float = 100.0,
    n_joints: int = SHIPPED_JOINTS,
    extra: Extra = (),
    coding: JointCoding | None = None,
) -> spaces.Box:
    """The flat ``state (16 + n + k,)`` space: the Dict bounds concatenated in contract order."""
    bounds = _bounds(force_clip, n_joints, extra=extra, coding=coding)
    low, high = _concat(bounds, obs_layout(n_joints, extra))
    return spaces.Box(low, high, dtype=np.float32)


def wrap_angle(xp: Any, q):
    """Wrap angles (rad) into [-pi, pi]; any shape."""
    return xp.arctan2(xp.sin(q), xp.cos(q))


def canonical_quat(xp: Any, quat):
    """Unit quaternion (w, x, y, z) with w >= 0, shape ``(..., 4)``.

    Divides by the norm carrying the sign of ``w`` (``-0.0`` counts as positive): the values
    of ``quat / |quat|`` times ``-1 if w < 0 else 1``, in five cheap array operations.
    """
    norm = xp.sqrt(xp.vecdot(quat, quat))[..., None]
    return quat / xp.copysign(norm, quat[..., :1] + 0.0)


def raw_state(xp: Any, ee_pos, ee_quat, qpos, target_pos, wrench, extra_obs=None, coding=None):
    """The flat ``state`` before clipping, shape ``(..., 16 + n)``, the dtype of the inputs.

    Quaternion made canonical, joint angles encoded (:func:`encode_joints`), nothing clipped: a
    non-finite input shows as a non-finite entry here (clipping would turn an infinity into a
    bound).

    Args:
        xp: ``numpy`` or ``jax.numpy``.
        ee_pos: end-effector point (m), shape ``(..., 3)``.
        ee_quat: end-effector orientation (w, x, y, z), shape ``(..., 4)``.
        qpos: the n joint angles (rad), shape ``(..., n)``.
        target_pos: target point (m), shape ``(..., 3)``.
        wrench: tared external wrench on the tool in the ee frame, shape ``(..., 6)``.
        extra_obs: the task's extra keys, concatenated, ``(..., k)`` (None: none).
        coding: the joint encoding (:class:`JointCoding`; None: ``wrapped``).
    """
    joints = encode_joints(xp, qpos, coding)
    parts = [ee_pos, canonical_quat(xp, ee_quat), joints, target_pos, wrench]
    if extra_obs is not None:
        parts.append(extra_obs)
    return xp.concatenate(parts, axis=-1)


def clip_state(xp: Any, state, bounds: tuple[Any, Any]):
    """Clip a flat ``state (..., 16 + n)`` into ``bounds`` (:func:`state_bounds`); same dtype."""
    low, high = bounds
    return xp.minimum(xp.maximum(state, low), high)


def flat_obs(
    xp: Any, ee_pos, ee_quat, qpos, target_pos, wrench, force_clip: float, extra=None, coding=None
):
    """The observation as the flat float32 ``state (..., 16 + n + k)`` (see
    :func:`assemble_obs`); ``extra``: ``(layout, values (..., k))`` of the task's extra keys;
    ``coding``: the joint encoding (None: ``wrapped``)."""
    layout, values = extra if extra is not None else ((), None)
    raw = raw_state(xp, ee_pos, ee_quat, qpos, target_pos, wrench, values, coding)
    bounds = state_bounds(force_clip, qpos.shape[-1], tuple(layout), coding)
    return xp.asarray(clip_state(xp, raw, bounds), dtype=xp.float32)


def assemble_obs(
    xp: Any, ee_pos, ee_quat, qpos, target_pos, wrench, force_clip: float, coding=None
) -> dict:
    """Build the observation dict from physics quantities (world frame = base frame).

    Args:
        xp: ``numpy`` or ``jax.numpy``.
        ee_pos: end-effector point (m), shape ``(..., 3)``.
        ee_quat: end-effector orientation (w, x, y, z), shape ``(..., 4)``.
        qpos: the n joint angles (rad), shape ``(..., n)``.
        target_pos: target point (m), shape ``(..., 3)``.
        wrench: tared external wrench on the tool in the ee frame, shape ``(..., 6)``.
        force_clip: bound of each wrench component.
        coding: the joint encoding (:class:`JointCoding`; None: ``wrapped``).

    Returns:
        Dict of float32 arrays in contract key order, each inside :func:`observation_space`:
        views into one flat ``state (..., 16 + n)`` (:func:`flat_obs`).
    """
    state = flat_obs(xp, ee_pos, ee_quat, qpos, target_pos, wrench, force_clip, coding=coding)
    return unflatten_obs(state)


def flatten_obs(xp: Any, obs: dict):
    """Concatenate an observation dict into ``state``: the contract's four keys, then any
    extra keys in the dict's order."""
    extra = [value for key, value in obs.items() if key not in OBS_KEYS]
    return xp.concatenate([obs[key] for key in OBS_KEYS] + extra, axis=-1)


def unflatten_obs(state, extra: Extra = ()) -> dict:
    """Split ``state (..., 16 + n + k)`` back into the observation dict (views, no copy)."""
    extra = tuple(extra)
    return {key: state[..., s] for key, s in _slices(n_joints_of(state.shape[-1], extra), extra)}
