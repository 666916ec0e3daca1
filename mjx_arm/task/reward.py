"""Reward terms, success and termination, written once against an array namespace ``xp``."""

from __future__ import annotations

from typing import Any

from mjx_arm.task.config import REWARD_TERMS, TaskConfig


def target_distance(xp: Any, ee_pos, target_pos):
    """Distance d (m) from the ee point to the target point, shape ``(...)``."""
    return xp.linalg.norm(ee_pos - target_pos, axis=-1)


def force_in_band(xp: Any, force_norm, cfg: TaskConfig):
    """1.0 where the contact force norm (N) lies inside ``cfg.force_band``, else 0.0."""
    low, high = cfg.force_band
    return xp.where((force_norm >= low) & (force_norm <= high), 1.0, 0.0)


def is_success(xp: Any, distance, force_norm, cfg: TaskConfig):
    """Success flag (bool array): Reach d < success_distance; Touch also force in band."""
    near = distance < cfg.success_distance
    if cfg.uses_contact:
        return near & (force_in_band(xp, force_norm, cfg) > 0)
    return near


def reward_terms(
    xp: Any, distance, force_norm, qpos, qvel, joint_limits, success, nonfinite, cfg: TaskConfig
) -> dict:
    """Raw (unweighted) reward terms by name.

    Args:
        xp: ``numpy`` or ``jax.numpy``.
        distance: d (m), shape ``(...)``.
        force_norm: tared contact force norm (N), shape ``(...)``.
        qpos: joint angles (rad), shape ``(..., 6)``.
        qvel: joint velocities (rad/s), shape ``(..., 6)``.
        joint_limits: (lower, upper) joint limits (rad), each shape ``(6,)``.
        success: success flag, shape ``(...)``.
        nonfinite: flag of a non-finite physics state, shape ``(...)``.
        cfg: the task configuration.

    Returns:
        Dict term name -> float array, shape ``(...)``; keys are ``REWARD_TERMS``.
    """
    lower, upper = joint_limits
    mid, half = (upper + lower) / 2, (upper - lower) / 2
    beyond = xp.abs(qpos - mid) > cfg.reward.soft_limit * half
    near = distance < cfg.success_distance
    contact = force_in_band(xp, force_norm, cfg) * near if cfg.uses_contact else 0.0 * distance
    terms = {
        "distance": 1.0 - xp.exp(-distance / cfg.reward.distance_length),
        "contact": contact,
        "joint_limit": xp.sum(beyond, axis=-1) * 1.0,
        "joint_velocity": xp.sum(xp.abs(qvel), axis=-1),
        "success": xp.where(success, 1.0, 0.0),
        "nonfinite": xp.where(nonfinite, 1.0, 0.0),
    }
    assert tuple(terms) == REWARD_TERMS
    return terms


def total_reward(terms: dict, cfg: TaskConfig):
    """Weighted sum of the reward terms, shape ``(...)``."""
    weights = cfg.reward.weights()
    return sum(weights[name] * value for name, value in terms.items())
