"""A toy task in one file: hover the tool tip above a spot on the table.

This is everything a new task needs: a :class:`~mjx_arm.task.spec.Task` subclass with its config
preset, the methods it changes, its own reward term (a reward type that adds its weight), its
scene and its training budget, registered by name (:func:`~mjx_arm.task.registry.register_task`;
the tests register it and take it out again). The engines, the Gymnasium id, the reward rules
and the presets pick it up from the registry.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

from mjx_arm.task import RewardConfig, Task, TaskConfig
from mjx_arm.task.spec import Budget
from mjx_arm.urdf.scene_shapes import SceneSpec

HOVER_HEIGHT = 0.37  # m above the table: the tool's height at the home pose
HOVER_BUDGET = Budget(num_timesteps=50_000, num_evals=2)  # its cpu preset's budget


@dataclass(frozen=True)
class HoverReward(RewardConfig):
    """The shared weights and the toy's own term, ``height``: the tool tip's height above the
    table (m)."""

    task_terms: ClassVar[tuple[str, ...]] = ("height",)
    height: float = 0.0


class Hover(Task):
    """Hold the tool tip within 3 cm of a point ``HOVER_HEIGHT`` above a spot on the table, for
    5 control steps running; nothing is touched."""

    name = "hover"
    # the table and a target that is not drawn: nothing to collide with, nothing to see
    scene = SceneSpec("hover", marker=False)
    reward_type = HoverReward
    budgets: ClassVar[Mapping[str, Budget]] = {"cpu": HOVER_BUDGET}

    def config(self, **overrides: Any) -> TaskConfig:
        base = TaskConfig(
            task=self.name,
            episode_steps=60,
            success_distance=0.03,
            success_hold_steps=5,
            target_low=(0.40, -0.20, 0.0),
            target_high=(0.60, 0.20, 0.0),
            reward=HoverReward(contact=0.0, success=10.0, height=2.0),
        )
        return base.replace(**overrides)

    def target_body_pos(self, xp: Any, u3, cfg: TaskConfig):
        """The spot on the table (z = 0)."""
        return super().target_body_pos(xp, u3, cfg) * xp.asarray([1.0, 1.0, 0.0])

    def target_point(self, xp: Any, body_pos, cfg: TaskConfig):
        """The point above the spot."""
        return body_pos + xp.asarray([0.0, 0.0, HOVER_HEIGHT])

    def measures(self, xp: Any, ee_pos, ee_quat, grip, cfg: TaskConfig) -> dict[str, Any]:
        """``height``: the tool tip's height above the table (m), ``(...)``."""
        return {"height": ee_pos[..., 2]}

    def task_terms(self, xp: Any, extra: dict[str, Any], zero) -> dict[str, Any]:
        """The ``height`` term: the measure as it is."""
        return {"height": extra["height"] + zero}


HOVER = Hover()
