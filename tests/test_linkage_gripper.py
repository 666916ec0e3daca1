"""Linkage grippers (assets/ur5e_2f85.urdf, four-bar knuckles of the 2F-85 kind;
assets/ur5e_xarm_gripper.urdf, revolute fingers of the xArm gripper kind): found from the URDF,
driven by one command in CPU MuJoCo, MJX and PyBullet with every ``<mimic>`` joint following,
the pads where the URDF's kinematics put them, and the Lift pick holding the cube.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from lift_script import run_scripted_lift

from mjx_arm.arm.config import ArmConfig, resolve_arm
from mjx_arm.arm.info import arm_info
from mjx_arm.arm.model_io import arm_model
from mjx_arm.envs.mujoco_env import MujocoArmEnv
from mjx_arm.paths import asset
from mjx_arm.task.lift import LIFT_HEIGHT, lift_config
from mjx_arm.task.touch import touch_config
from mjx_arm.urdf.grippers import find_layout, pad_gap
from mjx_arm.urdf.validate import validate

ARMS = {"2f85": asset("ur5e_2f85.urdf"), "xarm": asset("ur5e_xarm_gripper.urdf")}
# published strokes (m): the 2F-85's 85 mm, the xArm gripper's 86 mm
STROKES = {"2f85": 0.085, "xarm": 0.086}
GAP_TOL = 1e-3  # m: the pad gap an engine reaches against the URDF's kinematics
FOLLOW_TOL = 2e-3  # rad: a <mimic> joint against multiplier * driven + offset, settled
PRESSED_TOL = 0.015  # rad: the same in PyBullet with the closed pads pressing each other


def _layout(name: str):
    resolved = resolve_arm(ArmConfig(urdf=str(ARMS[name])))
    return resolved.model, find_layout(resolved.model, set(resolved.joint_names))


@pytest.mark.parametrize("name", list(ARMS))
def test_the_linkage_is_found_with_its_published_stroke(name: str) -> None:
    assert validate(ARMS[name], engine="all").ok
    model, layout = _layout(name)
    assert layout.kind == "linkage" and len(layout.followers) == 5
    assert abs(layout.opening - STROKES[name]) < 1e-3  # m
    assert pad_gap(model, layout, layout.closed_q) == pytest.approx(0.0, abs=1e-12)
    assert 0.018 <= layout.pad_width <= 0.024  # m
    gripper = arm_info(ARMS[name]).gripper
    assert gripper.linkage and gripper.opening == pytest.approx(layout.opening)
    assert {f.multiplier for f in gripper.followers} <= {-1.0, 1.0}


def test_the_parallel_gripper_is_found_as_before() -> None:
    gripper = arm_info(asset("ur5e_gripper.urdf")).gripper
    assert not gripper.linkage and gripper.opening == pytest.approx(0.085, abs=1e-12)
    assert (gripper.joint, gripper.open_q, gripper.closed_q) == ("left_finger_joint", 0.0, 0.0425)
    assert gripper.pad_links == ("left_finger", "right_finger")


def _mujoco_closes(model, gripper, command: float, steps: int = 720) -> mujoco.MjData:
    data = mujoco.MjData(model)
    for name, q in gripper.positions(gripper.open_q).items():
        data.qpos[model.joint(name).qposadr[0]] = q
    for _ in range(steps):
        data.ctrl[model.actuator(gripper.joint).id] = command
        mujoco.mj_step(model, data)
    return data


@pytest.mark.parametrize("name", list(ARMS))
def test_one_command_closes_every_joint_in_mujoco(name: str) -> None:
    arm = arm_info(ARMS[name])
    gripper, (_, layout) = arm.gripper, _layout(name)
    model = arm_model(arm, lift_config())
    data = _mujoco_closes(model, gripper, gripper.v_max * gripper.closing_sign)
    q = float(data.qpos[model.joint(gripper.joint).qposadr[0]])
    assert abs(q - gripper.closed_q) < 0.01  # rad: at its limit
    for name_, want in gripper.positions(q).items():
        assert abs(data.qpos[model.joint(name_).qposadr[0]] - want) < FOLLOW_TOL, name_
    pads = [data.xpos[model.body(p).id] for p in gripper.pad_links[:2]]
    closed = np.linalg.norm(pads[0] - pads[1])
    data = _mujoco_closes(model, gripper, -gripper.v_max * gripper.closing_sign)
    pads = [data.xpos[model.body(p).id] for p in gripper.pad_links[:2]]
    opened = np.linalg.norm(pads[0] - pads[1]) - closed
    assert abs(opened - layout.opening) < GAP_TOL


@pytest.mark.parametrize("name", list(ARMS))
def test_touch_and_reach_models_start_with_the_linkage_closed(name: str) -> None:
    arm = arm_info(ARMS[name])
    model = arm_model(arm, touch_config())
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    pads = [data.xpos[model.body(p).id] for p in arm.gripper.pad_links[:2]]
    model_urdf, layout = _layout(name)
    gap = pad_gap(model_urdf, layout, layout.open_q)
    open_frames = np.linalg.norm(pads[0] - pads[1])
    # closed: the pad frames stand ``opening`` nearer than open
    assert open_frames < gap  # m: the frames' distance closed is below the open gap
    for joint, q in arm.gripper.positions(arm.gripper.closed_q).items():
        assert data.qpos[model.joint(joint).qposadr[0]] == pytest.approx(q)


def _env(engine: str, name: str):
    if engine == "mujoco":
        return MujocoArmEnv(lift_config(), ARMS[name])
    from pybullet_ref.env import PybulletArmEnv

    return PybulletArmEnv(lift_config(), ARMS[name])


@pytest.mark.parametrize("engine", ["mujoco", "pybullet"])
@pytest.mark.parametrize("name", list(ARMS))
def test_scripted_pick_lifts_the_cube(engine: str, name: str) -> None:
    """Over the cube, down, close, lift (tests/lift_script.py): the cube ends LIFT_HEIGHT up,
    held by both pads."""
    env = _env(engine, name)
    try:
        result = run_scripted_lift(env, 0)
        info = result["info"]
        assert result["success"], (engine, name, info)
        assert info["height"] >= LIFT_HEIGHT and info["grasp"] == 1.0
    finally:
        env.close()


@pytest.mark.parametrize("name", list(ARMS))
def test_one_command_closes_every_joint_in_pybullet(name: str) -> None:
    """Gear constraints hold the followers; the pads close by the URDF's opening."""
    env = _env("pybullet", name)
    gripper, (_, layout) = env.arm.gripper, _layout(name)
    try:
        env.reset(seed=0)
        c, body = env.client, env.body
        joint = {c.getJointInfo(body, j)[1].decode(): j for j in range(c.getNumJoints(body))}
        pads = env.ids.pads

        def gap() -> float:
            a, b = (np.array(c.getLinkState(body, p)[4]) for p in pads)
            return float(np.linalg.norm(a - b))

        def error() -> float:
            q = c.getJointState(body, joint[gripper.joint])[0]
            want = gripper.positions(q)
            return max(abs(c.getJointState(body, joint[n])[0] - v) for n, v in want.items())

        opened = gap()
        action = np.zeros(env.arm.n_joints + 1, np.float32)
        action[-1] = 1.0
        for _ in range(5):
            env.step(action)
        assert error() < FOLLOW_TOL  # moving: measured 1e-5 rad
        for _ in range(35):
            env.step(action)
        q = c.getJointState(body, joint[gripper.joint])[0]
        assert abs(q - gripper.closed_q) < 0.01  # rad
        # closed, the pads press on each other and the gear constraints give: 0.011 rad
        assert error() < PRESSED_TOL
        assert abs(opened - gap() - layout.opening) < GAP_TOL
    finally:
        env.close()


@pytest.mark.slow
def test_mjx_closes_the_linkage_as_cpu_mujoco() -> None:
    """MJX (JAX on the CPU) steps the 2F-85 arm's model with one command: the followers track
    (closed on its limit with the pads pressing each other: 0.0064 rad measured) and the pads
    end where CPU MuJoCo puts them."""
    import jax
    from mujoco import mjx

    arm = arm_info(ARMS["2f85"])
    gripper = arm.gripper
    model = arm_model(arm, lift_config())
    command = gripper.v_max * gripper.closing_sign
    cpu = _mujoco_closes(model, gripper, command, steps=240)
    start = mujoco.MjData(model)
    for name, q in gripper.positions(gripper.open_q).items():
        start.qpos[model.joint(name).qposadr[0]] = q
    start.ctrl[model.actuator(gripper.joint).id] = command
    mx, dx = mjx.put_model(model), mjx.put_data(model, start)
    dx = jax.jit(lambda d: jax.lax.fori_loop(0, 240, lambda _, d: mjx.step(mx, d), d))(dx)
    qpos = np.asarray(dx.qpos)
    for name, want in gripper.positions(qpos[model.joint(gripper.joint).qposadr[0]]).items():
        assert abs(qpos[model.joint(name).qposadr[0]] - want) < PRESSED_TOL, name
    xpos = np.asarray(dx.xpos)
    for pad in gripper.pad_links[:2]:
        body = model.body(pad).id
        np.testing.assert_allclose(xpos[body], cpu.xpos[body], atol=GAP_TOL)


@pytest.mark.parametrize("engine", ["mujoco", "pybullet"])
def test_touch_runs_with_the_linkage_closed(engine: str) -> None:
    """Touch on the 2F-85 arm: the gripper starts closed in both engines and stays closed
    while the arm moves (the pads' frames at their closed distance, within GAP_TOL)."""
    arm = arm_info(ARMS["2f85"])
    model_urdf, layout = _layout("2f85")
    closed = pad_gap(model_urdf, layout, layout.open_q)  # open minus closed
    if engine == "mujoco":
        env = MujocoArmEnv(touch_config(), ARMS["2f85"])
    else:
        from pybullet_ref.env import PybulletArmEnv

        env = PybulletArmEnv(touch_config(), ARMS["2f85"])
    try:
        env.reset(seed=0)
        rng = np.random.default_rng(0)
        for _ in range(30):
            _, reward, *_ = env.step(rng.uniform(-0.3, 0.3, arm.n_joints).astype(np.float32))
            assert np.isfinite(reward)
        if engine == "mujoco":
            pads = [env.data.xpos[env.model.body(p).id] for p in arm.gripper.pad_links[:2]]
        else:
            c, body = env.client, env.body
            link = {c.getJointInfo(body, j)[12].decode(): j for j in range(c.getNumJoints(body))}
            pads = [np.array(c.getLinkState(body, link[p])[4]) for p in arm.gripper.pad_links[:2]]
        frames_open = np.linalg.norm(pads[0] - pads[1]) + closed
        opened = _open_frame_distance(model_urdf, layout)
        assert abs(frames_open - opened) < GAP_TOL
    finally:
        env.close()


def _open_frame_distance(model, layout) -> float:
    """The pads' frame distance (m) with the gripper open, from the URDF's kinematics."""
    from mjx_arm.urdf.kinematics import link_frames

    positions = {j.name: 0.0 for j in model.actuated_joints if j.mimic is None}
    positions.update(layout.positions(layout.open_q))
    frames = link_frames(model, positions)
    a, b = layout.pads[:2]
    return float(np.linalg.norm(frames[a][:3, 3] - frames[b][:3, 3]))
