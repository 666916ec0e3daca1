"""Episode sampling from uniform draws, so each engine can use its own random generator.

Each function maps uniform numbers in [0, 1) to the episode's start state; numpy draws them from
the env's seeded generator, JAX from ``jax.random.uniform``.
"""

from __future__ import annotations

from typing import Any

from mjx_arm.task.config import TaskConfig
from mjx_arm.urdf.scene import box_top_offset

N_UNIFORMS = 9  # 6 for the start pose, 3 for the target


def initial_qpos(xp: Any, u6, cfg: TaskConfig):
    """Start joint angles (rad): home pose plus uniform noise; ``u6`` shape ``(..., 6)``."""
    home = xp.asarray(cfg.home_qpos)
    return home + cfg.init_noise * (2.0 * u6 - 1.0)


def target_body_pos(xp: Any, u3, cfg: TaskConfig):
    """Position (m) of the target body; ``u3`` shape ``(..., 3)``.

    Reach: the target point itself. Touch: the box's bottom-face centre, standing on the table
    (z = 0); the target point is the top-face centre, see :func:`target_point`.
    """
    low, high = xp.asarray(cfg.target_low), xp.asarray(cfg.target_high)
    pos = low + u3 * (high - low)
    if cfg.uses_contact:
        pos = pos * xp.asarray([1.0, 1.0, 0.0])
    return pos


def target_point(xp: Any, body_pos, cfg: TaskConfig):
    """The point the ee must reach (m), shape ``(..., 3)``: for Touch the box's top-face centre."""
    if cfg.uses_contact:
        return body_pos + xp.asarray([0.0, 0.0, box_top_offset()])
    return body_pos
