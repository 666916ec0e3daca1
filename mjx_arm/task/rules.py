"""The step rules, composed once for every engine.

After each control step an engine measures the distance ``d`` and the tared contact force, and
decides whether its physics diverged; :func:`score_step` turns that into the episode's progress,
success, the reward terms and their total, and termination. The CPU envs (one env, on Python
floats, :mod:`mjx_arm.envs.scalar`) and the batched MJX env (``jax.numpy``, traced under
``jit``/``vmap``) all run it, so the rules cannot drift apart between engines.

On a diverged step the reading is not physics: every reward term except ``nonfinite`` is zero,
success is ruled out and the episode ends.
"""

from __future__ import annotations

from typing import Any, NamedTuple

from mjx_arm.task import reward as reward_lib
from mjx_arm.task.config import TaskConfig


class StepScore(NamedTuple):
    """What one control step scored (per env; shapes ``(...)``).

    Attributes:
        progress: the success rule's progress after the step.
        success: the episode succeeded on this step (bool).
        over: the contact force read above the band on this step (bool).
        terms: raw reward terms by name (``REWARD_TERMS``), zero on a diverged step except
            ``nonfinite``.
        reward: the weighted sum of the terms.
        done: the episode terminates (success, a strike or divergence, as configured).
    """

    progress: reward_lib.Progress
    success: Any
    over: Any
    terms: dict[str, Any]
    reward: Any
    done: Any


def score_step(
    xp: Any,
    cfg: TaskConfig,
    progress: reward_lib.Progress,
    prev_distance,
    action_change,
    distance,
    force_norm,
    qpos,
    qvel,
    band: reward_lib.JointBand,
    diverged,
    extra: dict | None = None,
) -> StepScore:
    """Score one control step.

    Args:
        xp: ``numpy`` or ``jax.numpy``.
        cfg: the task configuration.
        progress: the success rule's progress before the step.
        prev_distance: d at the previous step (m), ``(...)``.
        action_change: sum of the squared action change since the previous step, ``(...)``.
        distance: d after the step (m), ``(...)``.
        force_norm: tared contact force norm after the step (N), ``(...)``.
        qpos, qvel: joint angles (rad) and velocities (rad/s), ``(..., n)`` (lists of n floats
            with ``SCALAR_XP``, the band's too).
        band: the joint-limit band (:func:`mjx_arm.task.reward.joint_band`).
        diverged: the physics diverged on this step (bool, ``(...)``).
        extra: the task's measures (:meth:`mjx_arm.task.spec.Task.measures`), or None.

    Returns:
        The :class:`StepScore`.
    """
    sane = xp.logical_not(diverged)
    progress, success, over = reward_lib.advance(xp, progress, distance, force_norm, cfg, extra)
    success = xp.logical_and(success, sane)
    motion = reward_lib.Motion(prev_distance, action_change, progress.hold)
    terms = reward_lib.band_reward_terms(
        xp, distance, force_norm, qpos, qvel, band, success, diverged, cfg, motion, extra
    )
    terms = _forfeit_press_pay(terms, progress.over, cfg)
    terms = _masked(xp, sane, terms)
    done = reward_lib.ends_episode(success, xp.where(sane, force_norm, 0.0), diverged, cfg, xp)
    return StepScore(progress, success, over, terms, reward_lib.total_reward(terms, cfg), done)


# The terms that pay a press, which a reading above the band can forfeit.
PRESS_TERMS = ("contact", "press", "streak")


def _forfeit_press_pay(terms: dict[str, Any], over, cfg: TaskConfig) -> dict[str, Any]:
    """``terms`` with :data:`PRESS_TERMS` zero once success is ruled out by a reading above the
    band (``over``, bool ``(...)``: seen at this step or before), unless the config pays them on
    (``pay_after_overforce``, the default) or no reading rules success out."""
    if cfg.pay_after_overforce or not cfg.fail_on_overforce:
        return terms
    keep = 1.0 - over * 1.0
    return {k: v * keep if k in PRESS_TERMS else v for k, v in terms.items()}


def _masked(xp: Any, sane, terms: dict[str, Any]) -> dict[str, Any]:
    """``terms`` with every term but ``nonfinite`` zero where the step is not ``sane``.

    One env's sane step (``sane`` the Python ``True``, :mod:`mjx_arm.envs.scalar.xp`) keeps
    its terms as they are, without a ``where`` per term.
    """
    if sane is True:
        return terms
    return {k: v if k == "nonfinite" else xp.where(sane, v, 0.0) for k, v in terms.items()}
