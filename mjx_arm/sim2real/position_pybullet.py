"""The position-controlled copy of the PyBullet reference env (see
:mod:`mjx_arm.sim2real.position_env` for the servo law and the chain); the reference engine's
``position_env`` in the engine registry, imported only when a PyBullet position env is made."""

from __future__ import annotations

import functools
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

    The drive at every substep is the velocity servo's (:mod:`pybullet_ref.drive`) with the
    velocity target ``K * (q_target - q)``: MuJoCo's position actuator with its joint damping
    and gravity compensation. Arguments as for :class:`MujocoPositionArmEnv`.
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
        calls, body, joints, dofs = self._calls, self.body, self.ids.joints, self.ids.dofs
        target = self._position_target
        for i in range(n_substeps):
            if self._feedforward and not self._holding:
                target = functools.partial(self._feedforward_target, (i + 1) / n_substeps)
            states = calls.get_joint_states(body, dofs)
            torque = self._drive.torques(calls, body, states, target)
            calls.set_motors(body, joints, pybullet.TORQUE_CONTROL, forces=torque)
            if i == n_substeps - 1:
                self._tool_before = self._tool_velocity()
            calls.step()

    def _position_target(self, q: list[float]) -> list[float]:
        """The velocity targets (rad/s) of the position loop at the joint angles ``q``."""
        gain = self._gain
        return [gain * (t - x) for t, x in zip(self._q_target, q, strict=True)]

    def _feedforward_target(self, frac: float, q: list[float]) -> list[float]:
        """The feed-forward loop's velocity targets (rad/s) at ``frac`` of the control step."""
        return self._servo_velocity(frac, np.asarray(q)).tolist()
