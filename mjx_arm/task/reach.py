"""Reach: bring the tool tip within 2 cm of a point in the air; nothing to touch."""

from __future__ import annotations

from typing import Any

from mjx_arm.task.config import RewardConfig, TaskConfig
from mjx_arm.task.spec import Task
from mjx_arm.urdf.scene_shapes import REACH_SCENE


class Reach(Task):
    """A point target drawn in a box in front of the arm; success is being within 2 cm of it."""

    name = "reach"
    scene = REACH_SCENE

    def config(self, **overrides: Any) -> TaskConfig:
        """The Reach preset; ``variant`` may only be ``"seed"`` (Reach has one variant)."""
        if overrides.pop("variant", "seed") != "seed":
            raise ValueError("reach has a single variant, 'seed'")
        base = TaskConfig(
            task="reach",
            success_distance=0.02,
            target_low=(0.35, -0.25, 0.10),
            target_high=(0.65, 0.25, 0.45),
            reward=RewardConfig(contact=0.0),
        )
        return base.replace(**overrides)


REACH = Reach()


def reach_config(**overrides: Any) -> TaskConfig:
    """The Reach preset with ``overrides``."""
    return REACH.config(**overrides)
