"""One-jaw grippers: the SO-101 (tests/data/example-robot-data, as example-robot-data publishes
it), a 5-joint arm whose moving jaw closes on a jaw that is part of its hand. The jaw is found
from the URDF, its pads are boxes fitted to the meshes (the fixed jaw cut off the hand's meshes)
and sit alike in MuJoCo, MJX and PyBullet, one command closes it, Touch and Reach hold it closed,
``--check`` says yes to every task, and a scripted pick lifts the (smaller) cube in both CPU
engines.
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from lift_script import run_scripted_lift

import mjx_arm  # noqa: F401  (registers the ids)
from mjx_arm.arm.config import ArmConfig, resolve_arm
from mjx_arm.arm.info import arm_info, tool_down_solver
from mjx_arm.arm.model_io import arm_model
from mjx_arm.arm.points import task_arm
from mjx_arm.arm.setup import arm_setup
from mjx_arm.arm.verdict import task_verdict
from mjx_arm.task.config import task_config
from mjx_arm.task.lift import LIFT_HEIGHT, cube_half, lift_config
from mjx_arm.urdf.grippers import find_layout
from mjx_arm.urdf.pad_fit import PAD_GEOM_SUFFIX
from mjx_arm.urdf.scene_shapes import box_top_offset

DATA = Path(__file__).parent / "data" / "example-robot-data" / "robots"
SO101 = DATA / "so_arm_description" / "urdf" / "so101.urdf"
ARM = ArmConfig(urdf=str(SO101), repair_inertia=True)  # its gripper_frame_link is massless
MOVING, HAND = "moving_jaw_so101_v1_link", "gripper_link"
POSE_TOL = 1e-5  # m: a pad box's centre in MuJoCo against PyBullet, same joint angles


def test_the_jaw_is_found_and_its_fixed_jaw_cut_off_the_hand() -> None:
    resolved = resolve_arm(ARM)
    layout = find_layout(resolved.model, set(resolved.joint_names))
    assert layout.kind == "jaw" and layout.driven == "gripper" and not layout.followers
    assert layout.pads == (MOVING, HAND)
    # closed is the limit that brings the moving jaw nearest the tool axis
    assert (layout.open_q, layout.closed_q) == pytest.approx((1.74533, -0.174533))
    # m: the widest gap where the pads face each other over half a cube's height (5.8 cm);
    # square to each other (within 10 degrees) they hold a 2.3 cm cube
    assert 0.055 < layout.opening < 0.062 and 0.0225 <= 2 * layout.held_half < 0.025
    fixed = layout.fitted.box(HAND)
    assert fixed is not None and layout.fitted.box(MOVING) is not None
    # the hand's two meshes are kept as hulls of what lies behind the cut: none of their
    # points reaches the fixed jaw (the hull of the whole hand sloped 1-2 cm into the grasp)
    approach = fixed.rotation[:, 1]
    jaw_start = float(fixed.centre @ approach - fixed.half[1])
    rests = [vertices for link, vertices in layout.fitted.rests if link == HAND]
    assert len(rests) == 2
    assert max(float((v @ approach).max()) for v in rests) < jaw_start + 0.005
    # the fixed jaw is the thin part that sticks out: 2.7 cm thick, 6.5 cm long, its face along
    # the tool axis
    assert fixed.half[0] < 0.015 and fixed.half[1] > 0.03
    np.testing.assert_allclose(approach, [0.0, 0.0, -1.0], atol=1e-6)


def test_the_arm_gets_the_jaw_a_smaller_cube_and_two_ee_points() -> None:
    arm = arm_info(ARM)
    gripper = arm.gripper
    assert gripper.kind == "jaw" and gripper.linkage and gripper.rests_closed
    assert arm.joint_names[-1] == "wrist_roll" and len(arm.joint_names) == 5
    # Reach and Touch press with the closed jaws' tips, 10.6 cm down the tool axis; Lift grips
    # 1.65 cm in front of the fixed jaw (the cube's half and 5 mm), 6 mm behind the tips (there
    # they stay 5 mm above the table with the cube resting on it)
    np.testing.assert_allclose(arm.ee_offset, [0.0, 0.0, -0.106], atol=0.002)
    np.testing.assert_allclose(arm.grip_offset, [0.0084, 0.0, -0.0981], atol=0.002)
    # the jaw's squeeze: 30 N at its 7.5 cm lever, not the URDF's 10 N m
    assert gripper.effort_cap == pytest.approx(2.25, abs=0.1)
    task = lift_config()
    ok, why = task_verdict(arm, task)
    assert ok, why
    setup = arm_setup(arm, task)
    # the cube the jaw holds square: 2.3 cm, half the shipped one's edge and mass
    assert 2 * cube_half(task.replace(object_scale=setup.object_scale)) == pytest.approx(
        2 * gripper.cube_half
    )
    assert setup.object_scale == pytest.approx(0.5, abs=0.01)


def test_touch_home_leaves_room_above_the_box() -> None:
    """The SO-101 holds its tool down no higher than about 7 cm over Touch's area; of the
    heights tried (0.2, 0.15, 0.10 m, then those times its 0.38 reach scale) the highest with a
    home is 5.7 cm, its tip 7 mm over the 5 cm box. The home is raised to the highest
    tool-down height instead: at least 1.5 cm of room above the box (PRESS_CLEARANCE)."""
    arm = arm_info(ARM)
    setup = arm_setup(arm, task_config("touch"))
    assert setup.home_source == "derived" and setup.covers_area
    tip = tool_down_solver(task_arm(arm, task_config("touch"))).ik.pose(
        np.asarray(setup.home_qpos)
    )[0][2]
    assert tip - box_top_offset() >= 0.015
    assert any("cm above the box, less than the 3 cm wanted" in note for note in setup.notes)


def test_mujoco_gets_the_fitted_pads_with_touch_sensors_around_them_alone() -> None:
    arm = arm_info(ARM)
    model = arm_model(arm, lift_config(object_scale=0.6))
    for link in (MOVING, HAND):
        body = model.body(link).id
        box = model.geom(f"{link}{PAD_GEOM_SUFFIX}")
        assert box.type[0] == mujoco.mjtGeom.mjGEOM_BOX and box.bodyid[0] == body
        site = model.site(f"{link}_pad")
        # the touch zone is the fitted box, 2 mm larger (not the hand's palm beside it)
        np.testing.assert_allclose(site.size, model.geom_size[box.id] + 0.002, atol=1e-9)
    collides = (model.geom_contype > 0) | (model.geom_conaffinity > 0)
    shapes = model.geom_type[(model.geom_bodyid == model.body(MOVING).id) & collides]
    assert list(shapes) == [mujoco.mjtGeom.mjGEOM_BOX]  # the moving jaw's mesh is its box now


def _bullet_box_centres(env) -> dict[str, np.ndarray]:
    """World centres of the PyBullet arm's box collision shapes, by link name."""
    c, body = env.client, env.body
    names = {c.getJointInfo(body, j)[12].decode(): j for j in range(c.getNumJoints(body))}
    out = {}
    for link in (MOVING, HAND):
        state = c.getLinkState(body, names[link], computeForwardKinematics=1)
        for shape in c.getCollisionShapeData(body, names[link]):
            if shape[2] == 3:  # GEOM_BOX, placed in the link's inertial frame
                position, _ = c.multiplyTransforms(state[0], state[1], shape[5], shape[6])
                out[link] = np.array(position)
    return out


def test_the_pads_sit_alike_in_mujoco_and_pybullet() -> None:
    from mjx_arm.envs.mujoco_env import MujocoArmEnv
    from pybullet_ref.env import PybulletArmEnv

    task = lift_config()
    envs = [MujocoArmEnv(task, ARM), PybulletArmEnv(task, ARM)]
    try:
        for env in envs:
            env.reset(seed=3)
        mujoco_env, bullet = envs
        np.testing.assert_allclose(
            mujoco_env.data.qpos[mujoco_env.ids.qpos_adr],
            [bullet.client.getJointState(bullet.body, j)[0] for j in bullet.ids.joints],
            atol=1e-9,
        )
        jaw = mujoco_env.data.qpos[mujoco_env.model.joint("gripper").qposadr[0]]
        bullet.client.resetJointState(bullet.body, bullet.ids.finger, float(jaw), 0.0)
        centres = _bullet_box_centres(bullet)
        for link in (MOVING, HAND):
            geom = mujoco_env.model.geom(f"{link}{PAD_GEOM_SUFFIX}").id
            np.testing.assert_allclose(
                centres[link], mujoco_env.data.geom_xpos[geom], atol=POSE_TOL
            )
    finally:
        for env in envs:
            env.close()


@pytest.mark.parametrize("name", ["reach", "touch"])
def test_reach_and_touch_hold_the_jaw_closed(name: str) -> None:
    arm = arm_info(ARM)
    model = arm_model(arm, task_config(name))
    jaw = model.joint("gripper")
    assert model.qpos0[jaw.qposadr[0]] == pytest.approx(arm.gripper.closed_q)


def test_check_says_yes_to_every_task_and_names_the_jaw(capsys) -> None:
    from mjx_arm.cli import main

    assert main(["arm", str(SO101), "--check", "--repair-inertia"]) == 0
    out = capsys.readouterr().out
    lines = {line.split()[0]: line for line in out.splitlines() if line.startswith("  ")}
    assert all(lines[name].split()[1] == "yes" for name in ("reach", "touch", "lift")), out
    assert "jaw: gripper turns moving_jaw_so101_v1_link" in out
    assert "cube of 2.3 cm" in out


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["mujoco", "pybullet"])
def test_scripted_pick_lifts_the_cube(engine: str) -> None:
    """Over the cube, the pads turned square to it, down, close, lift (tests/lift_script.py):
    the cube ends LIFT_HEIGHT up, held by the moving pad against the fixed one (2 seeds), and
    Lift's reward reads that grasp as one: the cube's centre is between the pads (``cradle``
    pays the closure) and no finger presses astray (``stray`` 0)."""
    env = gym.make("mjx_arm/Lift-v0", engine=engine, arm=ARM).unwrapped
    try:
        for seed in (0, 1):
            result = run_scripted_lift(env, seed, align=True, above=0.03)
            info = result["info"]
            assert result["success"], (engine, seed, info)
            assert info["height"] >= LIFT_HEIGHT and info["grasp"] == 1.0
            terms = info["reward_terms"]
            assert terms["cradle"] > 0.5 and terms["stray"] == 0.0, (engine, seed, terms)
    finally:
        env.close()


@pytest.mark.slow
def test_mjx_puts_the_pads_where_cpu_mujoco_does() -> None:
    """MJX (JAX on the CPU) places the fitted pad boxes and their touch sites of the Lift
    model where C MuJoCo does, at three jaw angles from open to past closed (1e-6 m)."""
    import jax
    from mujoco import mjx

    arm = arm_info(ARM)
    model = arm_model(arm, lift_config(object_scale=0.5))
    mx, data = mjx.put_model(model), mujoco.MjData(model)
    kinematics = jax.jit(mjx.kinematics)
    jaw = model.joint("gripper").qposadr[0]
    for q in (1.5, 0.6, -0.1):  # rad
        data.qpos[:5] = [0.2, -0.3, 0.4, 1.2, 0.5]
        data.qpos[jaw] = q
        mujoco.mj_kinematics(model, data)
        dx = kinematics(mx, mjx.put_data(model, data))
        for link in (MOVING, HAND):
            geom = model.geom(f"{link}{PAD_GEOM_SUFFIX}").id
            site = model.site(f"{link}_pad").id
            np.testing.assert_allclose(dx.geom_xpos[geom], data.geom_xpos[geom], atol=1e-6)
            np.testing.assert_allclose(dx.site_xpos[site], data.site_xpos[site], atol=1e-6)
