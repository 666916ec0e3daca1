"""Position-controlled envs, the command chain and ``mjx-arm deploy-sim``.

The deploy tests reuse the session's small trained Reach policy (``test_policy.trained_run_dir``,
about 30-40 s of training on a CPU, shared with test_policy, test_evaluate and test_replay).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from test_policy import trained_run_dir

from mjx_arm.cli import EXIT_INVALID, EXIT_OK, main
from mjx_arm.envs.mujoco_env import MujocoArmEnv
from mjx_arm.policy import export_policy, load
from mjx_arm.sim2real.deploy import DeployConfig, VelocityCommandChain, deploy_sim
from mjx_arm.sim2real.limiter import JointLimits
from mjx_arm.sim2real.observation import ObservationBuilder
from mjx_arm.sim2real.position_env import ServoConfig, make_position_env
from mjx_arm.task.config import task_config
from pybullet_ref.env import PybulletArmEnv

REACH = task_config("reach")
VELOCITY_ENVS = {"mujoco": MujocoArmEnv, "pybullet": PybulletArmEnv}
ENGINES = [
    "mujoco",
    pytest.param("pybullet", marks=pytest.mark.pybullet),
]
# Measured on the session's small policy (122,880 training steps), 20 episodes, seed 0:
# success with velocity control / through the chain: MuJoCo 0.90 / 0.95, PyBullet 0.95 / 0.95.
# The tests ask for 0.75 through the chain, and no more than 0.15 below velocity control.
POSITION_SUCCESS_MIN = 0.75
SUCCESS_GAP_MAX = 0.15
DEPLOY_EPISODES = 20


@pytest.fixture(scope="module")
def policy_path(tmp_path_factory) -> Path:
    run_dir = trained_run_dir(tmp_path_factory)
    return export_policy(run_dir, tmp_path_factory.mktemp("deploy") / "policy.npz")


# --------------------------------------------------------------------------- position envs


@pytest.mark.parametrize("engine", ENGINES)
def test_position_env_keeps_the_contract(engine: str):
    """Same observation space and the same first observation as the velocity env."""
    position = make_position_env(REACH, engine)
    velocity = VELOCITY_ENVS[engine](REACH)
    try:
        assert position.observation_space == velocity.observation_space
        obs_p, info_p = position.reset(seed=3)
        obs_v, info_v = velocity.reset(seed=3)
        for key in obs_v:
            np.testing.assert_array_equal(obs_p[key], obs_v[key])
        assert info_p.keys() == info_v.keys()
        q = position.unwrapped.measured_qpos()
        _, reward, _, truncated, info = position.step(q)
        assert set(info["reward_terms"]) == set(REACH.reward.weights())
        assert np.isfinite(reward) and not truncated
        assert position.observation_space.contains(position.step(q)[0])
    finally:
        position.close()
        velocity.close()


@pytest.mark.parametrize("engine", ENGINES)
def test_position_servo_holds_and_settles(engine: str):
    """Holding the start pose drifts < 1e-6 rad; a 0.1 rad step on every joint settles
    within 1e-3 rad in 15 control steps (0.5 s). Measured: within 2e-4 rad after 8 steps."""
    env = make_position_env(REACH, engine)
    try:
        env.reset(seed=0)
        base = env.unwrapped
        q0 = base.measured_qpos()
        for _ in range(10):
            env.step(q0)
        np.testing.assert_allclose(base.measured_qpos(), q0, atol=1e-6)
        for _ in range(15):
            env.step(q0 + 0.1)
        np.testing.assert_allclose(base.measured_qpos(), q0 + 0.1, atol=1e-3)
        with pytest.raises(ValueError, match="NaN or inf"):
            env.step(np.full(6, np.nan))
    finally:
        env.close()


def test_servo_gains_wrap_the_velocity_servo():
    """kp = K * kv with the velocity actuator's kv; force capped at the URDF effort."""
    velocity = MujocoArmEnv(REACH)
    position = make_position_env(REACH, "mujoco", ServoConfig(position_gain=25.0)).unwrapped
    act = velocity.ids.actuators
    kv = velocity.model.actuator_gainprm[act, 0]
    np.testing.assert_allclose(position.gains.kv, kv)
    np.testing.assert_allclose(position.gains.kp, 25.0 * kv)
    np.testing.assert_allclose(position.model.actuator_biasprm[act, 1:3], -np.c_[25.0 * kv, kv])
    np.testing.assert_allclose(position.model.actuator_forcerange[act, 1], position.arm.effort)
    np.testing.assert_allclose(position.model.actuator_ctrlrange[act, 0], position.arm.lower)


def test_observation_builder_matches_the_env():
    """Forward kinematics from the joint angles gives the env's observation at reset (within
    1e-6; after a step the env reads its sensors one substep before the final joint angles)."""
    env = MujocoArmEnv(REACH)
    builder = ObservationBuilder(REACH)
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        q = env.data.qpos[env.ids.qpos_adr]
        built = builder(q, env.data.site_xpos[env.ids.target_site], np.zeros(6))
        for key in obs:
            np.testing.assert_allclose(built[key], obs[key], atol=1e-6)
    with pytest.raises(ValueError, match="6 finite"):
        builder(np.full(6, np.nan), np.zeros(3))


def test_chain_with_a_still_policy_holds_the_start_pose():
    """Zero velocity actions: the commands stay at the measured start, no clip."""
    chain = VelocityCommandChain(make_position_env(REACH, "mujoco"), 0.02, JointLimits.from_urdf())
    chain.reset(seed=1)
    q0 = chain.unwrapped.measured_qpos()
    for _ in range(20):
        chain.step(np.zeros(6, np.float32))
    commands = chain.episodes[-1].arrays()["commands"]
    np.testing.assert_array_equal(commands, np.tile(q0, (20, 1)))
    assert chain.limiter.total_clips == 0
    chain.close()


# --------------------------------------------------------------------------- deploy-sim


@pytest.mark.parametrize("engine", ENGINES)
def test_deploy_sim_success_through_the_chain(policy_path: Path, engine: str):
    report = deploy_sim(load(policy_path), engine, DEPLOY_EPISODES, seed=0)
    vel = report["velocity_control"]["success_rate"]
    pos = report["position_control"]["success_rate"]
    print(f"\n[deploy-sim {engine}] velocity {vel:.2f}, position {pos:.2f}, {report}")
    assert pos >= POSITION_SUCCESS_MIN
    assert pos >= vel - SUCCESS_GAP_MAX
    # measured: max 0.022 / 0.036 rad, mean 0.0033 / 0.0041 rad (MuJoCo / PyBullet)
    assert report["tracking_error_rad"]["max"] < 0.1
    assert report["tracking_error_rad"]["mean"] < 0.02
    assert report["ee_deviation_m"]["mean"] < 0.03
    commands = report["commands"]["commands"]
    limits = JointLimits.from_urdf()
    assert (commands >= limits.lower).all() and (commands <= limits.upper).all()


def test_cli_deploy_sim_writes_the_urscript(policy_path: Path, tmp_path: Path, capsys):
    script, trajectory, output = tmp_path / "p.script", tmp_path / "t.json", tmp_path / "r.json"
    argv = ["deploy-sim", str(policy_path), "--episodes", "4", "--script", str(script)]
    argv += ["--trajectory", str(trajectory), "-o", str(output), "--set", "tau=0.05"]
    assert main(argv) == EXIT_OK
    out = capsys.readouterr().out
    assert "success rate" in out and "tracking error" in out
    result = json.loads(output.read_text())
    assert result["settings"]["tau"] == 0.05 and result["episodes"] == 4
    lines = [line.strip() for line in script.read_text().splitlines()]
    servoj = [line for line in lines if line.startswith("servoj(")]
    assert len(servoj) == result["script_steps"] >= 1
    assert all(re.fullmatch(r"servoj\(\[[^]]+\], 0, 0, 0\.033333, 0\.1, 300\)", s) for s in servoj)
    msg = json.loads(trajectory.read_text())
    first = [float(v) for v in servoj[0][8 : servoj[0].index("]")].split(",")]
    np.testing.assert_allclose(first, msg["points"][0]["positions"], atol=5e-7)
    assert len(msg["points"]) == len(servoj)


def test_cli_deploy_sim_rejects_bad_settings(policy_path: Path, capsys):
    assert main(["deploy-sim", str(policy_path), "--set", "limiter.speed=1"]) == EXIT_INVALID
    assert "unknown setting 'speed'" in capsys.readouterr().err
    assert main(["deploy-sim", str(policy_path), "--set", "gain=50"]) == EXIT_INVALID
    assert "gain must be in [100, 2000]" in capsys.readouterr().err


def test_deploy_config_validates():
    with pytest.raises(ValueError, match="tau"):
        DeployConfig(tau=-0.1)
