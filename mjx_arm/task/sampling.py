"""Episode sampling from uniform draws, so each engine can use its own random generator.

Each function maps uniform numbers in [0, 1) to the episode's start state; numpy draws them from
the env's seeded generator, JAX from ``jax.random.uniform``.
"""

from __future__ import annotations

from typing import Any

from mjx_arm.task.config import TaskConfig
from mjx_arm.task.registry import get_task

N_TARGET_UNIFORMS = 3


def n_uniforms(n_joints: int, cfg: TaskConfig | None = None) -> int:
    """Uniform draws per episode: one per joint for the start pose, 3 for the target and, for
    a gripper task (``cfg``), its object's."""
    extra = get_task(cfg.task).object_uniforms if cfg is not None else 0
    return n_joints + N_TARGET_UNIFORMS + extra


def initial_qpos(xp: Any, u_n, cfg: TaskConfig):
    """Start joint angles (rad): home pose plus uniform noise; ``u_n`` shape ``(..., n)``.

    ``cfg.home_qpos`` must be filled in (:meth:`TaskConfig.for_arm`).
    """
    if not cfg.home_qpos:
        raise ValueError("the task config has no home_qpos: fill it in with TaskConfig.for_arm")
    home = xp.asarray(cfg.home_qpos)
    return home + cfg.init_noise * (2.0 * u_n - 1.0)


def target_body_pos(xp: Any, u3, cfg: TaskConfig):
    """Position (m) of the target body from uniform draws ``u3 (..., 3)``, as the task places
    it (:meth:`mjx_arm.task.spec.Task.target_body_pos`; Touch: the box on the table)."""
    return get_task(cfg.task).target_body_pos(xp, u3[..., :N_TARGET_UNIFORMS], cfg)


def target_point(xp: Any, body_pos, cfg: TaskConfig):
    """The point the ee must reach (m), ``(..., 3)`` (Touch: the box's top-face centre)."""
    return get_task(cfg.task).target_point(xp, body_pos, cfg)
