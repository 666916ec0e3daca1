"""Settings of the sim-to-real chain and of ``deploy-sim``: plain dataclasses, no engine imports.

Kept apart from the envs so that the command line can list the defaults without loading MuJoCo,
PyBullet or JAX.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from mjx_arm.sim2real.commands import ServojConfig
from mjx_arm.sim2real.gripper import GripperConfig
from mjx_arm.sim2real.limiter import LimiterConfig


@dataclass(frozen=True)
class ServoConfig:
    """The position servo of the position-controlled envs.

    Attributes:
        position_gain: ``K`` (1/s), the position loop's gain around the velocity servo: a
            position error ``e`` asks for the joint velocity ``K * e``.
    """

    position_gain: float = 40.0

    def __post_init__(self) -> None:
        if not self.position_gain > 0:
            raise ValueError(f"position_gain must be positive, got {self.position_gain}")


@dataclass(frozen=True)
class ChainConfig:
    """The command chain and servo of a position-controlled env.

    Attributes:
        tau: time constant (s) of the adapter's low-pass filter. 0.02 s (0.6 control periods)
            smooths the 30 Hz staircase of targets and a policy's bang-bang switches while
            adding only 20 ms of lag.
        limiter: how the limiter's limits are derived from the URDF.
        servo: the position servo.
        gripper: the gripper command's passthrough (gripper tasks).
    """

    tau: float = 0.02
    limiter: LimiterConfig = field(default_factory=LimiterConfig)
    servo: ServoConfig = field(default_factory=ServoConfig)
    gripper: GripperConfig = field(default_factory=GripperConfig)

    def __post_init__(self) -> None:
        if not self.tau >= 0:
            raise ValueError(f"tau must be >= 0, got {self.tau}")


@dataclass(frozen=True)
class DeployConfig:
    """Settings of a deploy-sim run.

    Attributes:
        tau, limiter, servo, gripper: the command chain, the servo and the gripper's
            passthrough (see :class:`ChainConfig`).
        lookahead_time, gain: the ``servoj`` arguments of the written URScript.
    """

    tau: float = 0.02
    limiter: LimiterConfig = field(default_factory=LimiterConfig)
    servo: ServoConfig = field(default_factory=ServoConfig)
    gripper: GripperConfig = field(default_factory=GripperConfig)
    lookahead_time: float = 0.1
    gain: float = 300.0

    def __post_init__(self) -> None:
        self.chain()  # range checks
        ServojConfig(t=1.0, lookahead_time=self.lookahead_time, gain=self.gain)

    def chain(self) -> ChainConfig:
        """The position env's chain and servo settings."""
        return ChainConfig(
            tau=self.tau, limiter=self.limiter, servo=self.servo, gripper=self.gripper
        )
