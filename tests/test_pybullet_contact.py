"""PyBullet's contacts shaped on MuJoCo's: the compliant scene (``pybullet_ref.contact``) and the
collision meshes eroded by Bullet's margin (``pybullet_ref.hulls``).

Figures in the comments were measured on this project's 2-core CPU (pybullet 3.2.7, mujoco
4.0.0); ``benchmarks/bench_pybullet_contact.py`` gives the full comparison.
"""

from __future__ import annotations

import sysconfig
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np
import pytest

from mjx_arm.arm.config import ArmConfig
from mjx_arm.cli import main
from mjx_arm.envs.mujoco_env import MujocoArmEnv
from mjx_arm.envs.registration import register_envs
from mjx_arm.evaluate.core import eval_arm, eval_task
from mjx_arm.evaluate.runners import run_episodes
from mjx_arm.names import EXIT_INVALID, EXIT_OK, env_id
from mjx_arm.policy import load
from mjx_arm.task import touch_config
from mjx_arm.urdf.convert import EE_SITE
from mjx_arm.urdf.errors import ConversionError
from mjx_arm.urdf.mesh_convert import load_mesh
from pybullet_ref import PybulletArmEnv
from pybullet_ref.contact import RIGID, SOFT, Compliance, SceneContact, scene_contact
from pybullet_ref.hulls import BULLET_URDF_MARGIN, bullet_urdf, eroded_hull

pytestmark = pytest.mark.pybullet

ROOT = Path(__file__).resolve().parents[1]
ROBOTS = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
UR10 = ROBOTS / "ur_description/urdf/ur10_robot.urdf"
LIFT_SEED0 = ROOT / "benchmarks/results/policies/lift-fast-seed0.npz"
UR10_HOME = (0.0, -1.3291, 2.1732, -2.4149, -1.5708, 0.0)  # benchmarks/arms/ur10.toml's
BOX_BODY = 2  # PyBullet body ids: the arm 0, the table 1, the box 2
needs_ur10 = pytest.mark.skipif(not UR10.is_file(), reason="example-robot-data not installed")


# --------------------------------------------------------------------------- the settings


def test_scene_contact_text_forms() -> None:
    assert scene_contact("soft") is SOFT and scene_contact("rigid") is RIGID
    parsed = SceneContact.parse("4e4:200/3e3:30")
    assert parsed == SceneContact(Compliance(4e4, 200.0), Compliance(3e3, 30.0))
    assert SceneContact.parse(str(parsed)) == parsed
    assert SceneContact.parse("rigid/3e3:30").fixed is None
    assert SceneContact.parse("4e4:200").cube is None  # the cube part defaults to rigid
    assert parsed.to_dict()["cube"] == {"stiffness": 3e3, "damping": 30.0}


@pytest.mark.parametrize("text", ["soft!", "4e4", "4e4:x", "-1:10", "1e4:-5"])
def test_bad_contact_text_is_a_named_error(text: str) -> None:
    with pytest.raises(ValueError, match=r"rigid|stiffness"):
        SceneContact.parse(text)


def test_the_env_sets_the_scene_compliance() -> None:
    """getDynamicsInfo: index 8 is the contact damping, 9 the stiffness (-1: not set)."""
    soft, rigid = (PybulletArmEnv(touch_config(), contact=c) for c in ("soft", "rigid"))
    try:
        for env in (soft, rigid):
            env.reset(seed=0)
        for body in (1, BOX_BODY):  # the table and the box
            info = soft.client.getDynamicsInfo(body, -1)
            assert (info[9], info[8]) == (SOFT.fixed.stiffness, SOFT.fixed.damping)
            assert rigid.client.getDynamicsInfo(body, -1)[9] == -1.0
        assert soft.client.getDynamicsInfo(0, 3)[9] == -1.0  # the arm's links set nothing
    finally:
        soft.close()
        rigid.close()


# --------------------------------------------------------------------------- eroded hulls


def _support(points: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Support function ``max_p p . u`` of a point set per unit direction, ``(k,)``."""
    return (directions @ points.T).max(axis=1)


def test_eroded_hull_plus_the_margin_is_the_hull() -> None:
    """A 10 cm box: faces 1 mm in; along any direction the eroded hull plus Bullet's margin
    reaches the box's own support within the edge rounding (at most (sqrt(3) - 1) mm)."""
    box = np.array([[x, y, z] for x in (0, 0.1) for y in (0, 0.1) for z in (0, 0.1)])
    vertices, faces = eroded_hull(box, BULLET_URDF_MARGIN)
    np.testing.assert_allclose(vertices.min(axis=0), 0.001, atol=1e-12)
    np.testing.assert_allclose(vertices.max(axis=0), 0.099, atol=1e-12)
    normals = np.cross(
        vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]]
    )
    outward = np.einsum("ij,ij->i", normals, vertices[faces[:, 0]] - vertices.mean(axis=0))
    assert (outward > 0).all()  # every triangle wound outward
    u = np.random.default_rng(0).normal(size=(500, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    gap = _support(box, u) - (_support(vertices, u) + BULLET_URDF_MARGIN)
    assert gap.min() >= -1e-12 and gap.max() <= (np.sqrt(3) - 1) * BULLET_URDF_MARGIN + 1e-12


def test_a_sliver_thinner_than_the_margin_still_gives_a_hull() -> None:
    sliver = np.array([[x, y, z] for x in (0, 0.1) for y in (0, 0.1) for z in (0, 0.001)])
    vertices, faces = eroded_hull(sliver, BULLET_URDF_MARGIN)
    assert len(faces) >= 4 and np.ptp(vertices[:, 2]) == pytest.approx(0.0005)


def test_a_urdf_without_collision_meshes_loads_as_it_is() -> None:
    urdf = ROOT / "assets/ur5e.urdf"
    assert bullet_urdf(urdf) == urdf


@needs_ur10
def test_ur10_copy_has_eroded_hulls(tmp_path: Path) -> None:
    copy = bullet_urdf(UR10, tmp_path)
    assert copy.parent == tmp_path and bullet_urdf(UR10, tmp_path) == copy  # cached
    text = copy.read_text()
    assert "package://" not in text and text.count("_hull_") == 7  # one per link with a mesh
    hull = next(tmp_path.glob("wrist3_hull_*.obj"))
    source = ROBOTS / "ur_description/meshes/ur10/collision/wrist3.stl"
    u = np.random.default_rng(1).normal(size=(300, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    eroded = _support(load_mesh(hull).vertices, u) + BULLET_URDF_MARGIN
    gap = _support(load_mesh(source).vertices, u) - eroded
    assert gap.min() >= -1e-9 and np.median(gap) < 2e-4  # faces back in place, edges rounded


@needs_ur10
def test_an_unwritable_cache_is_a_named_error(tmp_path: Path) -> None:
    blocked = tmp_path / "file"
    blocked.write_text("")  # a file where the cache folder should be
    with pytest.raises(ConversionError, match="XDG_CACHE_HOME"):
        bullet_urdf(UR10, blocked / "cache")


def _mujoco_distances(env: MujocoArmEnv, box_geom: int) -> dict[str, float]:
    """Per arm body: the smallest distance (m) of its geoms to the box (up to 1 m)."""
    m, d, out = env.model, env.data, {}
    for g in range(m.ngeom):
        name = m.body(m.geom_bodyid[g]).name
        if (
            g == box_geom
            or not (m.geom_contype[g] | m.geom_conaffinity[g])
            or name in ("world", "target")
        ):
            continue
        dist = mujoco.mj_geomDistance(m, d, g, box_geom, 1.0, None)
        out[name] = min(out.get(name, 1.0), dist)
    return out


def _bullet_distances(env: PybulletArmEnv, box: int) -> dict[str, float]:
    c, out = env.client, {}
    for p in c.getClosestPoints(env.body, box, 1.0):
        name = c.getJointInfo(env.body, p[3])[12].decode() if p[3] >= 0 else "base_link"
        out[name] = min(out.get(name, 1.0), p[8])
    return out


def _box_below_tool(mj: MujocoArmEnv, qpos: np.ndarray, box_geom: int, gap: float) -> np.ndarray:
    """The box position (m, ``(3,)``) under the ee point at which MuJoCo's nearest arm geom is
    ``gap`` (m) from it: the box is raised three times by the remaining distance."""
    mj._physics_reset(qpos, np.zeros(3))
    box = np.array([*mj.data.site_xpos[mj.model.site(EE_SITE).id][:2], 0.0])
    for _ in range(3):
        mj._physics_reset(qpos, box)
        box[2] += min(_mujoco_distances(mj, box_geom).values()) - gap
    mj._physics_reset(qpos, box)
    return box


@needs_ur10
def test_ur10_mesh_distances_agree_with_mujoco() -> None:
    """The UR10's wrist 0.5 mm above the box (in MuJoCo) at 6 wrist tilts of up to 0.4 rad:
    with the eroded hulls PyBullet's distance is at most 0.15 mm farther than MuJoCo's
    (measured: 0.025-0.099 mm, the rounded edges); with Bullet's own padded hulls about 1 mm
    closer (measured: 0.93-0.997 mm)."""
    arm = ArmConfig(urdf=str(UR10), home_qpos=UR10_HOME)
    task = touch_config()
    mj, pb = MujocoArmEnv(task, arm), PybulletArmEnv(task, arm, contact="rigid")
    raw = PybulletArmEnv(task, arm, contact="rigid")
    raw._urdf = UR10  # Bullet's own import of the meshes, for the comparison
    model = mj.model
    box_geom = next(
        g for g in range(model.ngeom) if model.body(model.geom_bodyid[g]).name == "target"
    )
    rng, eroded, padded = np.random.default_rng(0), [], []
    try:
        for _ in range(6):
            qpos = np.asarray(UR10_HOME) + np.r_[0.0, 0.0, 0.0, rng.uniform(-0.4, 0.4, 3)]
            box = _box_below_tool(mj, qpos, box_geom, 5e-4)
            want = _mujoco_distances(mj, box_geom)
            link = min(want, key=want.get)
            for env, out in ((pb, eroded), (raw, padded)):
                env._physics_reset(qpos, box)
                out.append(_bullet_distances(env, BOX_BODY)[link] - want[link])
    finally:
        for env in (mj, pb, raw):
            env.close()
    eroded, padded = np.array(eroded), np.array(padded)
    print(f"[hulls] Bullet - MuJoCo (mm): eroded {1000 * eroded}, padded {1000 * padded}")
    assert np.all((eroded > -2e-5) & (eroded < 1.5e-4))
    assert np.all((padded > -BULLET_URDF_MARGIN - 2e-5) & (padded < -0.9 * BULLET_URDF_MARGIN))


# --------------------------------------------------------------------------- a trained policy


def _success_rate(policy, task, arm, contact: str, episodes: int) -> float:
    register_envs()
    env = gym.make(env_id(task.task), engine="pybullet", task=task, arm=arm, contact=contact)
    try:
        run = run_episodes(policy, env, episodes, seed=0)
    finally:
        env.close()
    return float(np.mean([e.success for e in run.episodes]))


def test_lift_policy_sets_down_softly_in_pybullet() -> None:
    """Lift seed 0's policy lands its fingers on the cube. Rigid, PyBullet reads a strike
    (over 100 N) in most episodes (200 episodes: 0.075, against 0.92 in CPU MuJoCo); on the soft
    scene it lifts. 12 episodes each; measured 11 of 12 soft, 1 of 12 rigid."""
    policy = load(LIFT_SEED0)
    task, _ = eval_task(policy)
    arm = eval_arm(policy)
    soft = _success_rate(policy, task, arm, "soft", 12)
    rigid = _success_rate(policy, task, arm, "rigid", 12)
    print(f"[contact] Lift seed 0 in PyBullet: soft {soft:.3f}, rigid {rigid:.3f}")
    assert soft >= 0.75 and rigid <= 0.35


def test_eval_takes_the_contact_and_names_a_bad_one(capsys: pytest.CaptureFixture) -> None:
    """``mjx-arm eval --pybullet-contact``: the JSON summary names the contact it ran on; a bad text
    is exit 2 with the parser's message, before anything is loaded."""
    policy = str(LIFT_SEED0)
    assert (
        main(
            [
                "eval",
                policy,
                "--engine",
                "pybullet",
                "--episodes",
                "1",
                "--pybullet-contact",
                "rigid",
                "--json",
            ]
        )
        == EXIT_OK
    )
    assert '"contact": "rigid/rigid"' in capsys.readouterr().out
    assert (
        main(["eval", policy, "--engine", "pybullet", "--pybullet-contact", "1:2:3"])
        == EXIT_INVALID
    )
    assert "STIFFNESS:DAMPING" in capsys.readouterr().err


# --------------------------------------------------------------------------- self-collision


@needs_ur10
def test_arm_links_pass_through_each_other_as_in_the_task_model() -> None:
    """The task models have no arm self-collision, and neither has PyBullet's arm. From a pose
    where the UR10's wrist_2 mesh is 4 cm of joint travel above the forearm's, wrist_2 turned
    down for 15 steps (Reach) ends where MuJoCo's does (within 0.02 rad), with no contact
    between arm links. With Bullet's self-collision on, the forearm stopped it at 1.36 rad,
    which left a trained Reach policy 2-11 cm short of the target in 12 % of its episodes."""
    arm = ArmConfig(urdf=str(UR10), home_qpos=UR10_HOME)
    start = np.array([0.15, -1.45, 1.58, 1.05, 1.45, -0.01])
    action = np.zeros(6, np.float32)
    action[4] = -1.0
    wrist_2 = {}
    for engine in ("mujoco", "pybullet"):
        register_envs()
        env = gym.make(env_id("reach"), engine=engine, arm=arm).unwrapped
        try:
            env.reset(seed=0)
            env._physics_reset(start, np.array([0.8, 0.8, 0.8]))  # a target out of reach
            for _ in range(15):
                obs, *_ = env.step(action)
            wrist_2[engine] = float(obs["joint_angles"][4])
            if engine == "pybullet":
                assert env.client.getContactPoints(bodyA=env.body, bodyB=env.body) == ()
        finally:
            env.close()
    print(f"[self-collision] wrist_2 after 15 steps (rad): {wrist_2}")
    assert wrist_2["mujoco"] < 1.3
    assert abs(wrist_2["pybullet"] - wrist_2["mujoco"]) < 0.02
