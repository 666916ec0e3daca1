"""Compiled MuJoCo model of a task, and name-based access to what the contract reads from it.

Shared by the CPU MuJoCo env and the MJX env, so both read the same sites and sensors.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from mjx_arm.envs.arm import ArmInfo
from mjx_arm.task.config import TaskConfig
from mjx_arm.task.wrench import external_wrench
from mjx_arm.urdf.convert import EE_SITE, ConvertConfig, load_model
from mjx_arm.urdf.scene import TARGET_SITE


def arm_model(urdf: Path, task: TaskConfig) -> mujoco.MjModel:
    """The task's MuJoCo model: the arm converted from ``urdf`` with the task scene."""
    path = Path(urdf).resolve()
    return load_model(path, ConvertConfig(scene=task.task, sim_dt=task.sim_dt))


class SensorReader:
    """Ids and addresses, looked up by name once, and the contract read-outs built on them."""

    def __init__(self, model: mujoco.MjModel, arm: ArmInfo) -> None:
        self.arm = arm
        joints = [model.joint(name) for name in arm.joint_names]
        self.qpos_adr = np.array([j.qposadr[0] for j in joints])
        self.dof_adr = np.array([j.dofadr[0] for j in joints])
        self.actuators = np.array([model.actuator(name).id for name in arm.joint_names])
        self.ee_site = model.site(EE_SITE).id
        self.target_site = model.site(TARGET_SITE).id
        self.sensor_slices = {
            name: slice(int(model.sensor(name).adr[0]), int(model.sensor(name).adr[0]) + 3)
            for name in ("ft_force", "ft_torque", "tool_acc", "tool_gyro", "tool_angacc")
        }

    def ee_quat(self, data: Any, xp: Any = np):
        """ee orientation (w, x, y, z) from the site's rotation matrix, shape ``(4,)``."""
        if xp is np:
            quat = np.zeros(4)
            mujoco.mju_mat2Quat(quat, data.site_xmat[self.ee_site].ravel())
            return quat
        from mujoco.mjx._src import math as mjx_math

        return mjx_math.quat_from_mat(data.site_xmat[self.ee_site])  # pragma: no cover

    def wrench(self, xp: Any, sensordata):
        """Tared external wrench on the tool in the ee frame, shape ``(6,)``."""
        s = {name: sensordata[sl] for name, sl in self.sensor_slices.items()}
        return external_wrench(
            xp,
            s["ft_force"],
            s["ft_torque"],
            s["tool_acc"],
            s["tool_gyro"],
            s["tool_angacc"],
            self.arm.tool,
        )
