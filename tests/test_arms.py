"""Arms other than the shipped one: the arm config's defaults and checks, envs whose spaces
follow the joint count, targets scaled to the arm's reach, and policies that record their arm.

The published arms come from the example-robot-data package (a test dependency).
"""

from __future__ import annotations

import sysconfig
import xml.etree.ElementTree as ET
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import mjx_arm  # noqa: F401  (registers the ids)
from mjx_arm.arm.config import (
    SHIPPED_HOME_QPOS,
    ArmConfig,
    ArmConfigError,
    load_arm,
    resolve_arm,
)
from mjx_arm.arm.info import ArmMismatchError, arm_info, arm_record, check_same_arm
from mjx_arm.task import reach_config, sampling

ROBOTS = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
UR10 = ROBOTS / "ur_description/urdf/ur10_robot.urdf"
PANDA = ROBOTS / "panda_description/urdf/panda.urdf"
ARM_FILES = Path(__file__).resolve().parents[1] / "benchmarks/arms"

pytestmark = pytest.mark.skipif(not PANDA.is_file(), reason="example-robot-data not installed")


# --------------------------------------------------------------------------- the arm config


def test_defaults_of_the_shipped_arm() -> None:
    arm = resolve_arm(ArmConfig())
    assert arm.ee_link == "ee_link" and arm.ft_joint == "ft_sensor_joint"
    assert arm.home_qpos == SHIPPED_HOME_QPOS and len(arm.joints) == 6
    assert arm_info().reach_scale == 1.0  # exactly: the unit of every other arm's scale


def test_panda_defaults_leave_the_fingers_out() -> None:
    arm = resolve_arm(ArmConfig(urdf=str(PANDA)))
    assert arm.ee_link == "panda_hand_tcp"  # the fingers hang on prismatic joints
    assert arm.joint_names == tuple(f"panda_joint{i}" for i in range(1, 8))
    assert arm.ft_joint == "" and arm.ft_link == "panda_link7"
    limits = [(j.limit.lower, j.limit.upper) for j in arm.joints]
    np.testing.assert_allclose(arm.home_qpos, [(lo + hi) / 2 for lo, hi in limits])


def test_ur10_defaults() -> None:
    arm = resolve_arm(ArmConfig(urdf=str(UR10)))
    assert arm.ee_link == "ee_link" and len(arm.joints) == 6
    assert arm.ft_link == "wrist_3_link"
    assert arm.home_qpos == (0.0,) * 6  # the middle of UR's +-2 pi limits


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"ee_link": "nope"}, "is not a link"),
        ({"ee_link": "forearm_link"}, "5 to 7 arm joints"),
        ({"joints": ("shoulder_pan_joint", "finger")}, "not revolute joints on the chain"),
        ({"home_qpos": (0.0, 0.0)}, "2 angles for 6 joints"),
        ({"home_qpos": (0.0, 0.0, 4.0, 0.0, 0.0, 0.0)}, "outside"),
        ({"ft_joint": "shoulder_pan_joint"}, "must be a fixed joint"),
        ({"ft_joint": "ee_fixed_joint"}, "weighs no mass"),  # ee_link: a massless frame
    ],
)
def test_a_config_that_does_not_fit_the_urdf_is_a_named_error(change, message) -> None:
    with pytest.raises(ArmConfigError, match=message):
        resolve_arm(ArmConfig(urdf=str(UR10), **change))


def test_arm_files(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "relative.toml").write_text(f'urdf = "{PANDA.name}"\nee_link = "panda_link8"\n')
    (tmp_path / PANDA.name).write_text(PANDA.read_text())
    arm = load_arm(tmp_path / "relative.toml")
    assert Path(arm.urdf) == (tmp_path / PANDA.name).resolve() and arm.ee_link == "panda_link8"
    (tmp_path / "arm.json").write_text('{"urdf": "x.urdf", "wrist": 1}')
    with pytest.raises(ArmConfigError, match="unknown arm config keys"):
        load_arm(tmp_path / "arm.json")
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(ROBOTS))
    assert Path(load_arm(ARM_FILES / "ur10.toml").urdf) == UR10.resolve()
    assert load_arm(PANDA) == ArmConfig(urdf=str(PANDA.resolve()))
    with pytest.raises(FileNotFoundError, match="no such URDF or arm file"):
        load_arm(tmp_path / "missing.urdf")


# --------------------------------------------------------------------------- envs


@pytest.mark.parametrize("engine", ["mujoco", "pybullet"])
def test_panda_env_spaces_follow_the_joint_count(engine: str) -> None:
    env = gym.make("mjx_arm/Reach-v0", engine=engine, arm=PANDA)
    assert env.action_space.shape == (7,)
    assert env.observation_space["joint_angles"].shape == (7,)
    check_env(env.unwrapped, skip_render_check=True)
    obs, _ = env.reset(seed=3)
    for _ in range(20):
        obs, *_ = env.step(env.action_space.sample())
    assert env.observation_space.contains(obs)
    with pytest.raises(ValueError, match=r"shape \(7,\)"):
        env.step(np.zeros(6))
    env.close()


def test_targets_scale_with_the_reach() -> None:
    ur10 = arm_info(UR10)
    assert ur10.reach_scale == pytest.approx(1.30, abs=0.02)  # UR10 1.3 m, shipped arm 1.0 m
    task = reach_config().for_arm(tuple(ur10.home_qpos), ur10.reach_scale)
    low, high = (np.asarray(v) for v in task.target_box())
    np.testing.assert_allclose(low, np.asarray(reach_config().target_low) * ur10.reach_scale)
    u = np.random.default_rng(0).uniform(size=(200, 3))
    body = sampling.target_body_pos(np, u, task)
    assert np.all((body >= low) & (body <= high))
    env = gym.make("mjx_arm/Reach-v0", arm=UR10).unwrapped
    assert env.task.workspace_scale == ur10.reach_scale


def test_a_home_pose_of_another_length_is_refused() -> None:
    with pytest.raises(ValueError, match="7 joints"):
        gym.make("mjx_arm/Reach-v0", arm=PANDA, task=reach_config(home_qpos=SHIPPED_HOME_QPOS))


def test_vector_env_on_panda() -> None:
    envs = gym.make_vec("mjx_arm/Reach-v0", num_envs=3, vectorization_mode="vector_entry_point",
                        backend="mujoco", arm=PANDA)  # fmt: skip
    obs, _ = envs.reset(seed=0)
    assert obs["joint_angles"].shape == (3, 7) and envs.action_space.shape == (3, 7)
    obs, reward, *_ = envs.step(np.zeros((3, 7), np.float32))
    assert np.isfinite(reward).all()
    envs.close()


# --------------------------------------------------------------------------- policy records


def test_a_policy_runs_only_on_its_own_arm(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(ROBOTS.parent))  # the copy's package:// meshes
    panda, shipped = arm_info(PANDA), arm_info()
    check_same_arm(arm_record(panda), panda)  # the same arm: no error
    with pytest.raises(ArmMismatchError, match="panda_joint1"):
        check_same_arm(arm_record(panda), shipped)
    # same joint names, another arm (heavier link 3): the model hash tells them apart
    root = ET.parse(PANDA).getroot()
    link3 = next(link for link in root.findall("link") if link.get("name") == "panda_link3")
    link3.find("inertial/mass").set("value", "5.0")
    heavier = tmp_path / "panda_heavier.urdf"
    ET.ElementTree(root).write(heavier, encoding="unicode")
    other = arm_info(ArmConfig(urdf=str(heavier)))
    assert other.joint_names == panda.joint_names
    with pytest.raises(ArmMismatchError, match="different converted model"):
        check_same_arm(arm_record(panda), other)


def test_parity_forward_kinematics_on_panda(tmp_path: Path) -> None:
    from mjx_arm.bench.parity import ParityConfig, run_parity

    config = ParityConfig.quick(engines=("mujoco", "pybullet"), arm=str(PANDA), press_boxes=1)
    result = run_parity(config, log=lambda _: None)
    fk = result["figures"]["fk_m"]["mujoco vs pybullet"]
    assert fk < 1e-6, fk  # m, over random poses inside the limits


def test_collision_meshes_can_be_fitted_capsules() -> None:
    import mujoco

    from mjx_arm.arm.model_io import arm_model

    def collision_types(collision: str) -> set[str]:
        arm = arm_info(ArmConfig(urdf=str(UR10), collision=collision))
        model = arm_model(arm, reach_config())
        arm_geoms = [i for i in range(model.ngeom) if model.geom_bodyid[i] > 0]
        return {mujoco.mjtGeom(model.geom_type[i]).name for i in arm_geoms if model.geom_contype[i]}

    assert "mjGEOM_MESH" in collision_types("mesh")
    assert collision_types("capsule") == {"mjGEOM_CAPSULE", "mjGEOM_BOX"}  # ee_link's own box
    with pytest.raises(ArmConfigError, match="collision must be one of"):
        ArmConfig(collision="sphere")


def test_an_inertia_on_the_triangle_edge_is_moved_inside_by_the_repair() -> None:
    from mjx_arm.urdf.inertia import (
        REPAIR_MARGIN,
        inertia_tensor,
        on_triangle_edge,
        principal_moments,
        repair_inertia,
    )

    # TIAGo's arm_1_link: a + b exceeds c by 2e-12, which 6 written digits turn into a + b < c
    edge = inertia_tensor(
        {"ixx": 0.003060504572445, "ixy": 0.002364723186022, "ixz": 0.001495245689439,
         "iyy": 0.008630326004235, "iyz": 0.000522540423519, "izz": 0.009347757530069}
    )  # fmt: skip
    assert on_triangle_edge(edge)
    a, b, c = principal_moments(repair_inertia(edge))
    assert a + b >= c * (1 + REPAIR_MARGIN) * (1 - 1e-12)
    written = np.array([float(f"{m:.6g}") for m in (a, b, c)])
    assert written[0] + written[1] >= written[2]


def test_arm_command_writes_an_arm_file_that_resolves_the_same(tmp_path: Path, capsys) -> None:
    from mjx_arm.cli import main
    from mjx_arm.names import EXIT_INVALID, EXIT_OK

    out = tmp_path / "panda.toml"
    assert main(["arm", str(PANDA), "-o", str(out)]) == EXIT_OK
    shown = capsys.readouterr().out
    assert "panda_hand_tcp" in shown and "observation 23, action 7" in shown
    again = arm_info(load_arm(out))
    panda = arm_info(PANDA)
    assert again.joint_names == panda.joint_names and again.ee_link == panda.ee_link
    np.testing.assert_allclose(again.home_qpos, panda.home_qpos, atol=1e-6)
    assert main(["arm", str(PANDA), "--ee-link", "panda_link3"]) == EXIT_INVALID
    assert "5 to 7 arm joints" in capsys.readouterr().err


def test_a_hand_of_revolute_fingers_is_the_end_effector(tmp_path: Path) -> None:
    import pybullet_data

    xarm = Path(pybullet_data.getDataPath()) / "xarm/xarm6_with_gripper.urdf"
    # the gripper's fingers are revolute: its base, where they branch, ends the arm
    arm = resolve_arm(ArmConfig(urdf=str(xarm)))
    assert arm.ee_link == "xarm_gripper_base_link"
    assert arm.joint_names == tuple(f"joint{i}" for i in range(1, 7))
    # its link inertias break the triangle inequality: the arm file's repair makes it run
    with pytest.raises(Exception, match="triangle inequality"):
        gym.make("mjx_arm/Reach-v0", arm=xarm)
    (tmp_path / "xarm.toml").write_text(f'urdf = "{xarm}"\nrepair_inertia = true\n')
    env = gym.make("mjx_arm/Reach-v0", arm=tmp_path / "xarm.toml")
    env.reset(seed=0)
    _, reward, *_ = env.step(np.zeros(6, np.float32))
    assert np.isfinite(reward)


@pytest.mark.parametrize("engine", ["mujoco", "pybullet"])
def test_the_sim_to_real_chain_drives_a_seven_joint_arm(engine: str) -> None:
    from mjx_arm.sim2real.position_env import make_position_env

    env = make_position_env(reach_config(), engine, arm=PANDA)
    obs, _ = env.reset(seed=0)
    start = obs["joint_angles"].copy()
    for _ in range(10):
        obs, *_ = env.step(np.zeros(7, np.float32))  # hold still: the arm stays where it began
    np.testing.assert_allclose(obs["joint_angles"], start, atol=2e-3)  # rad
    commands = env.unwrapped.episodes[-1].arrays()["commands"]
    assert commands.shape == (10, 7)
    env.close()


def test_the_report_names_an_ee_point_that_fitted_capsules_move(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """With every fitted capsule kept (no box where one bulges), the xArm7's capsule around its
    flange reaches 8.8 mm past the mesh along the tool axis, so the ee point derived on capsules
    is not where PyBullet (which keeps the meshes) presses: the report says by how much and
    gives the meshes' point to set. As shipped, the flange gets a box and nothing moves; the
    Panda's capsules move nothing either way."""
    from mjx_arm.arm.info import _arm_info_cached
    from mjx_arm.arm.points import _solver_cached
    from mjx_arm.arm.report import describe
    from mjx_arm.urdf import collision_fit

    monkeypatch.setenv("ROS_PACKAGE_PATH", str(ROBOTS))
    xarm_file = ARM_FILES / "xarm7_capsules.toml"
    assert "ee point is" not in describe(arm_info(xarm_file))
    for cached in (_arm_info_cached, _solver_cached):
        cached.cache_clear()
    monkeypatch.setattr(collision_fit, "CAPSULE_BULGE", np.inf)
    try:
        xarm = describe(arm_info(xarm_file))
        panda = describe(arm_info(ARM_FILES / "panda_capsules.toml"))
    finally:
        for cached in (_arm_info_cached, _solver_cached):
            cached.cache_clear()
    line = next(s for s in xarm.splitlines() if s.startswith("collision"))
    gap = float(line.split("ee point is ")[1].split(" mm")[0])
    assert 7.0 <= gap <= 11.0, line  # measured 8.8 mm
    assert "set ee_offset = [0, 0, 0]" in line
    assert "collision   capsule\n" in panda + "\n" and "ee point is" not in panda


@pytest.mark.parametrize(
    ("arm_file", "boxed"),
    [
        ("xarm7_capsules", {"link7"}),
        ("ur10_capsules", {"base_link", "wrist_3_link"}),
        ("panda_capsules", set()),
    ],
)
def test_a_capsule_that_bulges_past_its_mesh_becomes_a_box(
    monkeypatch: pytest.MonkeyPatch, arm_file: str, boxed: set[str]
) -> None:
    """``collision = "capsule"`` keeps a capsule only where it stays within CAPSULE_BULGE
    (5 mm) of its mesh across its axis; the flanges of the xArm7 (8.7 mm) and the UR10 (11.8
    mm) and the UR10's base (25.5 mm) get boxes, the Panda's capsules (at most 2.4 mm) all
    stay. The ee point derived on the result is the meshes' to within 1 mm."""
    import mujoco

    from mjx_arm.arm.model_io import arm_model
    from mjx_arm.urdf.collision_fit import CAPSULE_BULGE, capsule_bulge

    monkeypatch.setenv("ROS_PACKAGE_PATH", str(ROBOTS))
    arm = arm_info(ARM_FILES / f"{arm_file}.toml")
    fitted = arm_model(arm, reach_config())
    meshes = arm_model(arm_info(arm.config.replace(collision="mesh")), reach_config())
    box, capsule = int(mujoco.mjtGeom.mjGEOM_BOX), int(mujoco.mjtGeom.mjGEOM_CAPSULE)
    found = set()
    for geom in range(meshes.ngeom):
        if meshes.geom_type[geom] != mujoco.mjtGeom.mjGEOM_MESH or not meshes.geom_contype[geom]:
            continue
        body = meshes.body(meshes.geom_bodyid[geom]).name
        mesh = meshes.mesh(meshes.geom_dataid[geom]).name
        assert fitted.geom_type[geom] in (box, capsule), body
        if fitted.geom_type[geom] == box:
            found.add(body)
        else:
            assert capsule_bulge(fitted, geom, mesh) <= CAPSULE_BULGE, body
    assert found == boxed
    mesh_point = arm_info(arm.config.replace(collision="mesh")).ee_offset
    assert np.linalg.norm(arm.ee_offset - mesh_point) < 1e-3
