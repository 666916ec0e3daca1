"""The task setup an arm derives from its model: tool-down IK, the home pose over the task area,
the episode from the joint speeds, the ee point at the tool, the servo gain, the joint
encoding, and ``mjx-arm arm --check``.

Published arms come from the example-robot-data package (a test dependency).
"""

from __future__ import annotations

import math
import sysconfig
import xml.etree.ElementTree as ET
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import mjx_arm  # noqa: F401  (registers the ids)
from mjx_arm.arm.config import SHIPPED_HOME_QPOS, ArmConfig, load_arm, resolve_arm
from mjx_arm.arm.info import arm_info, press_kv_factor, tool_down_solver
from mjx_arm.arm.setup import arm_setup, grid_targets
from mjx_arm.arm.verdict import task_verdict
from mjx_arm.cli import main
from mjx_arm.paths import default_arm_urdf
from mjx_arm.task import observation as obs_lib
from mjx_arm.task.config import TaskConfig, task_config
from mjx_arm.urdf.convert import EE_SITE

ROBOTS = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
UR10 = ROBOTS / "ur_description/urdf/ur10_robot.urdf"
KINOVA = ROBOTS / "kinova_description/robots/kinova.urdf"
Z1 = ROBOTS / "z1_description/urdf/z1.urdf"
SO100 = ROBOTS / "so_arm_description/urdf/so100.urdf"
PANDA = ROBOTS / "panda_description/urdf/panda.urdf"
UR3 = ROBOTS / "ur_description/urdf/ur3_robot.urdf"

published = pytest.mark.skipif(not UR10.is_file(), reason="example-robot-data not installed")

# The IK's tolerances (mjx_arm.arm.ik): 1 mm and 1 degree.
POS_TOL, TILT_TOL = 1e-3, math.radians(1.0)


# --------------------------------------------------------------------------- tool-down IK


def test_ik_finds_the_shipped_home_pose_from_the_middle_of_the_limits() -> None:
    arm = arm_info()
    solver = tool_down_solver(arm)
    target, axis = solver.ik.pose(np.asarray(SHIPPED_HOME_QPOS))
    assert axis @ [0.0, 0.0, -1.0] > math.cos(TILT_TOL)  # the shipped home holds the tool down
    result = solver.ik.solve(target, solver.middle)
    assert result.converged and result.position_error < POS_TOL and result.tilt < TILT_TOL
    assert np.all(result.q >= solver.lower) and np.all(result.q <= solver.upper)


def test_position_only_ik_ignores_the_tilt() -> None:
    solver = tool_down_solver(arm_info())
    target = np.array([0.45, 0.2, 0.45])
    result = solver.ik.solve(target, solver.middle, tool_down=False)
    assert result.converged and result.position_error < POS_TOL


def test_shipped_arms_keep_their_measured_setup() -> None:
    """The shipped arms' homes, scale and episode are what their figures were measured with."""
    arm = arm_info()
    for name in ("reach", "touch"):
        setup = arm_setup(arm, task_config(name))
        assert setup.home_qpos == SHIPPED_HOME_QPOS and setup.home_source == "shipped arm"
        assert setup.workspace_scale == 1.0 and setup.episode_steps == 150
        assert setup.covers_area
    assert arm.kv_factor == 1.0 and not np.any(arm.ee_offset)


# --------------------------------------------------------------------------- a published arm


@published
def test_ur10_home_holds_the_tool_down_over_the_middle_of_the_area() -> None:
    arm = arm_info(ArmConfig(urdf=str(UR10)))
    task = task_config("touch")
    setup = arm_setup(arm, task)
    assert setup.home_source == "derived" and setup.covers_area
    assert setup.workspace_scale == pytest.approx(arm.reach_scale)
    solver = tool_down_solver(arm)
    home = np.asarray(setup.home_qpos)
    ee, axis = solver.ik.pose(home)
    points = grid_targets(task.replace(workspace_scale=setup.workspace_scale))
    middle = 0.5 * (points[:, :2].min(axis=0) + points[:, :2].max(axis=0))
    np.testing.assert_allclose(ee, [*middle, 0.20], atol=POS_TOL)  # 0.2 m above the table
    assert np.arccos(axis @ [0.0, 0.0, -1.0]) < TILT_TOL
    assert np.all(home >= solver.lower) and np.all(home <= solver.upper)  # the margin kept
    assert not solver.collides(home)
    assert setup.episode_steps == 150  # the UR10 is fast enough for Touch's 5 s


@published
def test_arm_file_home_is_kept_and_checked() -> None:
    home = (0.0, -1.3291, 2.1732, -2.4149, -1.5708, 0.0)  # benchmarks/arms/ur10.toml
    arm = arm_info(ArmConfig(urdf=str(UR10), home_qpos=home))
    setup = arm_setup(arm, task_config("touch"))
    assert setup.home_qpos == home and setup.home_source == "arm file" and setup.covers_area


@published
def test_a_small_arm_homes_lower_where_that_keeps_its_moves_inside_the_episode() -> None:
    """The UR3's tool-down home 0.2 m up sits a 1.5 rad wrist swing from the box (3.1 s at
    Touch's speeds, an episode of 6.3 s); a lower home reaches every target with moves short
    enough for Touch's 5 s, and is taken."""
    arm = arm_info(ArmConfig(urdf=str(UR3)))
    task = task_config("touch")
    setup = arm_setup(arm, task)
    assert setup.home_source == "derived" and setup.covers_area
    assert setup.episode_steps == task.episode_steps and 2.0 * setup.travel_time <= 5.0
    height = tool_down_solver(arm).ik.pose(np.asarray(setup.home_qpos))[0][2]
    assert 0.09 < height < 0.16  # below the usual 0.2 m (HOME_HEIGHTS: 0.2, 0.15, 0.10)


def _slow_arm(tmp_path: Path, velocity: float) -> Path:
    """The shipped arm with every joint limited to ``velocity`` rad/s."""
    root = ET.parse(default_arm_urdf()).getroot()
    for limit in root.iter("limit"):
        limit.set("velocity", str(velocity))
    path = tmp_path / "slow_arm.urdf"
    ET.ElementTree(root).write(path)
    return path


def test_a_slow_arm_gets_a_longer_episode_and_its_time_limit(tmp_path: Path) -> None:
    """At 0.25 rad/s (a command of 0.15 x 2.0 = 0.3 rad/s is capped at the limit) the slowest
    move from home takes over 2.5 s, so Touch's episode grows past 150 steps, and the
    registered env truncates there."""
    arm = ArmConfig(urdf=str(_slow_arm(tmp_path, 0.25)), home_qpos=SHIPPED_HOME_QPOS)
    setup = arm_setup(arm_info(arm), task_config("touch"))
    assert setup.episode_steps > 150 and any("episode lengthened" in n for n in setup.notes)
    env = gym.make("mjx_arm/Touch-v0", arm=arm)
    try:
        assert env.unwrapped.task.episode_steps == setup.episode_steps
        env.reset(seed=0)
        zero = np.zeros(6, np.float32)
        for step in range(1, setup.episode_steps + 1):
            _, _, terminated, truncated, _ = env.step(zero)
            assert not terminated and truncated is (step == setup.episode_steps)
    finally:
        env.close()


def test_joint_speeds_follow_the_limits_clipped() -> None:
    """``min(action_scale * clip(v_max, 2, 3.5), v_max)``: a slow joint is not slowed further,
    an absurd limit does not make an absurd command, the usual ones are unchanged."""
    task = TaskConfig(action_scale=0.15)
    speeds = task.joint_speeds([0.25, 0.63, 2.2, 3.2, 10000.0])
    np.testing.assert_allclose(speeds, [0.25, 0.3, 0.33, 0.48, 0.525])
    assert task.joint_speeds([math.pi] * 6) == pytest.approx(0.15 * math.pi)


# --------------------------------------------------------------------------- grippers and tools


@published
def test_a_single_jaw_ends_the_arm_chain() -> None:
    z1 = resolve_arm(ArmConfig(urdf=str(Z1)))
    assert z1.ee_link == "gripperStator" and len(z1.joints) == 6
    so100 = resolve_arm(ArmConfig(urdf=str(SO100)))
    assert so100.ee_link == "gripper" and "gripper" not in so100.joint_names
    assert len(so100.joints) == 5


@published
def test_the_ee_point_moves_to_where_the_tool_touches() -> None:
    """Z1: to its closed jaw's tips, 15 cm out along the tool axis; the Kinova's open fingers
    reach 5 cm past its palm beside the axis: its ee point is a fingertip's, the deepest point
    of the tool, 10.5 cm off the axis (the axis kept); the Panda keeps its TCP between the pads
    (its closed fingertips are 9.5 mm further, within GRIP_PRESS)."""
    z1 = arm_info(ArmConfig(urdf=str(Z1)))
    np.testing.assert_allclose(z1.ee_offset, [0.149, 0.0, 0.0], atol=0.005)
    assert z1.tool_axis is None  # on the axis: the axis is found as before
    kinova = arm_info(ArmConfig(urdf=str(KINOVA)))
    np.testing.assert_allclose(kinova.ee_offset, [0.002, 0.105, 0.0], atol=0.005)
    np.testing.assert_allclose(kinova.tool_axis, [1.0, 0.0, 0.0], atol=1e-6)
    assert not np.any(arm_info(ArmConfig(urdf=str(PANDA))).ee_offset)
    # whole micrometres, so another CPU's last bits do not change the arm's model hash
    for offset in (z1.ee_offset, kinova.ee_offset):
        np.testing.assert_array_equal(offset, np.round(offset * 1e6) / 1e6)
    # the converted model's ee site sits there
    solver = tool_down_solver(z1)
    site = solver.ik.model.site(EE_SITE)
    np.testing.assert_allclose(site.pos, z1.ee_offset, atol=1e-9)


@published
def test_records_from_before_the_derived_fields_read_what_they_trained_with(tmp_path) -> None:
    record = ArmConfig.from_dict({"urdf": str(UR10)})
    assert record.kv_factor == 1.0 and record.ee_offset == (0.0, 0.0, 0.0)
    arm_file = tmp_path / "ur10.toml"
    arm_file.write_text(f'urdf = "{UR10}"\n')
    assert load_arm(arm_file).kv_factor == 0.0 and load_arm(arm_file).ee_offset == ()
    old = TaskConfig.from_dict({"task": "touch"})
    assert old.joint_encoding == "wrapped" and TaskConfig().joint_encoding == "centred"


@published
def test_a_stiff_arm_gets_a_softer_servo() -> None:
    """The UR10 presses about 1.6x as hard per action as the shipped arm at gain 1: its
    derived gain brings it back, and its models carry it."""
    ur10 = arm_info(ArmConfig(urdf=str(UR10)))
    assert 0.5 < ur10.kv_factor < 0.8
    assert ur10.kv_factor == pytest.approx(press_kv_factor(ur10))
    assert ur10.convert_config().kv_factor == ur10.kv_factor
    assert arm_info(ArmConfig(urdf=str(UR10), kv_factor=1.0)).kv_factor == 1.0


@published
def test_cylinder_collision_shapes_become_capsules() -> None:
    model = tool_down_solver(arm_info(ArmConfig(urdf=str(Z1)))).ik.model
    collides = (model.geom_contype > 0) | (model.geom_conaffinity > 0)
    assert not np.any(model.geom_type[collides] == mujoco.mjtGeom.mjGEOM_CYLINDER)
    assert np.any(model.geom_type[collides] == mujoco.mjtGeom.mjGEOM_CAPSULE)


# --------------------------------------------------------------------------- joint encoding


def test_centred_angles_do_not_jump_inside_a_range() -> None:
    """A UR joint of +-2 pi range read across pi: centred, the reading follows the angle;
    wrapped, it jumps by 2 pi. The bounds are each range's half."""
    lower, upper = np.array([-2 * math.pi, 0.82]), np.array([2 * math.pi, 5.46])
    coding = obs_lib.joint_coding("centred", lower, upper, [False, False], (0.0, 3.0))
    q = np.array([[3.0, 3.0], [3.3, 3.3]])  # both joints cross pi
    centred = obs_lib.encode_joints(np, q, coding)
    np.testing.assert_allclose(centred[1] - centred[0], [0.3, 0.3], atol=1e-12)
    np.testing.assert_allclose(coding.bound, [2 * math.pi, (5.46 - 0.82) / 2])
    wrapped = obs_lib.encode_joints(np, q, None)
    assert abs(wrapped[1, 0] - wrapped[0, 0]) > 5.9  # 2 pi - 0.3: the jump centring removes
    np.testing.assert_allclose(obs_lib.decode_joints(centred, coding), q, atol=1e-12)


def test_a_full_turn_joint_is_wrapped_about_its_home() -> None:
    coding = obs_lib.joint_coding("centred", [-6.3], [6.3], [True], (1.0,))
    angle = obs_lib.encode_joints(np, np.array([1.0 + math.pi - 0.01]), coding)
    assert angle[0] == pytest.approx(math.pi - 0.01) and coding.bound == (math.pi,)


@published
def test_kinova_observation_stays_continuous_and_inside_the_space() -> None:
    """The Kinova's joints 2, 3 and 5 have ranges around pi; wrapped readings flipped sign as
    they moved. Centred, 60 random steps change no reading by more than the joint moved."""
    env = gym.make("mjx_arm/Reach-v0", arm=str(KINOVA))
    try:
        obs, _ = env.reset(seed=0)
        rng = np.random.default_rng(0)
        biggest = 0.0
        for _ in range(60):
            before = obs["joint_angles"].copy()
            obs, *_ = env.step(rng.uniform(-1, 1, 6).astype(np.float32))
            assert env.observation_space.contains(obs)
            biggest = max(biggest, float(np.abs(obs["joint_angles"] - before).max()))
        assert biggest < 0.1  # rad per control step: at most 0.3 rad/s x 1/30 s, plus slack
    finally:
        env.close()


# --------------------------------------------------------------------------- the check


@published
def test_check_says_what_an_arm_can_do_and_draws_it(tmp_path: Path, capsys) -> None:
    picture = tmp_path / "kinova.png"
    assert main(["arm", str(KINOVA), "--check", "--picture", str(picture)]) == 0
    out = capsys.readouterr().out
    lines = {line.split()[0]: line for line in out.splitlines() if line.startswith("  ")}
    assert "yes" in lines["reach"].split()[1]
    assert lines["touch"].split()[1] == "yes"  # with a fingertip: the tool's deepest point
    assert lines["lift"].split()[1] == "no" and "no gripper" in lines["lift"]
    assert picture.stat().st_size > 10_000 and picture.read_bytes()[:4] == b"\x89PNG"


@published
def test_verdicts_of_published_arms() -> None:
    ur10 = arm_info(ArmConfig(urdf=str(UR10)))
    assert task_verdict(ur10, task_config("touch"))[0]
    assert not task_verdict(ur10, task_config("lift"))[0]  # no gripper
    panda = arm_info(ArmConfig(urdf=str(PANDA)))
    assert all(task_verdict(panda, task_config(name))[0] for name in ("reach", "touch", "lift"))
    # its link 1 overlaps the base (merged into the world body) by design: not a collision
    spheres = arm_info(ArmConfig(urdf=str(PANDA.with_name("panda_collision.urdf"))))
    assert task_verdict(spheres, task_config("touch"))[0]


@published
def test_a_tool_that_straddles_the_box_presses_with_its_deepest_point() -> None:
    """The UR3 gripper URDF's finger blocks (6 cm apart) straddle the 5 cm box at one turn and
    land on it at another: on the tool axis, where the tool meets the box moves 4.75 cm as the
    box turns (more than the 1 cm the check allows). So the ee point moves to the tool's
    deepest point, a block's tip 3 cm off the axis: there the contact does not move with the
    turn, and Touch is open. A tool with a face keeps its axis point, whose contact moves by
    3 mm or less (UR10, Panda, Z1)."""
    from mjx_arm.arm.points import CONTACT_SPREAD

    gripper = arm_info(ArmConfig(urdf=str(UR3.with_name("ur3_gripper.urdf"))))
    np.testing.assert_allclose(gripper.ee_offset, [0.0604, 0.03, 0.0], atol=0.002)
    setup = arm_setup(gripper, task_config("touch"))
    assert setup.contact_spread < CONTACT_SPREAD and abs(setup.contact_offset) < 0.005
    assert task_verdict(gripper, task_config("touch"))[0]
    assert task_verdict(gripper, task_config("reach"))[0]
    for urdf in (UR10, PANDA, Z1):
        arm = arm_info(ArmConfig(urdf=str(urdf)))
        assert arm.tool_axis is None
        assert arm_setup(arm, task_config("touch")).contact_spread < 0.003


@published
@pytest.mark.parametrize("engine", ["mujoco", "pybullet"])
def test_a_gripper_that_closes_towards_zero_starts_open_and_closes_on_command(engine) -> None:
    """The Panda's fingers close towards their lower limit (0): Lift on its own hand starts
    open (closure 0) and a gripper action of +1 closes it, as on the shipped gripper arm."""
    panda = arm_info(ArmConfig(urdf=str(PANDA)))
    assert panda.gripper.open_q == pytest.approx(0.04) and panda.gripper.closed_q == 0.0
    env = gym.make("mjx_arm/Lift-v0", engine=engine, arm=str(PANDA))
    try:
        obs, _ = env.reset(seed=0)
        assert obs["gripper"][0] == pytest.approx(0.0, abs=1e-3)
        action = np.zeros(8, np.float32)
        action[-1] = 1.0
        for _ in range(15):  # 0.5 s at 0.2 m/s closes the 4 cm stroke
            obs, *_ = env.step(action)
        assert obs["gripper"][0] > 0.95
        action[-1] = -1.0
        for _ in range(15):
            obs, *_ = env.step(action)
        assert obs["gripper"][0] < 0.05
    finally:
        env.close()


@published
@pytest.mark.parametrize("engine", ["mujoco", "pybullet"])
def test_the_panda_picks_the_cube_from_its_derived_lift_setup(engine) -> None:
    """A scripted pick (tests/lift_script.py: over the cube, down, close, lift) through the
    Lift env on the Panda's own hand, from its derived home: the cube goes up and the episode
    succeeds (both seeds, both CPU engines)."""
    from lift_script import run_scripted_lift

    env = gym.make("mjx_arm/Lift-v0", engine=engine, arm=str(PANDA)).unwrapped
    try:
        for seed in (0, 1):
            result = run_scripted_lift(env, seed=seed)
            assert result["success"], (seed, result["info"])
    finally:
        env.close()
