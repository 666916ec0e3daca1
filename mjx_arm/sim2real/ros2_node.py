"""A ROS 2 node that drives a UR5e with an exported policy through the adapter and the limiter.

Needs ``rclpy`` and the standard message packages (a sourced ROS 2 install); importing this module
without them raises ImportError. Nothing else in :mod:`mjx_arm.sim2real` needs ROS.

Each control period (the policy's ``ctrl_dt``) the node builds the observation from the latest
``sensor_msgs/JointState`` (and ``geometry_msgs/WrenchStamped``, when one arrives), runs the
policy, passes its joint velocities through :class:`VelocityToPositionAdapter` and
:class:`SafetyLimiter`, and publishes the command as a one-point
``trajectory_msgs/JointTrajectory`` due one period later. Before the first command it checks
with tf that the robot's base frame sits where the simulation put it
(:func:`check_frame_alignment`), and that the first observation (the target, the start pose)
lies inside what the policy was trained on (:func:`~mjx_arm.policy.familiar.check_familiar`);
it refuses to start otherwise.

Run it::

    python -m mjx_arm.sim2real.ros2_node --ros-args -p policy:=policy.npz \\
        -p target:="[0.5, 0.1, 0.2]"

Parameters: ``policy`` (file), ``target`` (x, y, z in the base frame, m), ``tau`` (s),
``joint_states`` / ``wrench`` / ``command`` (topics), ``world_frame`` / ``base_frame`` and
``tol_m`` / ``tol_rad`` (the frame check; an empty ``world_frame`` skips it).
"""

from __future__ import annotations

try:
    import rclpy
    from builtin_interfaces.msg import Duration
    from geometry_msgs.msg import WrenchStamped
    from rclpy.node import Node
    from rclpy.time import Time
    from sensor_msgs.msg import JointState
    from tf2_ros import Buffer, TransformListener
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
except ImportError as exc:  # pragma: no cover - depends on the machine
    raise ImportError(
        "mjx_arm.sim2real.ros2_node needs rclpy and the ROS 2 message packages "
        "(sensor_msgs, trajectory_msgs, geometry_msgs, tf2_ros): source a ROS 2 install "
        "(e.g. /opt/ros/jazzy/setup.bash) first. The rest of mjx_arm.sim2real works without it."
    ) from exc

import numpy as np

from mjx_arm.envs.base import check_action
from mjx_arm.evaluate import eval_task
from mjx_arm.policy import load
from mjx_arm.policy.familiar import check_familiar
from mjx_arm.sim2real.adapter import VelocityToPositionAdapter
from mjx_arm.sim2real.commands import duration
from mjx_arm.sim2real.frames import Pose, check_frame_alignment
from mjx_arm.sim2real.limiter import JointLimits, SafetyLimiter
from mjx_arm.sim2real.observation import ObservationBuilder

SIM_BASE = Pose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]))


class PolicyNode(Node):
    """Streams limited joint position commands from a policy (see the module docstring)."""

    def __init__(self) -> None:
        super().__init__("mjx_arm_policy")
        p = {
            "policy": "policy.npz",
            "target": [0.5, 0.0, 0.2],
            "tau": 0.02,
            "joint_states": "/joint_states",
            "wrench": "/force_torque_sensor_broadcaster/wrench",
            "command": "/scaled_joint_trajectory_controller/joint_trajectory",
            "world_frame": "world",
            "base_frame": "base_link",
            "tol_m": 0.005,
            "tol_rad": 0.01,
        }
        for name, default in p.items():
            self.declare_parameter(name, default)
        self.policy = load(self._param("policy"))
        self.task = eval_task(self.policy)[0]
        self.builder = ObservationBuilder(self.task)
        self.names = list(self.builder.arm.joint_names)
        self.limits = JointLimits.from_urdf()
        self.target = np.array(self._param("target"), dtype=np.float64)
        self.q: np.ndarray | None = None
        self.wrench = np.zeros(6)
        self.chain: tuple[VelocityToPositionAdapter, SafetyLimiter] | None = None
        self.tf = Buffer()
        self.tf_listener = TransformListener(self.tf, self)
        self.publisher = self.create_publisher(JointTrajectory, self._param("command"), 1)
        self.create_subscription(JointState, self._param("joint_states"), self._on_joints, 10)
        self.create_subscription(WrenchStamped, self._param("wrench"), self._on_wrench, 10)
        self.create_timer(self.task.ctrl_dt, self._tick)

    def _param(self, name: str):
        return self.get_parameter(name).value

    def _on_joints(self, msg: JointState) -> None:
        index = {name: i for i, name in enumerate(msg.name)}
        if all(n in index for n in self.names):
            self.q = np.array([msg.position[index[n]] for n in self.names])

    def _on_wrench(self, msg: WrenchStamped) -> None:
        f, t = msg.wrench.force, msg.wrench.torque
        self.wrench = np.array([f.x, f.y, f.z, t.x, t.y, t.z])

    def _start(self) -> bool:
        """Check the frames, then start adapter and limiter at the measured joint angles."""
        world = self._param("world_frame")
        if world:
            base = self._param("base_frame")
            if not self.tf.can_transform(world, base, Time()):
                self.get_logger().info(f"waiting for tf {world} -> {base}")
                return False
            robot = Pose.from_tf(self.tf.lookup_transform(world, base, Time()))
            report = check_frame_alignment(
                SIM_BASE, robot, self._param("tol_m"), self._param("tol_rad")
            )
            self.get_logger().info(f"base frame check passed: {report.message()}")
        # a target (or start pose) the policy never trained on: refuse before the first command
        check_familiar(self.policy, self.builder(self.q, self.target, self.wrench))
        dt = self.task.ctrl_dt
        adapter = VelocityToPositionAdapter(
            dt, self._param("tau"), self.q, self.limits.lower, self.limits.upper
        )
        self.chain = (adapter, SafetyLimiter(self.limits, dt, self.q))
        return True

    def _tick(self) -> None:
        if self.q is None or (self.chain is None and not self._start()):
            return
        adapter, limiter = self.chain
        obs = self.builder(self.q, self.target, self.wrench)
        qdot = check_action(self.policy(obs)) * self.task.joint_speeds(self.builder.arm.v_max)
        command = limiter(adapter.step(qdot))
        point = JointTrajectoryPoint(
            positions=command.tolist(),
            velocities=limiter.velocity.tolist(),
            time_from_start=Duration(**duration(self.task.ctrl_dt)),
        )
        self.publisher.publish(JointTrajectory(joint_names=self.names, points=[point]))


def main(args: list[str] | None = None) -> None:
    """Spin a :class:`PolicyNode` until shutdown."""
    rclpy.init(args=args)
    node = PolicyNode()
    try:
        rclpy.spin(node)
    finally:
        node.destroy_node()
        rclpy.shutdown()


if __name__ == "__main__":
    main()
