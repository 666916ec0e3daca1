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
from mjx_arm.urdf.convert import EE_SITE, SENSORS, ConvertConfig, load_model
from mjx_arm.urdf.scene import TARGET_SITE


def task_convert_config(task: TaskConfig) -> ConvertConfig:
    """Conversion settings of a task model: its scene and time step, no self-collision."""
    return ConvertConfig(scene=task.task, sim_dt=task.sim_dt, self_collision=False)


def arm_model(urdf: Path, task: TaskConfig) -> mujoco.MjModel:
    """The task's MuJoCo model: the arm converted from ``urdf`` with the task scene."""
    return load_model(Path(urdf).resolve(), task_convert_config(task))


class SensorReader:
    """Ids and addresses, looked up by name once, and the contract read-outs built on them."""

    def __init__(self, model: mujoco.MjModel, arm: ArmInfo) -> None:
        self.arm = arm
        joints = [model.joint(name) for name in arm.joint_names]
        self.qpos_adr = np.array([j.qposadr[0] for j in joints])
        self.dof_adr = np.array([j.dofadr[0] for j in joints])
        self.actuators = np.array([model.actuator(name).id for name in arm.joint_names])
        self.ee_site = model.site(EE_SITE).id
        self.ee_body = int(model.site_bodyid[self.ee_site])
        self.target_site = model.site(TARGET_SITE).id
        self.sensor_slices = {
            name: slice(
                int(model.sensor(name).adr[0]),
                int(model.sensor(name).adr[0]) + int(model.sensor(name).dim[0]),
            )
            for name in SENSORS
        }

    def ee_quat(self, data: Any):
        """ee orientation (w, x, y, z), ``(4,)``: the ee body's, whose frame the site shares."""
        return data.xquat[self.ee_body]

    def wrench(self, xp: Any, sensordata):
        """Tared external wrench on the tool in the ee frame, shape ``(6,)``."""
        s = {name: sensordata[sl] for name, sl in self.sensor_slices.items()}
        # frameangacc reports in the world frame; the other tool sensors in the sensor frame
        alpha = quat_rotate_inverse(xp, s["ft_quat"], s["tool_angacc"])
        return external_wrench(
            xp, s["ft_force"], s["ft_torque"], s["tool_acc"], s["tool_gyro"], alpha, self.arm.tool
        )


def quat_rotate_inverse(xp: Any, quat, vec):
    """Rotate ``vec (3,)`` by the inverse of unit quaternion ``quat (4,)`` (w, x, y, z)."""
    w, u = quat[0], quat[1:]
    t = 2.0 * xp.cross(-u, vec)
    return vec + w * t + xp.cross(-u, t)
