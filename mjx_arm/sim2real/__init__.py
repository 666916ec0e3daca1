"""Sim-to-real: drive a position-controlled arm (a UR5e) with a policy that emits joint
velocities.

- :class:`VelocityToPositionAdapter`: velocity commands -> filtered position targets.
- :class:`SafetyLimiter`: position, velocity and acceleration limits on the targets.
- :func:`check_frame_alignment`: the simulated base frame against the robot's (tf).
- :func:`urscript_program` / :func:`joint_trajectory_msg`: the commands as URScript ``servoj``
  lines or a ROS 2 ``JointTrajectory`` message (dict).
- :mod:`mjx_arm.sim2real.deploy`: the chain closed around a position-controlled sim arm
  (``mjx-arm deploy-sim``); :mod:`mjx_arm.sim2real.ros2_node`: a ROS 2 node (needs ``rclpy``).

Importing this package loads neither MuJoCo, PyBullet, JAX nor ROS: numpy and what ``mjx_arm``
itself imports (Gymnasium). The envs, the deploy run and the ROS 2 node are imported from their
modules.
"""

from mjx_arm.sim2real.adapter import VelocityToPositionAdapter
from mjx_arm.sim2real.commands import (
    ServojConfig,
    joint_trajectory_msg,
    servoj_line,
    urscript_program,
)
from mjx_arm.sim2real.frames import (
    FrameAlignment,
    FrameAlignmentError,
    Pose,
    check_frame_alignment,
)
from mjx_arm.sim2real.limiter import (
    JointLimits,
    LimiterConfig,
    SafetyLimiter,
    UnsafeCommandError,
)

__all__ = [
    "FrameAlignment",
    "FrameAlignmentError",
    "JointLimits",
    "LimiterConfig",
    "Pose",
    "SafetyLimiter",
    "ServojConfig",
    "UnsafeCommandError",
    "VelocityToPositionAdapter",
    "check_frame_alignment",
    "joint_trajectory_msg",
    "servoj_line",
    "urscript_program",
]
