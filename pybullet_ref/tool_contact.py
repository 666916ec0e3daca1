"""The table and box contact of one arm: the calibrated spring scaled by the arm's tool mass.

MuJoCo's soft contact scales with the effective mass ``m`` of the pair (its spring and damper
are ``2.6e3 m`` and ``100 m``, :mod:`pybullet_ref.contact`), so a tool meets the box with the
same time constant on every arm. Bullet's spring is a fixed stiffness: calibrated on the UR5e
and UR10 (``m`` 5.2 and 5.5 kg at home), it was a third too stiff for the xArm7's 3.9 kg, whose
first strikes peaked about 30 % harder in PyBullet than in MuJoCo. So ``"soft"`` here is the
calibrated spring and damper times ``m / m_ref``, ``m`` the arm's effective mass at the tool
along the vertical at its Touch home pose in the converted MuJoCo model (armature included),
``m_ref`` the shipped arm's; the shipped arm keeps the calibrated values.

The free cube's spring (calibrated with the shipped 4.5 cm cube) is stiffened by ``1 /
object_scale**2`` for the smaller cube of an arm whose gripper opens less
(:func:`mjx_arm.task.lift.cube_half`). On the SO-101's 2.3 cm cube (scale 0.5) its jaw, which
presses up to 30 N, sank 6-8 mm into the calibrated spring and knocked the cube away: its Lift
export scored 0.805 in PyBullet against 0.980 in CPU MuJoCo (200 episodes from seed 1000); at
2x, 4x the spring it scored 0.940, 0.985. The 4x (the inverse square) was chosen there;
checked on another episode range: benchmarks/results/arms/small_and_grippers/.
"""

from __future__ import annotations

import functools

import mujoco
import numpy as np

from mjx_arm.arm.info import ArmInfo, arm_info
from mjx_arm.arm.resolve import task_for_arm
from mjx_arm.task.touch import touch_config
from mjx_arm.urdf.convert import load_model
from mjx_arm.urdf.convert_config import EE_SITE
from pybullet_ref.contact import SOFT, Compliance, SceneContact, scene_contact

__all__ = ["arm_contact", "tool_mass"]


def tool_mass(arm: ArmInfo) -> float:
    """The effective mass (kg) of ``arm``'s tool along the vertical at its Touch home pose:
    ``1 / (e_z J M^-1 J^T e_z)`` with the ee point's Jacobian ``J`` ``(3, n)`` and MuJoCo's
    joint-space inertia ``M`` ``(n, n)``, armature included."""
    return _tool_mass_cached(arm.config, arm.urdf.stat().st_mtime)


@functools.cache
def _tool_mass_cached(config, mtime: float) -> float:
    del mtime  # part of the cache key only
    arm = arm_info(config)
    task = task_for_arm(touch_config(), arm, check=False)  # a measurement, not an env
    model = load_model(arm.urdf, arm.convert_config(sim_dt=task.sim_dt))
    data = mujoco.MjData(model)
    for name, q in zip(arm.joint_names, task.home_qpos, strict=True):
        data.qpos[model.joint(name).qposadr[0]] = q
    mujoco.mj_forward(model, data)
    mass = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, mass)
    jacobian = np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, jacobian, None, model.site(EE_SITE).id)
    vertical = jacobian[2]
    return float(1.0 / (vertical @ np.linalg.solve(mass, vertical)))


def arm_contact(value: SceneContact | str, arm: ArmInfo, object_scale: float = 0.0) -> SceneContact:
    """The scene contact for ``arm``: ``"soft"`` (or :data:`~pybullet_ref.contact.SOFT`) with
    its table and box spring and damper scaled by the arm's :func:`tool_mass` over the shipped
    arm's, and the cube's spring by ``1 / object_scale**2`` (the task's cube over the shipped
    one; 0 is the shipped size); any other value as given
    (:func:`~pybullet_ref.contact.scene_contact`)."""
    contact = scene_contact(value)
    if contact != SOFT or SOFT.fixed is None:
        return contact
    cube = SOFT.cube
    if cube is not None and 0.0 < object_scale < 1.0:
        cube = Compliance(cube.stiffness / object_scale**2, cube.damping)
    scale = tool_mass(arm) / tool_mass(arm_info())
    if not (np.isfinite(scale) and scale > 0.0):  # a degenerate pose: keep the calibration
        return SceneContact(SOFT.fixed, cube)
    fixed = Compliance(SOFT.fixed.stiffness * scale, SOFT.fixed.damping * scale)
    return SceneContact(fixed, cube)
