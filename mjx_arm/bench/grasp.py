"""Grasp parity: the same scripted pick of a cube off the table in every engine, and how far the
cube slips in the fingers while it is held.

Two starts (:data:`STARTS`), each with the fingers 1 mm short of a 4.5 cm, 0.1 kg cube on each
side (the lift scene's cube; the gripper arm ``assets/ur5e_gripper.urdf``):

- ``table``: the cube rests on the table under the home ee point; the arm starts in the pose that
  puts the ee (between the pads) :data:`GRIP_ABOVE` above the cube's centre, tool down: the
  pick a Lift task asks for;
- ``air``: the arm at its home pose, the cube floating between the pads (gravity on): the
  fingers alone, away from the table.

The script, one command per control step:

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
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from mjx_arm.arm.info import ArmInfo, arm_info
from mjx_arm.engines import engine as engine_row
from mjx_arm.engines import engine_names, load
from mjx_arm.paths import asset
from mjx_arm.task.grip import ObjectStart
from mjx_arm.task.lift import LIFT_SIM_DT, SERVO_DT
from mjx_arm.urdf.convert import build_spec
from mjx_arm.urdf.scene_shapes import CUBE_BODY, CUBE_HALF, CUBE_MASS

NEAR_CLOSED = 0.019  # finger position (m): 1 mm short of the cube on each side
GRIP_ABOVE = 0.005  # m: the ee above the cube's centre (the finger tips 2.5 mm above the table)
STARTS = ("table", "air")
FINGER, MIMIC = "left_finger_joint", "right_finger_joint"
PHASES = (("close", 1.0), ("lift", 1.0), ("hold", 2.0))  # name, seconds
LIFT_SPEED = 0.1  # m/s of the ee during the lift
SLIP_GOAL = 0.005  # m over the hold
# The Lift task's physics step and servo step, and the control period (s). At the other tasks'
# 1/240 s a cube picked off the table slips out in C MuJoCo and MJX (bench_grasp_step.py).
SIM_DT, SERVO_DT, CTRL_DT = LIFT_SIM_DT, SERVO_DT, 1.0 / 30.0


@dataclass(frozen=True)
class Cube:
    """The cube: half edge (m), mass (kg) and sliding friction (MuJoCo's geom friction; PyBullet's
    lateral friction)."""

    half: float = CUBE_HALF
    mass: float = CUBE_MASS
    friction: float = 1.0


@dataclass(frozen=True)
class Script:
    """The start and the commands of every control step.

    Attributes:
        start_qpos: the arm's joint angles at the start (rad), ``(n,)``.
        cube_pos: the cube's centre at the start (m), ``(3,)``.
        qdot: arm joint velocities (rad/s), ``(T, n)``.
        finger_speed: the driven finger's velocity command (m/s).
        hold_start: the step index where the hold starts.
    """

    start_qpos: np.ndarray
    cube_pos: np.ndarray
    qdot: np.ndarray
    finger_speed: float
    hold_start: int


def gripper_arm() -> ArmInfo:
    """The shipped arm with the gripper."""
    return arm_info(asset("ur5e_gripper.urdf"))


def grasp_model(arm: ArmInfo, sim_dt: float = SIM_DT, cube: Cube = Cube()) -> mujoco.MjModel:
    """The gripper arm in the lift scene (table and free cube; gravity on), stepping ``sim_dt``
    (a whole fraction of :data:`CTRL_DT`). The servos keep the gains converted for
    :data:`SERVO_DT` (as the Lift task's model), so the finger presses the same at every step."""
    config = arm.convert_config(
        scene="lift", self_collision=False, sim_dt=sim_dt, servo_dt=SERVO_DT
    )
    spec = build_spec(arm.urdf, config)
    (geom,) = spec.body(CUBE_BODY).geoms
    geom.size, geom.mass = [cube.half] * 3, cube.mass
    geom.friction = [cube.friction, *geom.friction[1:]]
    return spec.compile()


def substeps(model: mujoco.MjModel) -> int:
    """Physics steps per control step."""
    return round(CTRL_DT / model.opt.timestep)


def cube_of(model: mujoco.MjModel) -> Cube:
    """The model's cube."""
    geom = model.geom(CUBE_BODY)
    return Cube(float(geom.size[0]), float(model.body(CUBE_BODY).mass[0]), float(geom.friction[0]))


def _posed(model: mujoco.MjModel, arm: ArmInfo, qpos) -> mujoco.MjData:
    """Data with the arm's joints at ``qpos`` ``(n,)`` and the kinematics the ee Jacobian
    reads (positions and subtree centres) computed; everything else at its default."""
    data = mujoco.MjData(model)
    data.qpos[[model.joint(n).qposadr[0] for n in arm.joint_names]] = qpos
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    return data


def _ee_jacobian(model: mujoco.MjModel, data: mujoco.MjData, arm: ArmInfo) -> np.ndarray:
    """The ee site's Jacobian over the arm joints, ``(6, n)``: linear rows, then angular."""
    jacp, jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, jacp, jacr, model.site("ee").id)
    dofs = [model.joint(n).dofadr[0] for n in arm.joint_names]
    return np.vstack([jacp[:, dofs], jacr[:, dofs]])


def pick_pose(model: mujoco.MjModel, arm: ArmInfo, steps: int = 200) -> tuple[np.ndarray, ...]:
    """The start: the cube on the table under the home ee point, and the arm's joint angles
    ``(n,)`` that put the ee :data:`GRIP_ABOVE` above its centre with the home orientation
    (damped least-squares steps on the ee Jacobian). Returns ``(qpos, cube_pos)``."""
    qpos, home_ee = start_pose(model, arm, "air")
    cube = np.array([*home_ee[:2], cube_of(model).half])
    goal = cube + np.array([0.0, 0.0, GRIP_ABOVE])
    for _ in range(steps):
        data = _posed(model, arm, qpos)
        jac = _ee_jacobian(model, data, arm)
        error = np.concatenate([goal - data.site_xpos[model.site("ee").id], np.zeros(3)])
        qpos = qpos + jac.T @ np.linalg.solve(jac @ jac.T + 1e-6 * np.eye(6), error)
    return qpos, cube


def start_data(model: mujoco.MjModel, arm: ArmInfo, script: Script) -> mujoco.MjData:
    """The script's start pose, fingers near closed on the cube, everything at rest."""
    data = mujoco.MjData(model)
    data.qpos[[model.joint(n).qposadr[0] for n in arm.joint_names]] = script.start_qpos
    for name in (FINGER, MIMIC):
        data.qpos[model.joint(name).qposadr[0]] = NEAR_CLOSED
    cube = model.joint(CUBE_BODY).qposadr[0]
    data.qpos[cube : cube + 7] = [*script.cube_pos, 1.0, 0.0, 0.0, 0.0]
    mujoco.mj_forward(model, data)
    return data


def start_pose(model: mujoco.MjModel, arm: ArmInfo, start: str) -> tuple[np.ndarray, ...]:
    """``(arm qpos (n,), cube centre (3,))`` of ``start`` (one of :data:`STARTS`)."""
    if start == "table":
        return pick_pose(model, arm)
    if start != "air":
        raise ValueError(f"unknown grasp start {start!r}; choose one of {STARTS}")
    data = _posed(model, arm, arm.home_qpos)
    return np.asarray(arm.home_qpos, float), data.site_xpos[model.site("ee").id].copy()


def record_script(model: mujoco.MjModel, arm: ArmInfo, start: str = "table") -> Script:
    """The start pose and the joint velocities of every phase, from the ee Jacobian there."""
    qpos, cube = start_pose(model, arm, start)
    linear = _ee_jacobian(model, _posed(model, arm, qpos), arm)[:3]
    lift = np.linalg.lstsq(linear, [0.0, 0.0, LIFT_SPEED], rcond=None)[0]
    steps = {name: round(seconds / CTRL_DT) for name, seconds in PHASES}
    qdot = np.concatenate(
        [
            np.zeros((steps["close"], arm.n_joints)),
            np.tile(lift, (steps["lift"], 1)),
            np.zeros((steps["hold"], arm.n_joints)),
        ]
    )
    speed = finger_speed(model)
    return Script(qpos, cube, qdot, speed, steps["close"] + steps["lift"])


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


Frames = list | None  # RGB frames of the scene camera, one per control step, when a list


def _ids(model: mujoco.MjModel, arm: ArmInfo) -> tuple[list[int], int, int, int]:
    """The arm's actuators, the driven finger's actuator, the cube body and the ee site."""
    acts = [model.actuator(n).id for n in arm.joint_names]
    return acts, model.actuator(FINGER).id, model.body(CUBE_BODY).id, model.site("ee").id


def run_mujoco(
    model: mujoco.MjModel, arm: ArmInfo, script: Script, frames: Frames = None
) -> dict[str, Any]:
    """The script in C MuJoCo."""
    data = start_data(model, arm, script)
    acts, finger, cube, ee = _ids(model, arm)
    cubes, ees = [], []
    film = _Film(model, frames)
    for qdot in script.qdot:
        data.ctrl[acts] = qdot
        data.ctrl[finger] = script.finger_speed
        mujoco.mj_step(model, data, nstep=substeps(model))
        cubes.append(data.xpos[cube].copy())
        ees.append(data.site_xpos[ee].copy())
        film.add(data)
    opening = 0.085 - 2 * float(data.qpos[model.joint(FINGER).qposadr[0]])
    return summarize(np.array(cubes), np.array(ees), opening, script.hold_start)


def run_mjx(
    model: mujoco.MjModel, arm: ArmInfo, script: Script, frames: Frames = None
) -> dict[str, Any]:
    """The script in MJX (its JAX implementation, float32)."""
    import jax
    import jax.numpy as jnp
    from mujoco import mjx

    mx = mjx.put_model(model)
    data = mjx.put_data(model, start_data(model, arm, script))
    acts, finger, cube, ee = _ids(model, arm)
    acts = jnp.array(acts)

    def control_step(d, qdot):
        ctrl = d.ctrl.at[acts].set(qdot).at[finger].set(script.finger_speed)
        d = d.replace(ctrl=ctrl)
        d = jax.lax.fori_loop(0, substeps(model), lambda _, x: mjx.step(mx, x), d)
        return d, (d.xpos[cube], d.site_xpos[ee], d.qpos)

    scan = jax.jit(lambda d: jax.lax.scan(control_step, d, script.qdot))
    final, (cubes, ees, qposes) = scan(data)
    if frames is not None:  # film the recorded states
        film, shown = _Film(model, frames), mujoco.MjData(model)
        for qpos in np.asarray(qposes):
            shown.qpos[:] = qpos
            mujoco.mj_kinematics(model, shown)
            film.add(shown)
    opening = 0.085 - 2 * float(final.qpos[model.joint(FINGER).qposadr[0]])
    return summarize(np.asarray(cubes), np.asarray(ees), opening, script.hold_start)


def run_pybullet(
    model: mujoco.MjModel, arm: ArmInfo, script: Script, frames: Frames = None
) -> dict[str, Any]:
    """The script in PyBullet, through the Lift env's servo, world and cube; the driven finger
    is the env's velocity motor, capped at the MuJoCo finger servo's press."""
    from mjx_arm.task.lift import lift_config
    from pybullet_ref.env import PybulletArmEnv

    task = lift_config(sim_dt=float(model.opt.timestep))
    env = PybulletArmEnv(task, arm.config, width=FILM_SIZE[0], height=FILM_SIZE[1])
    try:
        spec = cube_of(model)
        upright = np.array([1.0, 0.0, 0.0, 0.0])
        obj = ObjectStart(upright, spec.mass, spec.friction)
        env._physics_reset(script.start_qpos, script.cube_pos, obj)
        client, body = env.client, env.body
        for name in (FINGER, MIMIC):
            client.resetJointState(body, _joint_index(client, body, name), NEAR_CLOSED)
        if spec.half != CUBE_HALF:  # another size: the env's cube is replaced
            client.removeBody(env.cube)
            env.cube = env._add_cube(list(script.cube_pos), obj, spec.half)
        env._physics_set_gripper(script.finger_speed)
        cubes, ees = [], []
        for qdot in script.qdot:
            env._physics_set_velocity_targets(qdot)
            env._physics_step(substeps(model))
            reading = env._physics_read()
            cubes.append(reading.target_pos)
            ees.append(reading.ee_pos)
            if frames is not None:
                frames.append(env._render_frame())
        opening = 0.085 - 2 * float(client.getJointState(body, env.ids.finger)[0])
    finally:
        env.close()
    return summarize(np.array(cubes), np.array(ees), opening, script.hold_start)


def _joint_index(client: Any, body: int, name: str) -> int:
    """PyBullet's index of joint ``name``."""
    names = [client.getJointInfo(body, j)[1].decode() for j in range(client.getNumJoints(body))]
    return names.index(name)


FILM_SIZE = (480, 360)  # width, height (pixels) of the videos


class _Film:
    """Frames of the MuJoCo scene camera, appended to ``frames`` (nothing when it is None)."""

    def __init__(self, model: mujoco.MjModel, frames: Frames) -> None:
        self.frames, self.renderer = frames, None
        if frames is not None:
            width, height = FILM_SIZE
            self.renderer = mujoco.Renderer(model, height, width)

    def add(self, data: mujoco.MjData) -> None:
        if self.renderer is not None:
            self.renderer.update_scene(data, camera="main")
            self.frames.append(self.renderer.render().copy())


def grasp_check(
    engines: tuple[str, ...] | None = None,
    log=print,
    video_dir: Path | None = None,
    starts: tuple[str, ...] = STARTS,
) -> dict[str, Any]:
    """The scripted pick from each of ``starts`` in each of ``engines`` (None: the Gymnasium
    env engines of :mod:`mjx_arm.engines` with a scripted pick, MuJoCo and PyBullet).

    Returns:
        Per start: the cube's start and, per engine, the lift (m), the slip over the hold (m),
        the final finger opening (m), whether the cube was held, the goal and (with
        ``video_dir``, ``table`` start) the path of its video ``grasp_ENGINE.mp4`` (one frame per
        control step, real time).
    """
    if engines is None:
        engines = tuple(n for n in engine_names("env") if n in engine_names("grasp"))
    arm = gripper_arm()
    model = grasp_model(arm)
    result: dict[str, Any] = {
        "cube": {"size_m": 2 * CUBE_HALF, "mass_kg": CUBE_MASS},
        "finger_press_n": finger_press(model, finger_speed(model)),
        "phases_s": dict(PHASES),
        "starts": {},
    }
    for start in starts:
        script = record_script(model, arm, start)
        rows = {}
        for name in engines:
            log(f"grasp from the {start}: {name}")
            films = video_dir is not None and start == "table"
            rows[name] = run_engine(name, model, arm, script, video_dir if films else None)
        result["starts"][start] = {"cube_start_m": script.cube_pos.tolist(), "engines": rows}
    return result


def finger_speed(model: mujoco.MjModel) -> float:
    """The driven finger's closing command (m/s): its URDF velocity limit."""
    return float(model.actuator(FINGER).ctrlrange[1])


def run_engine(name, model, arm, script, video_dir: Path | None = None) -> dict[str, Any]:
    """One engine's run of ``script``, its goal and, with ``video_dir``, its video."""
    from mjx_arm.replay import write_video

    frames = [] if video_dir is not None else None
    run = load(engine_row(name, "grasp").grasp)
    row = {**run(model, arm, script, frames), "slip_goal_m": SLIP_GOAL}
    row["met"] = row["held"] and row["slip_m"] <= SLIP_GOAL
    if frames:
        path = Path(video_dir) / f"grasp_{name}.mp4"
        write_video(path, frames, fps=1.0 / CTRL_DT)
        row["video"] = str(path)
    return row
