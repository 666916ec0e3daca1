"""The contract on CPU MuJoCo: the MJCF converted from the URDF, stepped by ``mujoco.mj_step``."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from mjx_arm.envs.base import DEFAULT_HEIGHT, DEFAULT_WIDTH, BaseRobotEnv, PhysicsReading
from mjx_arm.envs.model_io import SensorReader, arm_model
from mjx_arm.task.config import TaskConfig
from mjx_arm.urdf.scene import TARGET_BODY


class MujocoArmEnv(BaseRobotEnv):
    """The arm task on C MuJoCo (one world, CPU).

    Args:
        task: the task configuration (default: Touch).
        urdf: the arm URDF (default: the shipped arm).
        render_mode: None, "rgb_array" or "human".
        width, height: frame size (pixels).
    """

    engine = "mujoco"

    def __init__(
        self,
        task: TaskConfig | None = None,
        urdf: str | Path | None = None,
        render_mode: str | None = None,
        width: int = DEFAULT_WIDTH,
        height: int = DEFAULT_HEIGHT,
    ) -> None:
        super().__init__(task, urdf, render_mode, width, height)
        self.model = arm_model(self.arm.urdf, self.task)
        self.data = mujoco.MjData(self.model)
        self.ids = SensorReader(self.model, self.arm)
        self._mocap = self.model.body_mocapid[self.model.body(TARGET_BODY).id]
        self._renderer: mujoco.Renderer | None = None

    def _physics_reset(self, qpos: np.ndarray, target_body_pos: np.ndarray) -> None:
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[self.ids.qpos_adr] = qpos
        self.data.mocap_pos[self._mocap] = target_body_pos
        mujoco.mj_forward(self.model, self.data)
        mujoco.mj_rnePostConstraint(self.model, self.data)
        mujoco.mj_sensorAcc(self.model, self.data)

    def _physics_set_velocity_targets(self, qdot_target: np.ndarray) -> None:
        self.data.ctrl[self.ids.actuators] = qdot_target

    def _physics_step(self, n_substeps: int) -> None:
        # Positions, sensors and contacts are read as the last substep's mj_forward left them
        # (one substep, 1/240 s, before the integrated qpos/qvel), as the MJX env and the
        # batched C backend do: no extra forward pass per control step.
        mujoco.mj_step(self.model, self.data, nstep=n_substeps)

    def _physics_read(self) -> PhysicsReading:
        d = self.data
        return PhysicsReading(
            ee_pos=d.site_xpos[self.ids.ee_site].copy(),
            ee_quat=self.ids.ee_quat(d).copy(),
            qpos=d.qpos[self.ids.qpos_adr].copy(),
            qvel=d.qvel[self.ids.dof_adr].copy(),
            target_pos=d.site_xpos[self.ids.target_site].copy(),
            wrench=self.ids.wrench(np, d.sensordata),
        )

    def _render_frame(self) -> np.ndarray:
        if self._renderer is None:
            # the off-screen framebuffer must hold the frame (MuJoCo's default is 640x480)
            vis = self.model.vis.global_
            vis.offwidth, vis.offheight = (
                max(vis.offwidth, self.width),
                max(vis.offheight, self.height),
            )
            self._renderer = mujoco.Renderer(self.model, self.height, self.width)
        self._renderer.update_scene(self.data, camera="main")
        return self._renderer.render().copy()

    def close(self) -> None:
        """Free the renderer."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        super().close()
