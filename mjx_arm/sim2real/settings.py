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
        feedforward: stream the commands at the servo rate with velocity feed-forward: the
            velocity target is ``v_cmd + clip(K * (q_ref - q), +-correction_limit)``,
            ``v_cmd`` the limiter's command velocity and ``q_ref`` the line from the previous
            command to the current one (on a UR: ``speedj`` at the RTDE rate, 500 Hz, with the
            correction computed from the measured joints; or a trajectory controller fed
            positions and velocities). Off: each command is held for a whole control period
            and the loop is ``K * (q_cmd - q)`` alone (``servoj`` with the command as its only
            input).
        correction_limit: cap (rad/s) of the feed-forward stream's correction towards the
            command path.

    Why the feed-forward stream, ``K = 3 /s`` and a 0.1 rad/s cap: a policy trained on
    velocity servos expects a blocked joint to push with ``kv * v_cmd``. A held command must
    lead the arm by ``v / K`` plus a control period of motion to move it at ``v``, so a blocked
    joint pushes several times harder, and harder still as the commands run on; the cube is
    shoved instead of grasped, the box pressed past the force band. With the feed-forward
    doing the moving, ``K`` only pulls drift back onto the command path, and each radian the
    arm is held back adds ``kv * K`` of push: a low gain and a cap keep the arm about as
    compliant to contact as the velocity servo it was trained on. Measured with deploy-sim
    (CPU MuJoCo, 100 episodes; benchmarks/results/sim2real/): Lift's five shipped policies,
    held commands at ``K = 40``: 0.42-0.80 against 0.84-0.96 under velocity control;
    feed-forward at ``K = 40``: 0.85-0.95; at ``K = 10``: 0.90-0.96. A Touch policy (0.95
    under velocity control): held at ``K = 40``: 0.11; feed-forward at ``K = 10``: 0.79, with
    the cap at 0.03 rad/s: 0.92; at ``K = 3``: 0.96; at ``K = 1``: 1.00. At 3 /s a drift of
    0.01 rad is taken back with a time constant of 0.33 s.
    """

    position_gain: float = 3.0
    feedforward: bool = True
    correction_limit: float = 0.1

    def __post_init__(self) -> None:
        if not self.position_gain > 0:
            raise ValueError(f"position_gain must be positive, got {self.position_gain}")
        if not 0 < self.correction_limit <= 10:
            raise ValueError(f"correction_limit must be in (0, 10] rad/s: {self.correction_limit}")


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
