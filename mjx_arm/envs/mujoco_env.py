"""The contract on CPU MuJoCo: the MJCF converted from the URDF, stepped by ``mujoco.mj_step``."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from mjx_arm.arm.config import ArmConfig
from mjx_arm.arm.model_io import EE_POS as _EE_POS
from mjx_arm.arm.model_io import EE_QUAT as _EE_QUAT
from mjx_arm.arm.model_io import GripReader, SensorReader, arm_model, as_slice
from mjx_arm.arm.resolve import ArmTask
from mjx_arm.envs.base import DEFAULT_HEIGHT, DEFAULT_WIDTH, BaseRobotEnv, PhysicsReading
from mjx_arm.envs.camera import task_camera
from mjx_arm.task import sampling
from mjx_arm.task.config import TaskConfig
from mjx_arm.task.grip import ObjectStart
from mjx_arm.urdf.scene import TARGET_BODY
from mjx_arm.video import scene_option

_NO_GRIP = PhysicsReading._field_defaults["grip"]  # the reading's grip without a gripper


class MujocoArmEnv(BaseRobotEnv):
    """The arm task on C MuJoCo (one world, CPU).

    Args:
        task: the task on its arm (:class:`~mjx_arm.arm.resolve.ArmTask`), or a task
            configuration (default: Touch) resolved with ``arm``.
        arm: with a task configuration, the arm (a URDF, an arm file or an ArmConfig;
            default: the shipped arm).
        render_mode: None, "rgb_array" or "human".
        width, height: frame size (pixels).
    """

    engine = "mujoco"

    def __init__(
        self,
        task: TaskConfig | ArmTask | None = None,
        arm: str | Path | ArmConfig | None = None,
        render_mode: str | None = None,
        width: int = DEFAULT_WIDTH,
        height: int = DEFAULT_HEIGHT,
    ) -> None:
        super().__init__(task, arm, render_mode, width, height)
        self.model = arm_model(self.arm, self.task)
        self.data = mujoco.MjData(self.model)
        self.ids = SensorReader(self.model, self.arm)
        self._mocap = self.model.body_mocapid[self.model.body(TARGET_BODY).id]
        self._renderer: mujoco.Renderer | None = None
        # The step's read-out, set up once: views of MjData's arrays (valid while ``data``
        # lives). Reads gather with intp index arrays (numpy's fast path, and a copy).
        self._ctrl, self._sensordata = self.data.ctrl, self.data.sensordata
        self._qpos, self._qvel = self.data.qpos, self.data.qvel
        self._act = as_slice(self.ids.actuators)
        self._qpos_adr = self.ids.qpos_adr.astype(np.intp)
        self._dof_adr = self.ids.dof_adr.astype(np.intp)
        self._target_pos = np.zeros(3)  # the target point: fixed within an episode
        self.grip = GripReader(self.model, self.arm) if self.task.spec.gripper else None

    def _physics_reset(
        self, qpos: np.ndarray, target_body_pos: np.ndarray, obj: ObjectStart | None = None
    ) -> None:
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[self.ids.qpos_adr] = qpos
        self.data.mocap_pos[self._mocap] = target_body_pos
        if self.grip is not None:  # the cube at the target (its marker is not drawn), open
            self.grip.place(self.data.qpos, target_body_pos, obj.quat)
            self.grip.open(self.data.qpos)
            self.grip.dress(self.model, float(obj.mass), float(obj.friction))
        mujoco.mj_forward(self.model, self.data)
        mujoco.mj_rnePostConstraint(self.model, self.data)
        mujoco.mj_sensorAcc(self.model, self.data)
        # the target (a mocap body) only moves here: its point is fixed for the episode, where
        # the task puts it on the body (the C batch and MJX use the same rule)
        self._target_pos = np.asarray(sampling.target_point(np, target_body_pos, self.task))
        self._target_pos.setflags(write=False)

    def _physics_set_velocity_targets(self, qdot_target: np.ndarray) -> None:
        self._ctrl[self._act] = qdot_target

    def _physics_set_gripper(self, speed: float) -> None:
        self._ctrl[self.grip.finger_act] = speed

    def _physics_step(self, n_substeps: int) -> None:
        # Positions, sensors and contacts are read as the last substep's mj_forward left them
        # (one substep, 1/240 s, before the integrated qpos/qvel), as the MJX env and the
        # batched C backend do: no extra forward pass per control step.
        mujoco.mj_step(self.model, self.data, nstep=n_substeps)

    def _physics_read(self) -> PhysicsReading:
        # one gather of the sensors: the wrench block, the ee site's position and quaternion
        # (framepos / framequat of the ee site: the values of site_xpos and the body's xquat)
        s, wrench = self.ids.read(self._sensordata)
        target, grip = self._target_pos, _NO_GRIP
        if self.grip is not None:  # the target is the cube, wherever it is now
            grip = self.grip.read(np, self._qpos, self._sensordata)
            target = grip[1:4]
        return PhysicsReading(  # fields in order: ee_pos, ee_quat, qpos, qvel, target_pos, wrench
            s[_EE_POS],
            s[_EE_QUAT],
            self._qpos.take(self._qpos_adr),
            self._qvel.take(self._dof_adr),
            target,
            wrench,
            grip,
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
            self._aim_camera()
        self._renderer.update_scene(self.data, camera="main", scene_option=self._scene_option)
        return self._renderer.render().copy()

    def _aim_camera(self) -> None:
        """Frame the arm and the task area (:func:`~mjx_arm.envs.camera.task_camera`, as the
        PyBullet env does) with the scene's camera, and draw the arm's collision shapes where
        it has no visual ones (:func:`~mjx_arm.video.scene_option`)."""
        view = task_camera(self.arm_task, self.width / self.height)
        camera = self.model.camera("main").id
        self.model.cam_pos[camera] = view.eye
        self.model.cam_quat[camera] = view.quat()
        self.model.cam_fovy[camera] = view.fovy
        self.data.cam_xpos[camera] = view.eye  # as the next step's kinematics will put it
        self.data.cam_xmat[camera] = view.axes().T.ravel()
        self._scene_option = scene_option(self.model)

    def close(self) -> None:
        """Free the renderer."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        super().close()
