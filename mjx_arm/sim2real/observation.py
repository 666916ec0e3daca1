"""The contract's observation of a real arm: joint encoders, a target and the wrist F/T.

On the robot nothing reads the end-effector pose as the simulation's sensors do: it comes from
the joint angles through the converted model's forward kinematics (``mujoco.mj_kinematics``),
the same model and site the envs read. The rest is assembled by
:func:`mjx_arm.task.observation.assemble_obs`, so the policy sees exactly what it saw in training.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from mjx_arm.arm.config import ArmConfig
from mjx_arm.arm.info import arm_info
from mjx_arm.arm.model_io import arm_model
from mjx_arm.task import observation as obs_lib
from mjx_arm.task.config import TaskConfig
from mjx_arm.urdf.convert import EE_SITE


class ObservationBuilder:
    """Builds the Dict observation from joint angles, a target point and a wrench.

    Args:
        task: the policy's task (force clip, scene of the kinematic model).
        arm: the arm (a URDF, an arm file or an ArmConfig; default: the shipped arm).
    """

    def __init__(self, task: TaskConfig, arm: str | Path | ArmConfig | None = None) -> None:
        self.task = task
        self.arm = arm_info(arm)
        self.model = arm_model(self.arm, task)
        self.data = mujoco.MjData(self.model)
        self._qpos_adr = np.array([self.model.joint(n).qposadr[0] for n in self.arm.joint_names])
        self._site = self.model.site(EE_SITE).id
        self._body = int(self.model.site_bodyid[self._site])
        self.coding = self.arm.joint_coding(task)

    def ee_pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Forward kinematics: ee point (m, base frame) ``(3,)`` and quaternion (w, x, y, z)
        ``(4,)`` at joint angles ``q (n,)`` (rad, contract order)."""
        self.data.qpos[self._qpos_adr] = q
        mujoco.mj_kinematics(self.model, self.data)
        return self.data.site_xpos[self._site].copy(), self.data.xquat[self._body].copy()

    def __call__(
        self, q: np.ndarray, target: np.ndarray, wrench: np.ndarray | None = None
    ) -> dict[str, np.ndarray]:
        """The observation.

        Args:
            q: joint angles (rad), contract order, ``(n,)``.
            target: target point in the base frame (m), ``(3,)``.
            wrench: tared wrist wrench in the ee frame (N, N m), ``(6,)``; zeros if None.

        Returns:
            The contract's Dict observation (float32, inside the observation space).
        """
        q = np.asarray(q, dtype=np.float64)
        n = self.arm.n_joints
        if q.shape != (n,) or not np.isfinite(q).all():
            raise ValueError(f"joint angles must be {n} finite values, got {q!r}")
        ee_pos, ee_quat = self.ee_pose(q)
        w = np.zeros(6) if wrench is None else np.asarray(wrench, dtype=np.float64)
        target = np.asarray(target, dtype=np.float64)
        return obs_lib.assemble_obs(
            np, ee_pos, ee_quat, q, target, w, self.task.force_clip, self.coding
        )
