"""The gripper's command on its way to a real parallel gripper: a rate-limited position target.

A policy of a gripper task emits one more action entry than the arm has joints: the driven
finger's velocity (positive closes), as a fraction of its speed limit. Grippers such as the
2F-85 take a position (and a speed and a force) instead. :class:`GripperPassthrough` integrates
the velocity command into a finger position target once per control period, at most the
gripper's own speed limit times ``speed_scale`` per second, inside its travel. It has a rate
limit of its own and leaves the arm's limiter alone: the gripper's travel and speed are not
joint angles.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class GripperConfig:
    """How the gripper command is passed on.

    Attributes:
        speed_scale: fraction of the finger's URDF speed limit the target may move at.
        position_gain: the sim stand-in's position loop (1/s): the finger's velocity target is
            this times the position error, capped at its speed limit (a real gripper runs its
            own loop).
    """

    speed_scale: float = 1.0
    position_gain: float = 15.0

    def __post_init__(self) -> None:
        if not (0 < self.speed_scale <= 1 and self.position_gain > 0):
            raise ValueError(f"need 0 < speed_scale <= 1 and position_gain > 0: {self}")


@dataclass
class GripperPassthrough:
    """Velocity commands (m/s) -> a finger position target (m), rate limited.

    Args:
        lower, upper: the driven finger's travel (m): ``lower`` open, ``upper`` closed.
        v_max: the finger's speed limit (m/s).
        dt: control period (s).
        config: speed scale and the stand-in's position loop.

    Attributes:
        target: the position target (m) after the last step.
        clips: how many commands were faster than the rate limit.
    """

    lower: float
    upper: float
    v_max: float
    dt: float
    config: GripperConfig = field(default_factory=GripperConfig)
    target: float = 0.0
    clips: int = 0

    def reset(self, position: float) -> None:
        """Start from the finger's measured position (m)."""
        self.target = float(np.clip(position, self.lower, self.upper))

    def step(self, speed: float) -> float:
        """Integrate one velocity command (m/s; NaN or inf raises) into the target; return it.

        Raises:
            ValueError: a non-finite command.
        """
        if not np.isfinite(speed):
            raise ValueError(f"gripper command is not finite: {speed}")
        limit = self.v_max * self.config.speed_scale
        if abs(speed) > limit + 1e-12:
            self.clips += 1
        move = float(np.clip(speed, -limit, limit)) * self.dt
        self.target = float(np.clip(self.target + move, self.lower, self.upper))
        return self.target

    def servo_speed(self, position: float) -> float:
        """The sim stand-in's finger velocity target (m/s) at the measured ``position``."""
        speed = self.config.position_gain * (self.target - position)
        return float(np.clip(speed, -self.v_max, self.v_max))


def gripper_command_msg(position: float, max_effort: float) -> dict[str, float]:
    """A ROS ``control_msgs/GripperCommand`` as a JSON-ready dict: the finger position (m) and
    the force cap (N)."""
    return {"position": float(position), "max_effort": float(max_effort)}
