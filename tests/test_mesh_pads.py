"""A published linkage gripper whose finger collisions are meshes: pybullet_data's xArm6 with its
maker's gripper (``xarm/xarm6_with_gripper.urdf``, five ``<mimic>`` knuckles and fingers). Its
pads are boxes fitted to the finger meshes, the same in MuJoCo and PyBullet; ``--check`` says
yes to every task and each task's env builds; Touch presses with the closed fingers' tips; and
the scripted pick lifts the cube in both CPU engines.
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from lift_script import OpenHandPress, run_scripted_lift

import mjx_arm  # noqa: F401  (registers the ids)
from mjx_arm.arm.config import ArmConfig
from mjx_arm.arm.info import arm_info
from mjx_arm.arm.model_io import arm_model
from mjx_arm.arm.setup import arm_setup
from mjx_arm.arm.verdict import task_verdict
from mjx_arm.task.config import task_config
from mjx_arm.task.lift import GRASP_FORCE, LIFT_HEIGHT, lift_config
from mjx_arm.urdf.gripper_layout import TIP_CLEARANCE
from mjx_arm.urdf.pad_fit import PAD_GEOM_SUFFIX

pybullet_data = pytest.importorskip("pybullet_data")
XARM = Path(pybullet_data.getDataPath()) / "xarm" / "xarm6_with_gripper.urdf"
ARM = ArmConfig(urdf=str(XARM), repair_inertia=True)  # two link inertias break the inequality
PADS = ("left_finger", "right_finger")


def test_the_finger_meshes_become_fitted_boxes() -> None:
    arm = arm_info(ARM)
    gripper = arm.gripper
    assert gripper.kind == "linkage" and gripper.pad_links[:2] == PADS
    assert len(gripper.followers) == 5 and abs(gripper.opening - 0.087) < 0.002
    model = arm_model(arm, lift_config())
    collides = (model.geom_contype > 0) | (model.geom_conaffinity > 0)
    for pad in PADS:
        box = gripper.fitted.box(pad)
        assert box is not None and np.all(box.half > 0.005)  # m: a finger, not a sliver
        shapes = model.geom_type[(model.geom_bodyid == model.body(pad).id) & collides]
        assert list(shapes) == [mujoco.mjtGeom.mjGEOM_BOX]
        geom = model.geom(f"{pad}{PAD_GEOM_SUFFIX}")
        np.testing.assert_allclose(geom.size, box.half, atol=1e-9)
    # the pads' boxes face each other: their closing directions are opposite in the hand
    assert 0.02 < gripper.pad_width < 0.04  # m


@pytest.mark.parametrize("name", ["reach", "touch", "lift"])
def test_check_says_yes_and_the_env_builds_and_steps(name: str) -> None:
    arm = arm_info(ARM)
    task = task_config(name)
    ok, why = task_verdict(arm, task)
    assert ok, why
    env = gym.make(f"mjx_arm/{name.capitalize()}-v0", engine="mujoco", arm=ARM)
    try:
        env.reset(seed=0)
        _, reward, *_ = env.step(env.action_space.sample() * 0.1)
        assert np.isfinite(reward)
    finally:
        env.close()


def test_touch_presses_with_the_closed_fingers_tips() -> None:
    """With the gripper closed, the tool meets the box 17.7 cm down the tool axis: that is the
    ee point of Touch. Lift's ee point (the grip point) sits the held cube's half edge less
    5 mm behind it, so that a cube held at it leaves the tips 5 mm above the table (the pads'
    centre, 3.9 cm behind the tips, put them 1.6 cm into it)."""
    arm = arm_info(ARM)
    np.testing.assert_allclose(arm.ee_offset, [0.0, 0.0, 0.177], atol=0.003)
    tips_beyond = arm.ee_offset[2] - arm.grip_offset[2]
    assert tips_beyond == pytest.approx(arm.gripper.cube_half - TIP_CLEARANCE, abs=1e-5)
    setup = arm_setup(arm, task_config("touch"))
    assert abs(setup.contact_offset) < 0.005  # m: the box is met at the ee point


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["mujoco", "pybullet"])
def test_scripted_pick_lifts_the_cube(engine: str) -> None:
    """Over the cube, down, close, lift (tests/lift_script.py): the cube ends LIFT_HEIGHT up,
    held by both fitted pads (2 seeds), and the fingertips never strike the table on the way:
    the wrist reading stays inside the force band (the grip point at the pads' centre put
    the tips into the table: peaks of 59-64 N in MuJoCo, 34-37 N in PyBullet; now 8-23 N)."""
    env = gym.make("mjx_arm/Lift-v0", engine=engine, arm=ARM).unwrapped
    try:
        for seed in (0, 1):
            result = run_scripted_lift(env, seed)
            info = result["info"]
            assert result["success"], (engine, seed, info)
            assert info["height"] >= LIFT_HEIGHT and info["grasp"] == 1.0
            assert result["peak_force"] < env.task.force_band[1], (engine, seed, result)
    finally:
        env.close()


def test_an_open_hand_on_the_table_around_the_cube_is_no_grasp() -> None:
    """Pushed down around the cube with the gripper open, the hand rests with both pad boxes
    on the table, each pad reading a press, the cube's centre between them: without
    ``grasp_closure`` that read as a grasp (a Lift policy rested there and was paid 4 a step);
    the gripper is not closed far enough to hold the cube, so it is none."""
    env = gym.make("mjx_arm/Lift-v0", engine="mujoco", arm=ARM).unwrapped
    try:
        obs, _ = env.reset(seed=0, options={"object_quat": np.array([1.0, 0.0, 0.0, 0.0])})
        script = OpenHandPress(env, above=0.06)
        for _ in range(120):
            obs, _, done, _, info = env.step(script(obs))
            assert not done
        assert (obs["pad_force"] >= GRASP_FORCE).all(), obs["pad_force"]
        assert env.task.grasp_closure > 0.3 and obs["gripper"][0] < 0.05
        assert info["reward_terms"]["grasp"] == 0.0
    finally:
        env.close()


def test_the_fingers_collide_with_the_table() -> None:
    """The xArm6's URDF names its root link ``world`` (MuJoCo's world body, where the table and
    the box live), and at all-zero angles its fingers reach below the table top. No link may
    lose its contacts with the world body for that: at qpos0 MuJoCo makes pad-table contacts
    (it made none when the at-rest overlap excluded the fingers from the world, and trained
    policies pushed the fingers 15 mm through the table)."""
    model = arm_model(arm_info(ARM), lift_config())
    world_pairs = [s for s in model.exclude_signature if (s >> 16) == 0 or (s & 0xFFFF) == 0]
    assert world_pairs == []
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    table = model.geom("table_0").id
    pads = {model.geom(f"{pad}{PAD_GEOM_SUFFIX}").id for pad in PADS}
    touching = {
        g
        for c in data.contact[: data.ncon]
        for g in (c.geom1, c.geom2)
        if table in (c.geom1, c.geom2) and g in pads
    }
    assert touching == pads
