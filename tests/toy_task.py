"""A toy task in one file: hover the tool tip above a spot on the table.

This is everything a new task needs: a :class:`~mjx_arm.task.spec.Task` subclass with its config
preset and the methods it changes, registered by name. The engines, the Gymnasium id and the
reward rules pick it up from the registry.
"""

from __future__ import annotations

from typing import Any

from mjx_arm.task import RewardConfig, Task, TaskConfig, register_task

HOVER_HEIGHT = 0.37  # m above the table: the tool's height at the home pose


class Hover(Task):
    """Hold the tool tip within 3 cm of a point ``HOVER_HEIGHT`` above a spot on the table, for
    5 control steps running; nothing is touched."""

    name = "hover"
    scene = "reach"  # a marker, nothing to collide with

    def config(self, **overrides: Any) -> TaskConfig:
        base = TaskConfig(
            task=self.name,
            episode_steps=60,
            success_distance=0.03,
            success_hold_steps=5,
            target_low=(0.40, -0.20, 0.0),
            target_high=(0.60, 0.20, 0.0),
            reward=RewardConfig(contact=0.0, success=10.0),
        )
        return base.replace(**overrides)

    def target_body_pos(self, xp: Any, u3, cfg: TaskConfig):
        """The spot on the table (z = 0)."""
        return super().target_body_pos(xp, u3, cfg) * xp.asarray([1.0, 1.0, 0.0])

    def target_point(self, xp: Any, body_pos, cfg: TaskConfig):
        """The point above the spot."""
        return body_pos + xp.asarray([0.0, 0.0, HOVER_HEIGHT])


HOVER = register_task(Hover(), replace=True)
