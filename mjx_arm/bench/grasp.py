"""Grasp parity: the same scripted close-and-lift of a cube in every engine, and how far the cube
slips in the fingers while it is held.

The gripper arm (``assets/ur5e_gripper.urdf``) starts at its home pose with the fingers 1 mm
short of a 4.5 cm, 0.1 kg cube on each side. The script, one command per control step:

1. close (1 s): the driven finger at its full speed, the arm still;
2. lift (1 s): the arm joints at the velocities that raise the ee 0.1 m/s (a least-squares
   solve at the start pose, recorded once in C MuJoCo and replayed everywhere), fingers closing;
3. hold (2 s): the arm still, the fingers still closing (pressing at the servo's cap).

Slip is how far the cube moves against the ee frame over the hold (the goal: 5 mm); the lift is
how far the cube rose from its start. C MuJoCo and MJX step the same converted model; PyBullet
loads the URDF, holds the mimic finger with a gear constraint and drives the arm with the
MuJoCo model's servo law (:mod:`pybullet_ref.env`); its driven finger is a velocity motor whose
force cap is the MuJoCo finger servo's press.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from mjx_arm.envs.arm import ArmInfo, arm_info
from mjx_arm.paths import asset
from mjx_arm.urdf.convert import build_spec
from mjx_arm.urdf.scene_shapes import SCENE_CONAFFINITY, SCENE_CONTYPE

CUBE_HALF, CUBE_MASS = 0.0225, 0.1  # m, kg
NEAR_CLOSED = 0.019  # finger position (m): 1 mm short of the cube on each side
FINGER, MIMIC = "left_finger_joint", "right_finger_joint"
PHASES = (("close", 1.0), ("lift", 1.0), ("hold", 2.0))  # name, seconds
LIFT_SPEED = 0.1  # m/s of the ee during the lift
SLIP_GOAL = 0.005  # m over the hold
SIM_DT, N_SUBSTEPS = 1.0 / 240.0, 8


@dataclass(frozen=True)
class Script:
    """The commands of every control step: arm joint velocities ``(T, n)`` (rad/s) and the
    finger velocity (m/s), with the step index where the hold starts."""

    qdot: np.ndarray
    finger_speed: float
    hold_start: int


def gripper_arm() -> ArmInfo:
    """The shipped arm with the gripper."""
    return arm_info(asset("ur5e_gripper.urdf"))


def grasp_model(arm: ArmInfo) -> mujoco.MjModel:
    """The gripper arm (no scene, gravity on) with a free cube between the open fingers."""
    spec = build_spec(arm.urdf, arm.convert_config(self_collision=False, sim_dt=SIM_DT))
    probe = spec.copy().compile()
    data = mujoco.MjData(probe)
    data.qpos[[probe.joint(n).qposadr[0] for n in arm.joint_names]] = arm.home_qpos
    mujoco.mj_kinematics(probe, data)
    cube = spec.worldbody.add_body()
    cube.name, cube.pos = "cube", data.site_xpos[probe.site("ee").id].copy()
    cube.add_freejoint()
    geom = cube.add_geom()
    geom.type, geom.size, geom.mass = mujoco.mjtGeom.mjGEOM_BOX, [CUBE_HALF] * 3, CUBE_MASS
    geom.contype, geom.conaffinity = SCENE_CONTYPE, SCENE_CONAFFINITY
    return spec.compile()


def start_data(model: mujoco.MjModel, arm: ArmInfo) -> mujoco.MjData:
    """Home pose, fingers near closed on the cube, everything at rest."""
    data = mujoco.MjData(model)
    data.qpos[[model.joint(n).qposadr[0] for n in arm.joint_names]] = arm.home_qpos
    for name in (FINGER, MIMIC):
        data.qpos[model.joint(name).qposadr[0]] = NEAR_CLOSED
    mujoco.mj_forward(model, data)
    return data


def record_script(model: mujoco.MjModel, arm: ArmInfo) -> Script:
    """The joint velocities of every phase, from the ee Jacobian at the start pose."""
    data = start_data(model, arm)
    jacp = np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, jacp, None, model.site("ee").id)
    dofs = [model.joint(n).dofadr[0] for n in arm.joint_names]
    lift = np.linalg.lstsq(jacp[:, dofs], [0.0, 0.0, LIFT_SPEED], rcond=None)[0]
    ctrl_dt = SIM_DT * N_SUBSTEPS
    steps = {name: round(seconds / ctrl_dt) for name, seconds in PHASES}
    qdot = np.concatenate(
        [
            np.zeros((steps["close"], arm.n_joints)),
            np.tile(lift, (steps["lift"], 1)),
            np.zeros((steps["hold"], arm.n_joints)),
        ]
    )
    speed = float(model.actuator(FINGER).ctrlrange[1])  # the URDF velocity limit
    return Script(qdot, speed, steps["close"] + steps["lift"])


def finger_press(model: mujoco.MjModel, speed: float) -> float:
    """The MuJoCo finger servo's press (N) when blocked: ``kv * speed``, at most its cap."""
    act = model.actuator(FINGER)
    return min(float(act.gainprm[0]) * speed, float(act.forcerange[1]))


def summarize(cube: np.ndarray, ee: np.ndarray, opening: float, hold_start: int) -> dict:
    """Figures of one run from the cube and ee positions after each control step ``(T, 3)``."""
    rel = cube - ee
    return {
        "lift_m": float(cube[-1, 2] - cube[0, 2]),
        "slip_m": float(np.linalg.norm(rel[-1] - rel[hold_start - 1])),
        "opening_m": opening,
        "held": bool(cube[-1, 2] - cube[0, 2] > 0.5 * LIFT_SPEED),
    }


def run_mujoco(model: mujoco.MjModel, arm: ArmInfo, script: Script) -> dict[str, Any]:
    """The script in C MuJoCo."""
    data = start_data(model, arm)
    acts = [model.actuator(n).id for n in arm.joint_names]
    finger = model.actuator(FINGER).id
    cube, ee = model.body("cube").id, model.site("ee").id
    cubes, ees = [], []
    for qdot in script.qdot:
        data.ctrl[acts] = qdot
        data.ctrl[finger] = script.finger_speed
        mujoco.mj_step(model, data, nstep=N_SUBSTEPS)
        cubes.append(data.xpos[cube].copy())
        ees.append(data.site_xpos[ee].copy())
    opening = 0.085 - 2 * float(data.qpos[model.joint(FINGER).qposadr[0]])
    return summarize(np.array(cubes), np.array(ees), opening, script.hold_start)


def run_mjx(model: mujoco.MjModel, arm: ArmInfo, script: Script) -> dict[str, Any]:
    """The script in MJX (its JAX implementation, float32)."""
    import jax
    import jax.numpy as jnp
    from mujoco import mjx

    mx = mjx.put_model(model)
    data = mjx.put_data(model, start_data(model, arm))
    acts = jnp.array([model.actuator(n).id for n in arm.joint_names])
    finger = model.actuator(FINGER).id
    cube, ee = model.body("cube").id, model.site("ee").id

    def control_step(d, qdot):
        ctrl = d.ctrl.at[acts].set(qdot).at[finger].set(script.finger_speed)
        d = d.replace(ctrl=ctrl)
        d = jax.lax.fori_loop(0, N_SUBSTEPS, lambda _, x: mjx.step(mx, x), d)
        return d, (d.xpos[cube], d.site_xpos[ee])

    final, (cubes, ees) = jax.jit(lambda d: jax.lax.scan(control_step, d, script.qdot))(data)
    opening = 0.085 - 2 * float(final.qpos[model.joint(FINGER).qposadr[0]])
    return summarize(np.asarray(cubes), np.asarray(ees), opening, script.hold_start)


def run_pybullet(model: mujoco.MjModel, arm: ArmInfo, script: Script) -> dict[str, Any]:
    """The script in PyBullet, through the reference env's servo and world."""
    from mjx_arm.task import reach_config
    from pybullet_ref.env import PybulletArmEnv, pybullet

    env = PybulletArmEnv(reach_config(sim_dt=SIM_DT), arm.config)
    try:
        env._physics_reset(arm.home_qpos, np.array([5.0, 0.0, 0.0]))  # the marker far away
        client, body = env.client, env.body
        joint = {
            client.getJointInfo(body, j)[1].decode(): j for j in range(client.getNumJoints(body))
        }
        for name in (FINGER, MIMIC):
            client.resetJointState(body, joint[name], NEAR_CLOSED)
        start = env._physics_read().ee_pos
        shape = client.createCollisionShape(pybullet.GEOM_BOX, halfExtents=[CUBE_HALF] * 3)
        cube = client.createMultiBody(CUBE_MASS, shape, basePosition=list(start))
        client.changeDynamics(cube, -1, lateralFriction=1.0)
        press = finger_press(model, script.finger_speed)
        client.setJointMotorControl2(
            body, joint[FINGER], pybullet.VELOCITY_CONTROL,
            targetVelocity=script.finger_speed, force=press,
        )  # fmt: skip
        cubes, ees = [], []
        for qdot in script.qdot:
            env._physics_set_velocity_targets(qdot)
            env._physics_step(N_SUBSTEPS)
            cubes.append(np.array(client.getBasePositionAndOrientation(cube)[0]))
            ees.append(env._physics_read().ee_pos)
        opening = 0.085 - 2 * float(client.getJointState(body, joint[FINGER])[0])
    finally:
        env.close()
    return summarize(np.array(cubes), np.array(ees), opening, script.hold_start)


RUNNERS = {"mujoco": run_mujoco, "pybullet": run_pybullet, "mjx": run_mjx}


def grasp_check(engines: tuple[str, ...] = ("mujoco", "pybullet"), log=print) -> dict[str, Any]:
    """The scripted close-and-lift in each of ``engines``; per engine: lift (m), slip over the
    hold (m), final finger opening (m), whether the cube was held, and the goal."""
    arm = gripper_arm()
    model = grasp_model(arm)
    script = record_script(model, arm)
    rows = {}
    for name in engines:
        log(f"grasp: {name}")
        rows[name] = {**RUNNERS[name](model, arm, script), "slip_goal_m": SLIP_GOAL}
        rows[name]["met"] = rows[name]["held"] and rows[name]["slip_m"] <= SLIP_GOAL
    return {
        "cube": {"size_m": 2 * CUBE_HALF, "mass_kg": CUBE_MASS},
        "finger_press_n": finger_press(model, script.finger_speed),
        "phases_s": dict(PHASES),
        "engines": rows,
    }
