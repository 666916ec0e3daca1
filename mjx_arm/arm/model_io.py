"""Compiled MuJoCo model of a task, and name-based access to what the contract reads from it.

Shared by the CPU MuJoCo env and the MJX env, so both read the same sites and sensors.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import mujoco
import numpy as np

from mjx_arm.arm.info import ArmInfo, arm_info
from mjx_arm.task.config import TaskConfig
from mjx_arm.task.wrench import (
    SENSOR_BLOCK,
    SENSOR_BLOCK_SIZE,
    sensor_feature_factors,
    sensor_wrench,
)
from mjx_arm.urdf.convert import EE_SITE, FT_SITE, SENSORS, ConvertConfig, load_model
from mjx_arm.urdf.scene import TARGET_SITE
from mjx_arm.urdf.scene_shapes import CUBE_BODY
from mjx_arm.urdf.spec_edits import pad_sensor


def task_convert_config(task: TaskConfig, arm: ArmInfo | None = None) -> ConvertConfig:
    """Conversion settings of a task model: the arm's ee and F/T point (default: the shipped
    arm's), the task's scene (its cube at the task's ``object_scale``), time step, servo step
    and solver iterations (where the task sets them), no self-collision; a gripper task's finger
    pads get touch sensors."""
    arm = arm or arm_info()
    spec = task.spec
    pads = arm.gripper.pad_links if spec.gripper and arm.gripper else ()
    scene = spec.scene
    if scene.cube_half and task.object_scale:  # the task's cube (smaller for a small gripper)
        scene = dataclasses.replace(scene, cube_half=scene.cube_half * task.object_scale)
    solver = {
        key: value
        for key, value in (
            ("solver_iterations", task.solver_iterations),
            ("ls_iterations", task.ls_iterations),
        )
        if value > 0
    }
    return arm.convert_config(
        scene=scene,
        sim_dt=task.sim_dt,
        servo_dt=spec.servo_dt,
        pad_links=pads,
        self_collision=False,
        **solver,
    )


def arm_model(arm: ArmInfo, task: TaskConfig) -> mujoco.MjModel:
    """The task's MuJoCo model: ``arm`` converted from its URDF with the task scene."""
    return load_model(arm.urdf, task_convert_config(task, arm))


# The model's sensor of each entry of the wrench sensor block (``SENSOR_BLOCK`` order).
BLOCK_SENSORS = {
    "force": "ft_force",
    "torque": "ft_torque",
    "acc": "tool_acc",
    "gyro": "tool_gyro",
    "angacc": "tool_angacc",
    "quat": "ft_quat",
}
# What one gather of the sensor data holds (:attr:`SensorReader.read_index`): the wrench block,
# then the ee site's position and orientation.
BLOCK = slice(0, SENSOR_BLOCK_SIZE)
EE_POS = slice(SENSOR_BLOCK_SIZE, SENSOR_BLOCK_SIZE + 3)
EE_QUAT = slice(SENSOR_BLOCK_SIZE + 3, SENSOR_BLOCK_SIZE + 7)


class SensorReader:
    """Ids and addresses, looked up by name once, and the contract read-outs built on them.

    Attributes:
        qpos_adr, dof_adr: qpos and dof addresses of the arm's n joints, ``(n,)`` each.
        actuators: actuator ids of the n joints, ``(n,)``.
        ee_site, ee_body, target_site: ids of the ee site, its body and the target site.
        flange_body: the body the wrist F/T sensor's body hangs from (where a payload goes:
            upstream of the sensor, so the tared reading does not carry its weight).
        table_geoms: ids of the table's geoms, ``(k,)``.
        sensor_slices: where each named sensor sits in ``sensordata``.
        block_index: ``sensordata`` positions of the wrench block
            (:data:`mjx_arm.task.wrench.SENSOR_BLOCK` order), ``(19,)``.
        read_index: ``block_index`` then the ee position and quaternion sensors, ``(26,)``;
            ``sensordata[read_index]`` splits with :data:`BLOCK`, :data:`EE_POS`, :data:`EE_QUAT`.
    """

    def __init__(self, model: mujoco.MjModel, arm: ArmInfo) -> None:
        self.arm = arm
        joints = [model.joint(name) for name in arm.joint_names]
        self.qpos_adr = np.array([j.qposadr[0] for j in joints])
        self.dof_adr = np.array([j.dofadr[0] for j in joints])
        self.actuators = np.array([model.actuator(name).id for name in arm.joint_names])
        self.ee_site = model.site(EE_SITE).id
        self.ee_body = int(model.site_bodyid[self.ee_site])
        self.target_site = model.site(TARGET_SITE).id
        self.flange_body = int(model.body_parentid[model.site_bodyid[model.site(FT_SITE).id]])
        names = [model.geom(i).name for i in range(model.ngeom)]
        self.table_geoms = np.array([i for i, name in enumerate(names) if name.startswith("table")])
        self.sensor_slices = {
            name: slice(
                int(model.sensor(name).adr[0]),
                int(model.sensor(name).adr[0]) + int(model.sensor(name).dim[0]),
            )
            for name in SENSORS
        }
        block = [self._positions(BLOCK_SENSORS[name], size) for name, size in SENSOR_BLOCK]
        self.block_index = np.concatenate(block)
        self.read_index = np.concatenate(
            [self.block_index, self._positions("ee_pos", 3), self._positions("ee_quat", 4)]
        )
        self._block = as_slice(self.block_index)
        # one env's read (:meth:`read`): the gather, a 1.0 after it, the wrench's features
        self._gathered = np.zeros(len(self.read_index) + 1)
        self._gathered[-1] = 1.0
        self._factors = sensor_feature_factors(one=len(self.read_index))

    def _positions(self, name: str, size: int) -> np.ndarray:
        sl = self.sensor_slices[name]
        if sl.stop - sl.start != size:
            raise ValueError(f"sensor {name!r} has {sl.stop - sl.start} values, expected {size}")
        return np.arange(sl.start, sl.stop)

    def ee_quat(self, data: Any):
        """ee orientation (w, x, y, z), ``(4,)``: the ee body's, whose frame the site shares."""
        return data.xquat[self.ee_body]

    def block(self, sensordata):
        """The wrench sensor block of ``sensordata (..., nsensordata)``, shape ``(..., 19)``."""
        if isinstance(self._block, slice):
            return sensordata[..., self._block]
        return sensordata.take(self._block, axis=-1)

    def read(self, sensordata: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One env's read-out of a numpy ``sensordata``, in new arrays.

        Returns:
            ``sensordata[read_index]`` (split with :data:`BLOCK`, :data:`EE_POS`,
            :data:`EE_QUAT`) with a 1.0 after it, ``(27,)``, and the wrench
            (:meth:`wrench`'s values), ``(6,)``.
        """
        s = self._gathered.copy()
        sensordata.take(self.read_index, out=s[:-1])
        a, b, c = self._factors
        return s, (s.take(a) * s.take(b) * s.take(c)).dot(self.arm.tool.sensor_wrench_matrix)

    def wrench(self, xp: Any, sensordata):
        """Tared external wrench on the tool in the ee frame, shape ``(..., 6)``."""
        return sensor_wrench(xp, self.block(sensordata), self.arm.tool)


class GripReader:
    """Addresses of what a gripper task reads (:data:`mjx_arm.task.grip.GRIP_LAYOUT`): the
    driven finger, the free cube and the pads' touch sensors, looked up by name once.

    Attributes:
        finger_qpos: qpos address of the driven finger; finger_act: its actuator id.
        fingers_qpos: qpos addresses of every gripper joint (the driven one and its mimics);
            open_qpos: their positions open.
        lower, stroke: the finger's lower limit and travel (m).
        gripper: the arm's :class:`~mjx_arm.arm.info.Gripper` (open and closed positions).
        cube_qpos: qpos address of the cube's free joint (position, then quaternion).
        cube_dof: its dof address (6 velocities).
        pad_index: ``sensordata`` positions of the pads' touch sensors, ``(2,)``.
        cube_body: the cube's body id; friction_geoms: the cube's and the pads' geoms (their
            friction is the episode's); mass0, inertia0: the cube's mass and inertia as built.
    """

    def __init__(self, model: mujoco.MjModel, arm: ArmInfo) -> None:
        gripper = arm.gripper
        if gripper is None:
            raise ValueError(f"{arm.urdf} has no gripper")
        joint = model.joint(gripper.joint)
        self.finger_qpos = int(joint.qposadr[0])
        self.finger_act = int(model.actuator(gripper.joint).id)
        self.lower, self.stroke = float(joint.range[0]), gripper.stroke
        self.gripper = gripper
        # every gripper joint's qpos (the driven one and its mimics) and where opening puts
        # them (a reset's qpos0 has them at the URDF's 0, closed on some grippers)
        opened = gripper.positions(gripper.open_q)
        self.fingers_qpos = np.array([int(model.joint(name).qposadr[0]) for name in opened])
        self.open_qpos = np.array(list(opened.values()))
        cube = model.joint(CUBE_BODY)
        self.cube_qpos, self.cube_dof = int(cube.qposadr[0]), int(cube.dofadr[0])
        self.pad_index = np.array(
            [int(model.sensor(pad_sensor(link)).adr[0]) for link in gripper.pad_links[:2]]
        )
        self.cube_body = int(model.body(CUBE_BODY).id)
        bodies = [self.cube_body, *(int(model.body(link).id) for link in gripper.pad_links)]
        collides = (model.geom_contype > 0) | (model.geom_conaffinity > 0)
        self.friction_geoms = np.flatnonzero(np.isin(model.geom_bodyid, bodies) & collides)
        self.mass0 = float(model.body_mass[self.cube_body])
        self.inertia0 = model.body_inertia[self.cube_body].copy()
        self.invweight0 = model.body_invweight0[self.cube_body].copy()
        self.dof_invweight0 = model.dof_invweight0[self.cube_dof : self.cube_dof + 6].copy()
        self.dof_m0 = model.dof_M0[self.cube_dof : self.cube_dof + 6].copy()
        self.world_mass0 = float(model.body_subtreemass[0])

    def dress(self, model: Any, mass, friction) -> Any:
        """``model`` (an MjModel, in place; or an MJX model, returned) with the cube's mass
        (kg) and the sliding friction of cube and pads.

        The cube's inertia scales with its mass, and so do the constants MuJoCo precomputes
        from it (``mj_setConst`` gives the same values): the subtree masses, the diagonal of
        the mass matrix at ``qpos0`` and, inversely, the inverse weights of the contact
        softness. Left stale, a heavier cube diverges in the grip.
        """
        body, geoms, dofs = (
            self.cube_body,
            self.friction_geoms,
            slice(self.cube_dof, self.cube_dof + 6),
        )
        ratio = mass / self.mass0
        fields = {
            "body_mass": (body, mass),
            "body_inertia": (body, self.inertia0 * ratio),
            "body_invweight0": (body, self.invweight0 / ratio),
            "dof_invweight0": (dofs, self.dof_invweight0 / ratio),
            "dof_M0": (dofs, self.dof_m0 * ratio),
            "body_subtreemass": (np.array([0, body]), [self.world_mass0 - self.mass0 + mass, mass]),
        }
        if isinstance(model, mujoco.MjModel):
            for name, (index, value) in fields.items():
                getattr(model, name)[index] = value
            model.geom_friction[geoms, 0] = friction
            return model
        changes = {n: getattr(model, n).at[i].set(v) for n, (i, v) in fields.items()}
        changes["geom_friction"] = model.geom_friction.at[geoms, 0].set(friction)
        return model.replace(**changes)

    def read(self, xp: Any, qpos, sensordata):
        """The ``grip`` vector ``(10,)`` of one state's ``qpos`` and ``sensordata``."""
        closure = self.gripper.closure(qpos[self.finger_qpos : self.finger_qpos + 1])
        cube = qpos[self.cube_qpos : self.cube_qpos + 7]
        return xp.concatenate([closure, cube, sensordata[self.pad_index]])

    def open(self, qpos):
        """``qpos`` with the fingers open: a numpy array in place (returned), or a JAX array's
        updated copy."""
        if isinstance(qpos, np.ndarray):
            qpos[self.fingers_qpos] = self.open_qpos
            return qpos
        return qpos.at[self.fingers_qpos].set(self.open_qpos)

    def place(self, qpos, pos, quat) -> None:
        """Write the cube's pose into a numpy ``qpos`` (in place)."""
        qpos[self.cube_qpos : self.cube_qpos + 3] = pos
        qpos[self.cube_qpos + 3 : self.cube_qpos + 7] = quat


def as_slice(index: np.ndarray) -> slice | np.ndarray:
    """``index`` as a slice when it is a run of consecutive positions, else unchanged."""
    start = int(index[0])
    if np.array_equal(index, np.arange(start, start + len(index))):
        return slice(start, start + len(index))
    return index
