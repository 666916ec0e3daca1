"""The position-controlled copy of the PyBullet reference env (see
:mod:`mjx_arm.sim2real.position_env` for the servo law and the chain); the reference engine's
``position_env`` in the engine registry, imported only when a PyBullet position env is made."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mjx_arm.arm.config import ArmConfig
from mjx_arm.arm.resolve import ArmTask
from mjx_arm.envs.base import DEFAULT_HEIGHT, DEFAULT_WIDTH
from mjx_arm.sim2real.position_env import _ChainActuation, servo_gains
from mjx_arm.sim2real.settings import ChainConfig
from mjx_arm.task.config import TaskConfig
from pybullet_ref.env import PybulletArmEnv, pybullet  # pybullet imported quietly there


class PybulletPositionArmEnv(_ChainActuation, PybulletArmEnv):
    """:class:`PybulletArmEnv` driven through the chain into position servos.

    The torque law at every substep is the velocity servo's with the velocity target
    ``K * (q_target - q)``: ``clip(kv * (K * (q_target - q) - qdot), +-effort) - d * qdot
    + g(q)``, the same law as MuJoCo's position actuator with its joint damping and gravity
    compensation. Arguments as for :class:`MujocoPositionArmEnv`.
    """

    def __init__(
        self,
        task: TaskConfig | ArmTask | None = None,
        arm: str | Path | ArmConfig | None = None,
        config: ChainConfig | None = None,
        render_mode: str | None = None,
        width: int = DEFAULT_WIDTH,
        height: int = DEFAULT_HEIGHT,
    ) -> None:
        # the parent's constructor resets the world, which steps the servo: set it up first
        config = config or ChainConfig()
        self._gain = config.servo.position_gain
        self._feedforward = config.servo.feedforward
        self._q_target: list[float] = []
        self._holding = True
        super().__init__(task, arm, render_mode, width, height)
        self._setup_chain(config)
        self._start_chain()
        self.gains = servo_gains(self.servo.kv, self.servo.effort, config.servo)

    def _physics_reset(self, qpos, target_body_pos, obj=None) -> None:
        self._physics_set_position_targets(qpos)  # hold the start pose while the world settles
        holding, self._holding = self._holding, True
        super()._physics_reset(qpos, target_body_pos, obj)
        self._holding = holding
        if hasattr(self, "limiter"):  # not during the parent's constructor
            self._start_chain()

    def _physics_set_position_targets(self, q_target: np.ndarray) -> None:
        self._q_target = [float(v) for v in q_target]

    def gripper_lower(self) -> float:
        """The driven finger's open position (m)."""
        return self.ids.finger_lower

    def finger_position(self) -> float:
        """The driven finger's position (m)."""
        return float(self.client.getJointState(self.body, self.ids.finger)[0])

    def _finger_velocity(self, speed: float) -> None:
        PybulletArmEnv._physics_set_gripper(self, speed)

    def _physics_step(self, n_substeps: int) -> None:
        # PybulletArmEnv._physics_step with the position loop in front of the velocity servo
        calls, body, joints, zeros = self._calls, self.body, self.ids.joints, self._dof_zeros
        dofs, pick, gain = self.ids.dofs, self._pick, self._gain
        for i in range(n_substeps):
            states = calls.get_joint_states(body, dofs)
            gravity = calls.inverse_dynamics(body, [s[0] for s in states], zeros, zeros)
            if pick is not None:  # the arm's joints among the dofs (5 or more: a tuple)
                states, gravity = pick(states), pick(gravity)
            arm = states
            q = [s[0] for s in arm]
            if self._feedforward and not self._holding:
                u = self._servo_velocity((i + 1) / n_substeps, np.asarray(q)).tolist()
            else:
                u = [gain * (t - x) for t, x in zip(self._q_target, q, strict=True)]
            torque = self.servo.torque(u, [s[1] for s in arm], gravity)
            calls.set_motors(body, joints, pybullet.TORQUE_CONTROL, forces=torque)
            if i == n_substeps - 1:
                self._tool_before = self._tool_velocity()
            calls.step()
