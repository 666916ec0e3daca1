"""Reward terms, success and termination, written once against an array namespace ``xp``.

Every function works on one env (scalars and ``(6,)`` vectors) and on batches (a leading shape
``(...)``), in ``numpy``, under ``jax.numpy`` / ``jax.jit`` and, for one env on the CPU, in
:data:`~mjx_arm.envs.scalar.xp.SCALAR_XP` (Python floats, bools and lists of them). Norms are
``sqrt(vecdot)``, sums over the joints are matrix products with ones and 0/1 flags are
``flag * 1.0``: the values of ``linalg.norm``, ``sum`` and ``where(flag, 1.0, 0.0)``, plain XLA
ops under ``jit``, and a few operations of Python floats for one env.
"""

from __future__ import annotations

import functools
import operator
from typing import Any, NamedTuple

import numpy as np

from mjx_arm.task.config import REWARD_TERMS, TaskConfig
from mjx_arm.task.registry import get_task


class JointBand(NamedTuple):
    """The joint-limit test in precomputed form: joint ``j`` is beyond when
    ``|q_j - mid_j| > reach_j``.

    Attributes:
        mid: centre of each joint range (rad), ``(6,)``.
        reach: ``soft_limit`` times the half range (rad), ``(6,)``.
    """

    mid: Any
    reach: Any


def joint_band(joint_limits, cfg: TaskConfig) -> JointBand:
    """The :class:`JointBand` of ``(lower, upper)`` joint limits (rad), each ``(6,)``."""
    lower, upper = joint_limits
    mid, half = (upper + lower) / 2, (upper - lower) / 2
    return JointBand(mid, cfg.reward.soft_limit * half)


@functools.cache
def _ones(n: int) -> np.ndarray:
    return np.ones(n)


_ONES6 = _ones(6)


def _sum_last(xp: Any, x):
    """Sum over the last axis, ``(..., n) -> (...)``, float (booleans count as 0/1): a matrix
    product with ones (numpy's dot; one ``dot_general`` under JAX); one env's sum (a numpy
    scalar) as a Python float."""
    n = len(x) if isinstance(x, list) else x.shape[-1]
    total = xp.matmul(x, _ONES6 if n == 6 else _ones(n))
    return float(total) if isinstance(total, np.generic) else total


def joint_terms(xp: Any, qpos, qvel, band: JointBand):
    """The ``joint_limit`` term (how many joints are beyond the soft band) and the
    ``joint_velocity`` term (the sum of the joint speeds), each ``(...)``.

    Args:
        xp: the array namespace (:data:`~mjx_arm.envs.scalar.xp.SCALAR_XP` also takes one
            env's joints as lists of floats, with the band's as lists).
        qpos, qvel: joint angles (rad) and velocities (rad/s), ``(..., n)``.
        band: the joint-limit band.
    """
    beyond = xp.greater(xp.abs(xp.subtract(qpos, band.mid)), band.reach)
    return _sum_last(xp, beyond), _sum_last(xp, xp.abs(qvel))


def target_distance(xp: Any, ee_pos, target_pos):
    """Distance d (m) from the ee point to the target point, shape ``(...)``."""
    diff = ee_pos - target_pos
    return xp.sqrt(xp.vecdot(diff, diff))


def contact_force_norm(xp: Any, contact_force):
    """Norm (N) of the force part of a clipped wrench ``(..., 6)`` (or ``(..., 3)``): ``(...)``.

    Args:
        xp: ``numpy`` or ``jax.numpy``.
        contact_force: the ``contact_force`` observation (the tared wrench clipped to
            +-``force_clip``), float64 or float32; only its first three entries count.
    """
    force = contact_force[..., :3]
    return xp.sqrt(xp.vecdot(force, force))


def force_in_band(xp: Any, force_norm, cfg: TaskConfig):
    """1.0 where the contact force norm (N) lies inside ``cfg.force_band``, else 0.0."""
    low, high = cfg.force_band
    return ((force_norm >= low) & (force_norm <= high)) * 1.0


def force_band_peak(xp: Any, force_norm, cfg: TaskConfig):
    """How near the middle of ``cfg.force_band`` the contact force norm (N) is, ``(...)``: 1 at
    the middle, falling linearly to 0 at either end of the band and outside it."""
    low, high = cfg.force_band
    middle, half = 0.5 * (low + high), 0.5 * (high - low)
    return xp.clip(1.0 - xp.abs(force_norm - middle) / half, 0.0, 1.0)


def force_excess(xp: Any, force_norm, cfg: TaskConfig):
    """The contact force above the band as a fraction of its top, else 0, shape ``(...)``."""
    high = cfg.force_band[1]
    return xp.maximum(force_norm - high, 0.0) / high


def is_success(xp: Any, distance, force_norm, cfg: TaskConfig, extra=None):
    """The success condition of one step (bool array), as the task defines it
    (:meth:`mjx_arm.task.spec.Task.holds`). The episode succeeds once it has held for
    ``success_hold_steps`` (see :func:`advance`)."""
    return get_task(cfg.task).holds(xp, distance, force_norm, cfg, extra)


class Progress(NamedTuple):
    """What the success rule remembers within an episode (per env).

    Attributes:
        hold: consecutive control steps the success condition has held, float ``(...)``.
        over: whether a force reading above the band has been seen, bool ``(...)``.
    """

    hold: Any
    over: Any


def start_progress(xp: Any, shape: tuple[int, ...] = ()) -> Progress:
    """The progress at the start of an episode."""
    return Progress(xp.zeros(shape), xp.zeros(shape, dtype=bool))


def advance(xp: Any, progress: Progress, distance, force_norm, cfg: TaskConfig, extra=None):
    """One step of the success rule.

    Args:
        xp: ``numpy`` or ``jax.numpy``.
        progress: the progress before this step.
        distance: d (m), ``(...)``; force_norm: contact force norm (N), ``(...)``.
        cfg: the task configuration.
        extra: the task's measures (:meth:`mjx_arm.task.spec.Task.measures`), or None.

    Returns:
        (progress after the step, success flag, over-band flag of this step), bool ``(...)``.
    """
    task = get_task(cfg.task)
    holds = task.holds(xp, distance, force_norm, cfg, extra)
    over_now = task.over_band(xp, force_norm, cfg)
    hold = xp.where(holds, progress.hold + 1.0, 0.0)
    over = progress.over | over_now
    success = hold >= cfg.success_hold_steps
    if cfg.fail_on_overforce:
        success = xp.logical_and(success, xp.logical_not(over))
    return Progress(hold, over), success, over_now


def speed_limits(v_max, cfg: TaskConfig):
    """Joint speeds (rad/s, ``(6,)``) above which the physics counts as diverged."""
    return cfg.divergence_speed_factor * v_max


def runaway(xp: Any, qvel, limits):
    """Whether a joint turns faster than its divergence limit, bool ``(...)``.

    Args:
        xp: the array namespace.
        qvel: joint velocities (rad/s), ``(..., 6)``; NaN compares False (test finiteness apart).
        limits: :func:`speed_limits`, ``(6,)``.
    """
    return xp.any(xp.abs(qvel) > limits, axis=-1)


def strike_limit(cfg: TaskConfig) -> float:
    """Contact force norm (N) above which a Touch episode ends (a protective stop)."""
    return cfg.strike_force or cfg.force_band[1]


def ends_episode(success, force_norm, nonfinite, cfg: TaskConfig, xp: Any = np):
    """Termination (bool ``(...)``): a non-finite state, success or a strike, as configured.

    A strike is what the task calls one (:meth:`mjx_arm.task.spec.Task.strikes`; Touch: a
    contact force above :func:`strike_limit` while ``terminate_on_overforce``).
    """
    done = nonfinite | (success & cfg.terminate_on_success)
    return done | get_task(cfg.task).strikes(xp, force_norm, cfg)


class Motion(NamedTuple):
    """What the motion terms compare with the previous control step (per env).

    Attributes:
        prev_distance: d at the previous step (m), ``(...)``.
        action_change: sum over the six entries of (a_t - a_{t-1})^2, ``(...)``.
        hold: consecutive steps the success condition has held, this step included
            (``Progress.hold`` after :func:`advance`), ``(...)``.
    """

    prev_distance: Any
    action_change: Any
    hold: Any = 0.0


def streak(xp: Any, hold, cfg: TaskConfig):
    """How far a press has held on past its first step: 0 on a one-step tap, rising linearly
    to 1 once the success condition has held ``success_hold_steps`` steps running, shape
    ``(...)``. Always 0 when one step is enough to succeed."""
    steps = cfg.success_hold_steps
    if steps < 2:
        return 0.0 * hold
    return (xp.clip(hold, 1.0, steps) - 1.0) / (steps - 1.0)


def action_change(xp: Any, action, prev_action):
    """sum (a_t - a_{t-1})^2 over the last axis: ``(..., 6) -> (...)``."""
    delta = action - prev_action
    return xp.vecdot(delta, delta)


def reward_terms(
    xp: Any,
    distance,
    force_norm,
    qpos,
    qvel,
    joint_limits,
    success,
    nonfinite,
    cfg: TaskConfig,
    motion: Motion | None = None,
    extra: dict | None = None,
) -> dict:
    """Raw (unweighted) reward terms by name: :func:`band_reward_terms` with the joint limits
    given as ``(lower, upper)`` (rad, each ``(6,)``)."""
    band = joint_band(joint_limits, cfg)
    return band_reward_terms(
        xp, distance, force_norm, qpos, qvel, band, success, nonfinite, cfg, motion, extra
    )


def band_reward_terms(
    xp: Any,
    distance,
    force_norm,
    qpos,
    qvel,
    band: JointBand,
    success,
    nonfinite,
    cfg: TaskConfig,
    motion: Motion | None = None,
    extra: dict | None = None,
) -> dict:
    """:func:`reward_terms` with the joint limits as a precomputed :class:`JointBand`.

    Args:
        xp: ``numpy`` or ``jax.numpy``.
        distance: d (m), shape ``(...)``.
        force_norm: tared contact force norm (N), shape ``(...)``.
        qpos: joint angles (rad), shape ``(..., 6)`` (lists with ``SCALAR_XP``).
        qvel: joint velocities (rad/s), shape ``(..., 6)`` (lists with ``SCALAR_XP``).
        band: :func:`joint_band` of the joint limits.
        success: success flag (bool), shape ``(...)``.
        nonfinite: flag (bool) of a non-finite physics state, shape ``(...)``.
        cfg: the task configuration.
        motion: the previous step's distance, the action change and the hold count (None: their
            terms are 0).
        extra: the task's measures (:meth:`mjx_arm.task.spec.Task.measures`; None: the
            task's own terms are 0).

    Returns:
        Dict term name -> float array, shape ``(...)``; keys are ``REWARD_TERMS``, then the
        task's own terms (:attr:`mjx_arm.task.spec.Task.reward_terms`).
    """
    task = get_task(cfg.task)
    terms = _state_terms(xp, task, distance, force_norm, cfg)
    terms["joint_limit"], terms["joint_velocity"] = joint_terms(xp, qpos, qvel, band)
    terms["success"], terms["nonfinite"] = success * 1.0, nonfinite * 1.0
    terms.update(zip(MOTION_TERMS, _motion_terms(xp, distance, cfg, motion), strict=True))
    own = _own_terms(xp, task, distance, extra)
    return {**{name: terms[name] for name in REWARD_TERMS}, **own}


def _own_terms(xp: Any, task: Any, distance, extra: dict | None) -> dict:
    """``task``'s own terms from its measures ``extra`` (None: each 0), shaped as ``distance``
    ``(...)``, in the order of ``task.reward_terms``."""
    zero = 0.0 * distance
    own = task.task_terms(xp, extra, zero) if extra else dict.fromkeys(task.reward_terms, zero)
    return {name: own[name] for name in task.reward_terms}


def _state_terms(xp: Any, task: Any, distance, force_norm, cfg: TaskConfig) -> dict:
    """The terms of the distance d (m) and the tared force norm (N), each ``(...)``:
    ``distance``, ``proximity``, ``press`` (near the target, :func:`force_band_peak`), and
    ``task``'s ``contact``, ``force_excess``, ``overforce`` and ``strike``."""
    near = distance < cfg.success_distance
    contact, excess = task.contact_terms(xp, near, force_norm, cfg)
    return {
        "strike": task.strikes(xp, force_norm, cfg) + 0.0 * distance,
        "distance": 1.0 - xp.exp(-distance / cfg.reward.distance_length),
        "contact": contact,
        "force_excess": excess,
        "overforce": (excess > 0) * 1.0,
        "proximity": xp.exp(-distance / cfg.reward.proximity_length),
        "press": force_band_peak(xp, force_norm, cfg) * near,
    }


# The terms of the arm's motion between two steps, as :func:`_motion_terms` gives them.
MOTION_TERMS = ("approach_speed", "action_rate", "streak")


def _motion_terms(xp: Any, distance, cfg: TaskConfig, motion: Motion | None):
    """The ``approach_speed``, ``action_rate`` and ``streak`` terms, each ``(...)`` (0 without
    ``motion``)."""
    zero = 0.0 * distance
    if motion is None:
        return zero, zero, zero
    # squared: the cost of an approach grows with its speed (a sum of plain speeds over the
    # approach would be the distance closed over ctrl_dt, whatever the speed)
    closing = xp.maximum(motion.prev_distance - distance, 0.0) / cfg.ctrl_dt
    closing = closing * closing * (distance < cfg.reward.approach_radius)
    return closing, motion.action_change + zero, streak(xp, motion.hold + zero, cfg)


@functools.cache
def _weights(kind: type) -> tuple[tuple[str, ...], operator.attrgetter]:
    """The term names of a reward type in summing order, and the getter of their weights."""
    names = kind.term_names()
    return names, operator.attrgetter(*names)


def total_reward(terms: dict, cfg: TaskConfig):
    """Weighted sum of the reward terms (every name of ``cfg.reward.term_names()``: the shared
    ``REWARD_TERMS``, then the task's own), shape ``(...)``."""
    names, weights = _weights(type(cfg.reward))
    return sum(map(operator.mul, weights(cfg.reward), map(terms.__getitem__, names)))
