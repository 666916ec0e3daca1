"""Unit tests of the engine-neutral task contract in :mod:`mjx_arm.task`.

Everything here is plain numpy on hand-made inputs (no physics engine), so the file runs in about
a second; a few functions are run a second time with ``jax.numpy`` to show that the single
definition of the contract serves the JAX engine too.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from mjx_arm.arm.config import SHIPPED_HOME_QPOS
from mjx_arm.task import config as config_lib
from mjx_arm.task import observation as obs_lib
from mjx_arm.task import reach_config, sampling, touch_config
from mjx_arm.task import reward as reward_lib
from mjx_arm.task import touch as touch_lib
from mjx_arm.task.config import REWARD_TERMS, RewardConfig, TaskConfig
from mjx_arm.task.wrench import (
    SENSOR_BLOCK_SIZE,
    ToolInertia,
    external_wrench,
    sensor_wrench,
    tool_inertia,
)
from mjx_arm.urdf.scene import box_top_offset

GRAVITY = np.array([0.0, 0.0, -9.81])
# Hand-made joint limits for the reward tests: +-1 rad, so the soft limit (0.95) sits at +-0.95.
UNIT_LIMITS = (-np.ones(6), np.ones(6))


def rot_z(angle: float) -> np.ndarray:
    """Rotation matrix ``(3, 3)`` of ``angle`` (rad) about z."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_x(angle: float) -> np.ndarray:
    """Rotation matrix ``(3, 3)`` of ``angle`` (rad) about x."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def terms_for(
    cfg: TaskConfig,
    distance: float,
    force: float,
    qpos: np.ndarray | None = None,
    qvel: np.ndarray | None = None,
    xp=np,
) -> dict:
    """Reward terms of one state, success computed with the task's own rule."""
    qpos = np.zeros(6) if qpos is None else qpos
    qvel = np.zeros(6) if qvel is None else qvel
    d, f = xp.asarray(distance), xp.asarray(force)
    success = reward_lib.is_success(xp, d, f, cfg)
    return reward_lib.reward_terms(
        xp, d, f, xp.asarray(qpos), xp.asarray(qvel), UNIT_LIMITS, success, False, cfg
    )


# ----------------------------------------------------------------------------- config


def test_default_timing_is_eight_substeps() -> None:
    for cfg in (TaskConfig(), touch_config(), reach_config()):
        assert cfg.ctrl_dt == pytest.approx(1 / 30)
        assert cfg.sim_dt == pytest.approx(1 / 240)
        assert cfg.n_substeps == 8
        assert cfg.episode_steps == 150


def test_ctrl_dt_must_be_whole_multiple_of_sim_dt() -> None:
    with pytest.raises(ValueError, match="whole multiple"):
        TaskConfig(ctrl_dt=0.01, sim_dt=0.003)
    with pytest.raises(ValueError, match="task must be one of"):
        TaskConfig(task="grasp")


@pytest.mark.parametrize("preset", [reach_config, touch_config])
def test_task_config_dict_round_trip(preset) -> None:
    cfg = preset(action_scale=0.25, reward={"joint_velocity": -0.2})
    data = json.loads(json.dumps(cfg.to_dict()))  # through JSON: tuples come back as lists
    back = TaskConfig.from_dict(data)
    assert back == cfg
    assert back.reward == cfg.reward
    assert back.reward.joint_velocity == -0.2
    assert isinstance(back.home_qpos, tuple)


def test_task_config_from_dict_names_unknown_keys() -> None:
    data = reach_config().to_dict()
    with pytest.raises(ValueError, match=r"unknown task config keys: \['speed'\]"):
        TaskConfig.from_dict({**data, "speed": 1.0})
    with pytest.raises(ValueError, match=r"unknown reward keys: \['bonus'\]"):
        TaskConfig.from_dict({**data, "reward": {**data["reward"], "bonus": 1.0}})


def test_presets_and_overrides() -> None:
    reach, touch = config_lib.task_config("Reach"), config_lib.task_config("touch")
    assert (reach.task, reach.success_distance, reach.reward.contact) == ("reach", 0.02, 0.0)
    assert (touch.task, touch.success_distance, touch.force_band) == ("touch", 0.05, (1.0, 50.0))
    assert touch.variant == "gentle" and touch.reward == touch_lib.GENTLE_REWARD
    seed = config_lib.task_config("touch", variant="seed")
    assert seed.reward == RewardConfig() and seed.success_hold_steps == 1
    # Gentle Touch moves slower than the seed (and than Reach), so the band is a wider action.
    assert (touch.action_scale, seed.action_scale, reach.action_scale) == (0.15, 0.5, 0.5)
    assert config_lib.task_config("touch", action_scale=0.3).action_scale == 0.3
    assert not (seed.fail_on_overforce or seed.terminate_on_overforce)
    assert (touch.success_hold_steps, touch.fail_on_overforce, touch.terminate_on_overforce) == (
        3,
        True,
        True,
    )
    assert not reach.uses_contact and touch.uses_contact
    with pytest.raises(ValueError, match="unknown task"):
        config_lib.task_config("push")
    with pytest.raises(ValueError, match="unknown touch variant"):
        config_lib.task_config("touch", variant="rough")
    with pytest.raises(ValueError, match="single variant"):
        config_lib.task_config("reach", variant="gentle")


# ----------------------------------------------------------------------------- reward


def test_seed_preset_weights() -> None:
    w = touch_config(variant="seed").reward.weights()
    assert tuple(w) == REWARD_TERMS
    assert (w["distance"], w["contact"], w["joint_limit"], w["joint_velocity"]) == (
        -10.0,
        500.0,
        -5.0,
        -0.1,
    )


def test_reward_hand_worked_touch_in_contact() -> None:
    """d = 0.03 m, 10 N, two joints beyond the soft limit, sum |qdot| = 2.5 rad/s."""
    cfg = touch_config(variant="seed")
    qpos = np.array([0.96, -0.97, 0.5, 0.0, 0.0, 0.94])  # 0.96 and -0.97 beyond 0.95
    qvel = np.array([1.0, -1.0, 0.5, 0.0, 0.0, 0.0])
    terms = terms_for(cfg, 0.03, 10.0, qpos, qvel)
    assert tuple(terms) == REWARD_TERMS
    assert float(terms["distance"]) == pytest.approx(1 - math.exp(-0.3))
    assert float(terms["contact"]) == 1.0
    assert float(terms["joint_limit"]) == 2.0
    assert float(terms["joint_velocity"]) == pytest.approx(2.5)
    assert float(terms["success"]) == 1.0
    assert float(terms["nonfinite"]) == 0.0
    expected = -10 * (1 - math.exp(-0.03 / 0.1)) + 500 * 1 - 5 * 2 - 0.1 * 2.5  # 487.158182
    assert float(reward_lib.total_reward(terms, cfg)) == pytest.approx(expected, abs=1e-9)
    assert expected == pytest.approx(487.158182, abs=1e-6)


def test_reward_hand_worked_touch_far_away() -> None:
    """d = 0.1 m (one length scale), no contact, arm at rest inside its limits."""
    cfg = touch_config(variant="seed")
    terms = terms_for(cfg, 0.1, 0.0)
    assert float(reward_lib.total_reward(terms, cfg)) == pytest.approx(-10 * (1 - math.exp(-1)))
    assert float(reward_lib.total_reward(terms, cfg)) == pytest.approx(-6.3212056, abs=1e-6)


def test_contact_term_needs_force_in_band_and_near() -> None:
    cfg = touch_config()
    assert float(terms_for(cfg, 0.03, 60.0)["contact"]) == 0.0  # pressing too hard
    assert float(terms_for(cfg, 0.08, 10.0)["contact"]) == 0.0  # pressing the box elsewhere
    assert float(terms_for(cfg, 0.03, 0.5)["contact"]) == 0.0  # grazing


def test_reach_has_no_contact_reward() -> None:
    cfg = reach_config()
    terms = terms_for(cfg, 0.01, 10.0)
    assert float(terms["contact"]) == 0.0
    expected = -10 * (1 - math.exp(-0.01 / 0.1))
    assert float(reward_lib.total_reward(terms, cfg)) == pytest.approx(expected)


def test_nonfinite_penalty_and_custom_weights() -> None:
    cfg = touch_config("seed", reward={"distance": -1.0, "nonfinite": -100.0, "success": 7.0})
    d, f = np.asarray(0.5), np.asarray(0.0)
    terms = reward_lib.reward_terms(
        np, d, f, np.zeros(6), np.zeros(6), UNIT_LIMITS, False, True, cfg
    )
    assert float(terms["nonfinite"]) == 1.0
    expected = -1.0 * (1 - math.exp(-5.0)) - 100.0
    assert float(reward_lib.total_reward(terms, cfg)) == pytest.approx(expected)


@pytest.mark.parametrize(
    ("distance", "force", "success"),
    [
        (0.0499, 1.0, True),  # lower force edge is inside the band
        (0.0499, 50.0, True),  # upper force edge is inside the band
        (0.0, 25.0, True),
        (0.0499, 0.999, False),
        (0.0499, 50.001, False),
        (0.05, 25.0, False),  # d < 0.05 is strict
        (0.0501, 25.0, False),
    ],
)
def test_touch_success_band_edges(distance: float, force: float, success: bool) -> None:
    flag = reward_lib.is_success(np, np.asarray(distance), np.asarray(force), touch_config())
    assert bool(flag) is success


@pytest.mark.parametrize(
    ("distance", "success"), [(0.0, True), (0.0199, True), (0.02, False), (0.0201, False)]
)
@pytest.mark.parametrize("force", [0.0, 75.0])  # force does not matter for Reach
def test_reach_success_band_edges(distance: float, force: float, success: bool) -> None:
    flag = reward_lib.is_success(np, np.asarray(distance), np.asarray(force), reach_config())
    assert bool(flag) is success


def test_success_and_reward_batched() -> None:
    cfg = touch_config()
    d = np.array([0.01, 0.01, 0.2])
    f = np.array([10.0, 0.0, 10.0])
    np.testing.assert_array_equal(reward_lib.is_success(np, d, f, cfg), [True, False, False])
    ee = np.array([[0.0, 0.0, 0.0], [0.3, 0.4, 0.0]])
    np.testing.assert_allclose(reward_lib.target_distance(np, ee, np.zeros(3)), [0.0, 0.5])


def test_gentle_terms_hand_worked() -> None:
    """A strike at 80 N while closing in at 0.6 m/s, with an action change of 0.5."""
    cfg = touch_config()
    d, f = np.asarray(0.03), np.asarray(80.0)
    motion = reward_lib.Motion(prev_distance=0.05, action_change=0.5)
    terms = reward_lib.reward_terms(
        np, d, f, np.zeros(6), np.zeros(6), UNIT_LIMITS, False, False, cfg, motion
    )
    assert float(terms["force_excess"]) == pytest.approx(30.0 / 50.0)
    assert float(terms["overforce"]) == 1.0
    assert float(terms["approach_speed"]) == pytest.approx(0.6**2)  # ((0.05 - 0.03) * 30)^2
    assert float(terms["action_rate"]) == 0.5
    assert float(terms["contact"]) == 0.0
    assert float(terms["proximity"]) == pytest.approx(math.exp(-3.0))  # 3 cm, length 1 cm
    expected = (
        -10 * (1 - math.exp(-0.3)) + 10 * math.exp(-3.0) - 100 * 0.6 - 10 * 0.36 - 0.05 * 0.5
    ) - 20 * 1.0  # -85.7189
    assert float(reward_lib.total_reward(terms, cfg)) == pytest.approx(expected, abs=1e-9)
    # moving away and far from the box: no approach term
    away = reward_lib.Motion(prev_distance=0.02, action_change=0.0)
    far = reward_lib.Motion(prev_distance=0.3, action_change=0.0)
    for dist, mot in ((0.03, away), (0.2, far)):
        t = reward_lib.reward_terms(
            np, np.asarray(dist), np.asarray(0.0), np.zeros(6), np.zeros(6), UNIT_LIMITS,
            False, False, cfg, mot,
        )  # fmt: skip
        assert float(t["approach_speed"]) == 0.0


def test_gentle_weights_make_a_hold_beat_hovering_and_tapping() -> None:
    """Per step: up to +10 near the target, +20 in the band; +1000 for the success.

    With the cpu/fast presets' discount 0.97, hovering at the target for the rest of an episode
    is worth at most 10 / 0.03 = 333, tapping (contact every other step) (10 + 20) / (1 - 0.97^2)
    + 10 / 0.03 < 850; a 3-step hold is worth over 1000.
    """
    w = touch_config().reward
    assert (w.distance, w.proximity, w.contact, w.success) == (-10.0, 10.0, 20.0, 1000.0)
    hover = w.proximity / (1 - 0.97)
    tap = (w.proximity + w.contact) / (1 - 0.97**2) + hover
    assert w.success > max(hover, tap)


def _run_rule(cfg, forces, distance=0.01):
    """Advance the success rule over a force sequence; (successes, overs, terminations)."""
    progress = reward_lib.start_progress(np)
    out = []
    for force in forces:
        progress, success, over = reward_lib.advance(
            np, progress, np.asarray(distance), np.asarray(force), cfg
        )
        done = reward_lib.ends_episode(bool(success), np.asarray(force), False, cfg)
        out.append((bool(success), bool(over), bool(done)))
    return out


def test_gentle_success_needs_a_hold_without_a_strike() -> None:
    cfg = touch_config()
    # three in-band steps in a row: success on the third
    assert [s for s, _, _ in _run_rule(cfg, [10, 10, 10])] == [False, False, True]
    # a gap resets the hold
    assert [s for s, _, _ in _run_rule(cfg, [10, 10, 0, 10, 10])] == [False] * 5
    # a reading over the band rules success out for the episode; over 100 N it also ends it
    assert (
        _run_rule(cfg, [10, 60, 10, 10, 10])
        == [(False, False, False)] + [(False, True, False)] + [(False, False, False)] * 3
    )
    assert _run_rule(cfg, [10, 120])[-1] == (False, True, True)
    keep_going = touch_config(terminate_on_overforce=False)
    assert [s for s, _, _ in _run_rule(keep_going, [60, 10, 10, 10, 10])] == [False] * 5
    # the seed variant: first in-band step, strikes allowed
    seed = touch_config("seed")
    assert _run_rule(seed, [60, 10]) == [(False, True, False), (True, False, True)]


def test_success_rule_batched_matches_single_envs() -> None:
    cfg = touch_config()
    forces = np.array([[10, 10, 10], [10, 60, 10], [0, 10, 10], [10, 10, 10]], float)
    distance = np.array([0.01, 0.01, 0.01, 0.07])
    progress = reward_lib.start_progress(np, (4,))
    for step in range(3):
        progress, success, _ = reward_lib.advance(np, progress, distance, forces[:, step], cfg)
    np.testing.assert_array_equal(success, [True, False, False, False])
    for i in range(4):
        single = _run_rule(cfg, forces[i], distance[i])
        assert single[-1][0] == bool(success[i])


# ----------------------------------------------------------------------------- observation


def make_obs(**overrides) -> dict:
    """An observation from hand-made physics quantities (defaults are benign)."""
    values = {
        "ee_pos": np.array([0.5, 0.1, 0.3]),
        "ee_quat": np.array([0.0, 1.0, 0.0, 0.0]),
        "qpos": np.zeros(6),
        "target_pos": np.array([0.5, 0.0, 0.05]),
        "wrench": np.zeros(6),
    }
    values.update(overrides)
    return obs_lib.assemble_obs(np, **values, force_clip=100.0)


def test_obs_key_order_pinned() -> None:
    expected = ("ee_pose", "joint_angles", "target_rel", "contact_force")
    assert expected == obs_lib.OBS_KEYS
    assert tuple(obs_lib.observation_space().spaces) == expected
    assert tuple(make_obs()) == expected
    assert [s.shape for s in obs_lib.observation_space().spaces.values()] == [
        (7,),
        (6,),
        (3,),
        (6,),
    ]
    assert obs_lib.OBS_SIZE == 22


def test_obs_float32_and_inside_space() -> None:
    space = obs_lib.observation_space()
    obs = make_obs()
    assert all(v.dtype == np.float32 for v in obs.values())
    assert space.contains(obs)
    assert obs_lib.flat_observation_space().contains(obs_lib.flatten_obs(np, obs))


def test_quaternion_sign_and_normalisation() -> None:
    quat = np.array([-0.5, 0.5, -0.5, 0.5]) * 2.0  # w < 0, not unit
    pose = make_obs(ee_quat=quat)["ee_pose"]
    np.testing.assert_allclose(pose[3:], [0.5, -0.5, 0.5, -0.5], atol=1e-7)
    assert pose[3] >= 0
    # w = 0 exactly is kept as is (either sign of the xyz part is the same rotation)
    np.testing.assert_allclose(make_obs()["ee_pose"][3:], [0.0, 1.0, 0.0, 0.0])


def test_angle_wrapping() -> None:
    qpos = np.array([3 * math.pi / 2, -3 * math.pi / 2, 7.0, -7.0, 0.25, 2 * math.pi + 0.1])
    expected = [-math.pi / 2, math.pi / 2, 7.0 - 2 * math.pi, -7.0 + 2 * math.pi, 0.25, 0.1]
    angles = make_obs(qpos=qpos)["joint_angles"]
    np.testing.assert_allclose(angles, expected, atol=1e-6)
    assert np.all(np.abs(angles) <= np.float32(math.pi))


def test_clipping_keeps_obs_inside_space() -> None:
    obs = make_obs(
        ee_pos=np.array([5.0, -5.0, 0.1]),
        target_pos=np.array([-3.0, 0.2, 9.0]),
        wrench=np.array([500.0, -500.0, 99.0, -1e6, 0.0, 100.5]),
    )
    np.testing.assert_allclose(obs["ee_pose"][:3], [2.0, -2.0, 0.1], rtol=1e-6)
    np.testing.assert_allclose(obs["target_rel"], [-2.0, 0.2, 2.0], rtol=1e-6)
    np.testing.assert_allclose(obs["contact_force"], [100, -100, 99, -100, 0, 100])
    assert obs_lib.observation_space().contains(obs)
    assert obs_lib.observation_space(force_clip=50.0).spaces["contact_force"].high[0] == 50.0


def test_flatten_unflatten_round_trip() -> None:
    obs = make_obs(qpos=np.arange(6) * 0.1, wrench=np.arange(6) - 2.0)
    flat = obs_lib.flatten_obs(np, obs)
    assert flat.shape == (22,) and flat.dtype == np.float32
    np.testing.assert_array_equal(flat[:7], obs["ee_pose"])
    np.testing.assert_array_equal(flat[16:], obs["contact_force"])
    back = obs_lib.unflatten_obs(flat)
    assert tuple(back) == obs_lib.OBS_KEYS
    for key in obs_lib.OBS_KEYS:
        np.testing.assert_array_equal(back[key], obs[key])
    # batched: (4, 22) <-> dict of (4, n)
    batch = np.stack([flat + i for i in range(4)])
    parts = obs_lib.unflatten_obs(batch)
    assert parts["target_rel"].shape == (4, 3)
    np.testing.assert_array_equal(obs_lib.flatten_obs(np, parts), batch)


def test_random_obs_always_inside_space() -> None:
    rng = np.random.default_rng(0)
    space = obs_lib.observation_space()
    for _ in range(200):
        obs = make_obs(
            ee_pos=rng.normal(0, 2, 3),
            ee_quat=rng.normal(size=4),
            qpos=rng.uniform(-20, 20, 6),
            target_pos=rng.normal(0, 2, 3),
            wrench=rng.normal(0, 200, 6),
        )
        assert space.contains(obs), obs


# ----------------------------------------------------------------------------- sampling


@pytest.mark.parametrize("preset", [reach_config, touch_config])
def test_sampling_inside_bounds(preset) -> None:
    cfg = preset().for_arm(SHIPPED_HOME_QPOS, 1.0)
    rng = np.random.default_rng(1)
    u = rng.uniform(size=(500, sampling.n_uniforms(6)))
    u[0], u[1] = 0.0, np.nextafter(1.0, 0.0)  # the edges of [0, 1)
    qpos = sampling.initial_qpos(np, u[:, :6], cfg)
    assert qpos.shape == (500, 6)
    home = np.asarray(cfg.home_qpos)
    assert np.all(np.abs(qpos - home) <= cfg.init_noise + 1e-12)
    np.testing.assert_allclose(qpos[0], home - cfg.init_noise)
    body = sampling.target_body_pos(np, u[:, 6:], cfg)
    low, high = np.asarray(cfg.target_low), np.asarray(cfg.target_high)
    point = sampling.target_point(np, body, cfg)
    if cfg.uses_contact:  # the box stands on the table; the target is its top face
        assert np.all(body[:, 2] == 0.0)
        assert np.all((body[:, :2] >= low[:2]) & (body[:, :2] <= high[:2]))
        np.testing.assert_allclose(point[:, 2], box_top_offset())
    else:
        assert np.all((body >= low) & (body <= high))
        np.testing.assert_array_equal(point, body)
    np.testing.assert_allclose(point[:, :2], body[:, :2])


# ----------------------------------------------------------------------------- wrench


def hand_tool(ee_rot: np.ndarray | None = None) -> ToolInertia:
    """A 1.5 kg tool, centre of mass off the sensor axis, tip 0.2 m below the sensor."""
    return ToolInertia(
        mass=1.5,
        com=np.array([0.02, -0.01, 0.08]),
        inertia=np.diag([0.004, 0.005, 0.002]),
        ee_pos=np.array([0.0, 0.0, 0.2]),
        ee_rot=np.eye(3) if ee_rot is None else ee_rot,
    )


def free_motion_reading(tool: ToolInertia, world_to_sensor: np.ndarray, omega, alpha, a_c):
    """What a wrist sensor and an accelerometer read when only the arm and gravity act.

    Newton-Euler with no external load: the arm supplies ``m (a_c - g)`` and the torque that
    gives the tool its angular acceleration. Everything in the sensor frame.
    """
    g = world_to_sensor @ GRAVITY
    acc = a_c - g
    force = tool.mass * acc
    i = tool.inertia
    torque = i @ alpha + np.cross(omega, i @ omega) + np.cross(tool.com, force)
    return force, torque, acc


@pytest.mark.parametrize("tilt", [0.0, 0.7, math.pi])
def test_wrench_reads_zero_at_rest_under_gravity(tilt: float) -> None:
    tool = hand_tool()
    r = rot_x(tilt) @ rot_z(0.3)
    zero = np.zeros(3)
    force, torque, acc = free_motion_reading(tool, r, zero, zero, zero)
    assert np.linalg.norm(force) == pytest.approx(1.5 * 9.81)  # the sensor feels the weight
    wrench = external_wrench(np, force, torque, acc, zero, zero, tool)
    assert wrench.shape == (6,)
    np.testing.assert_allclose(wrench, 0.0, atol=1e-12)


def test_wrench_reads_zero_in_free_motion() -> None:
    tool = hand_tool(ee_rot=rot_z(0.4))
    omega, alpha, a_c = np.array([0.5, -1.0, 2.0]), np.array([3.0, 1.0, -2.0]), np.array([1, 2, 3])
    force, torque, acc = free_motion_reading(tool, rot_x(0.2), omega, alpha, a_c)
    wrench = external_wrench(np, force, torque, acc, omega, alpha, tool)
    np.testing.assert_allclose(wrench, 0.0, atol=1e-12)


def test_wrench_known_force_at_the_tip() -> None:
    """20 N pushing up on a point 1 cm beside the tip, tool at rest, ee frame turned 90 deg."""
    tool = hand_tool(ee_rot=rot_z(math.pi / 2))
    zero = np.zeros(3)
    f_ext = np.array([0.0, 0.0, -20.0])
    contact = tool.ee_pos + np.array([0.01, 0.0, 0.0])
    weight = tool.mass * GRAVITY  # sensor frame = world frame here
    # static balance: the sensor force and torque cancel weight and contact
    force_s = -weight - f_ext
    torque_s = -np.cross(tool.com, weight) - np.cross(contact, f_ext)
    acc = -GRAVITY
    wrench = external_wrench(np, force_s, torque_s, acc, zero, zero, tool)
    # sensor frame: F = (0, 0, -20) and, about the tip, tau = (0.01, 0, 0) x F = (0, 0.2, 0);
    # ee frame: v_ee = ee_rot @ v_s (a +90 deg turn about z maps (0, 0.2, 0) to (-0.2, 0, 0))
    rot = rot_z(math.pi / 2)
    np.testing.assert_allclose(wrench[:3], rot @ f_ext, atol=1e-12)
    np.testing.assert_allclose(wrench[3:], rot @ np.array([0.0, 0.2, 0.0]), atol=1e-12)
    np.testing.assert_allclose(wrench, [0, 0, -20, -0.2, 0, 0], atol=1e-12)


def test_wrench_batched() -> None:
    tool = hand_tool()
    zero = np.zeros(3)
    force, torque, acc = free_motion_reading(tool, np.eye(3), zero, zero, zero)
    push = np.array([0.0, 0.0, 5.0])  # 5 N external, acting at the sensor point
    batch = external_wrench(
        np,
        np.stack([force, force - push]),
        np.stack([torque, torque]),
        np.stack([acc, acc]),
        np.zeros((2, 3)),
        np.zeros((2, 3)),
        tool,
    )
    assert batch.shape == (2, 6)
    np.testing.assert_allclose(batch[0], 0.0, atol=1e-12)
    np.testing.assert_allclose(batch[1, :3], push, atol=1e-12)
    # a force through the sensor point has a moment about the tip 0.2 m below it: r x F = 0 (on z)
    np.testing.assert_allclose(batch[1, 3:], 0.0, atol=1e-12)


def test_tool_inertia_of_shipped_arm() -> None:
    from mjx_arm.paths import default_arm_urdf
    from mjx_arm.urdf.model import parse_urdf

    tool = tool_inertia(parse_urdf(default_arm_urdf()), "tool_link", "ee_link")
    assert tool.mass == pytest.approx(0.201)  # tool_link 0.2 kg + ee_link 1 g
    np.testing.assert_allclose(tool.com, [0, 0, (0.2 * 0.05 + 0.001 * 0.115) / 0.201])
    np.testing.assert_allclose(tool.ee_pos, [0, 0, 0.115])
    np.testing.assert_allclose(tool.ee_rot, np.eye(3))
    assert np.all(np.linalg.eigvalsh(tool.inertia) > 0)


# ----------------------------------------------------------------------------- jax.numpy


def test_same_code_under_jax_numpy() -> None:
    """Reward, success, observation and wrench give the numpy values under jax.numpy."""
    jnp = pytest.importorskip("jax.numpy")
    cfg = touch_config(variant="seed")
    qpos = np.array([0.96, -0.97, 0.5, 0.0, 0.0, 0.94])
    qvel = np.array([1.0, -1.0, 0.5, 0.0, 0.0, 0.0])
    t_np = terms_for(cfg, 0.03, 10.0, qpos, qvel)
    t_jx = terms_for(cfg, 0.03, 10.0, qpos, qvel, xp=jnp)
    for name in REWARD_TERMS:
        assert float(t_jx[name]) == pytest.approx(float(t_np[name]), rel=1e-6)
    assert float(reward_lib.total_reward(t_jx, cfg)) == pytest.approx(487.158182, rel=1e-6)

    inputs = {
        "ee_pos": np.array([5.0, 0.1, 0.3]),
        "ee_quat": np.array([-0.5, 0.5, -0.5, 0.5]),
        "qpos": np.array([3 * math.pi / 2, 0.1, -7.0, 0.0, 1.0, 2.0]),
        "target_pos": np.array([0.5, 0.0, 0.05]),
        "wrench": np.array([500.0, 0.0, 1.0, 0.0, 0.0, -200.0]),
    }
    o_np = obs_lib.assemble_obs(np, **inputs, force_clip=100.0)
    o_jx = obs_lib.assemble_obs(
        jnp, **{k: jnp.asarray(v) for k, v in inputs.items()}, force_clip=100.0
    )
    assert tuple(o_jx) == obs_lib.OBS_KEYS
    for key in obs_lib.OBS_KEYS:
        assert o_jx[key].dtype == jnp.float32
        np.testing.assert_allclose(np.asarray(o_jx[key]), o_np[key], atol=1e-5)
    flat = obs_lib.flatten_obs(jnp, o_jx)
    assert flat.shape == (22,)

    tool = hand_tool(ee_rot=rot_z(0.4))
    omega, alpha, a_c = np.array([0.5, -1.0, 2.0]), np.array([3.0, 1.0, -2.0]), np.ones(3)
    force, torque, acc = free_motion_reading(tool, rot_x(0.2), omega, alpha, a_c)
    args = [force - np.array([1.0, 2.0, 3.0]), torque, acc, omega, alpha]
    w_np = external_wrench(np, *args, tool)
    w_jx = external_wrench(jnp, *[jnp.asarray(a) for a in args], tool)
    np.testing.assert_allclose(np.asarray(w_jx), w_np, atol=1e-4)
    np.testing.assert_allclose(w_np[:3], rot_z(0.4) @ np.array([1.0, 2.0, 3.0]), atol=1e-12)


def test_tare_asks_jax_for_full_float32_precision() -> None:
    """Under JAX the tare's matrix product asks for full float32 precision: JAX's default lets
    a GPU round float32 operands to TF32, which left a tared free-motion reading of 2.4 to
    4.5 mN on an H100 and an H200 (1e-6 N in float32). A CPU computes float32 either way, so
    the request is checked in the lowered program, and the values against numpy's float64."""
    import jax
    import jax.numpy as jnp

    tool = hand_tool(ee_rot=rot_z(0.4))
    rng = np.random.default_rng(0)
    block = rng.uniform(-10.0, 10.0, (4, SENSOR_BLOCK_SIZE))
    block[:, -4:] /= np.linalg.norm(block[:, -4:], axis=1, keepdims=True)  # unit quaternion
    lowered = {
        "sensor": jax.jit(lambda b: sensor_wrench(jnp, b, tool)).lower(jnp.asarray(block)),
        "parts": jax.jit(lambda *a: external_wrench(jnp, *a, tool)).lower(*[jnp.ones(3)] * 5),
    }
    for name, program in lowered.items():
        dots = [line for line in program.as_text().splitlines() if "dot_general" in line]
        assert dots and all("precision = [HIGHEST, HIGHEST]" in d for d in dots), (name, dots)
    w_jx = jax.jit(lambda b: sensor_wrench(jnp, b, tool))(jnp.asarray(block, jnp.float32))
    want = sensor_wrench(np, block, tool)  # up to 22 N
    np.testing.assert_allclose(np.asarray(w_jx), want, atol=1e-4)  # measured 1.7e-6


@pytest.mark.parametrize(("hold", "expected"), [(0, 0.0), (1, 0.0), (2, 0.5), (3, 1.0), (7, 1.0)])
def test_streak_pays_for_a_press_that_holds(hold: int, expected: float) -> None:
    """Gentle Touch holds 3 steps: a one-step tap earns no streak, the second step in a row
    half, the third (the success step) all of it; numpy and JAX agree."""
    import jax.numpy as jnp

    cfg = touch_config()
    assert cfg.success_hold_steps == 3
    assert float(reward_lib.streak(np, np.asarray(float(hold)), cfg)) == expected
    assert float(reward_lib.streak(jnp, jnp.asarray(float(hold)), cfg)) == expected
    # in the reward: streak weight times the term, on top of the in-band contact pay
    motion = reward_lib.Motion(prev_distance=0.01, action_change=0.0, hold=float(hold))
    terms = reward_lib.reward_terms(
        np, np.asarray(0.01), np.asarray(10.0), np.zeros(6), np.zeros(6), UNIT_LIMITS,
        False, False, cfg, motion,
    )  # fmt: skip
    assert float(terms["streak"]) == expected
    assert cfg.reward.streak == 50.0


def test_streak_is_zero_where_one_step_succeeds() -> None:
    cfg = touch_config("seed")
    assert cfg.success_hold_steps == 1
    assert float(reward_lib.streak(np, np.asarray(5.0), cfg)) == 0.0


def test_the_strike_term_marks_the_step_a_strike_ends() -> None:
    """The ``strike`` term is 1 only on a reading over the strike limit of gentle Touch (the
    step that ends the episode), in numpy and JAX, and its weight adds to the reward; Reach and
    the seed variant of Touch (no protective stop) never set it. The shipped weight is 0: a
    charge of -400 was measured and dropped (docs/training.md)."""
    import jax.numpy as jnp

    cfg = touch_config()
    assert cfg.reward.strike == 0.0
    limit = reward_lib.strike_limit(cfg)
    for xp in (np, jnp):
        forces = xp.asarray([0.0, 30.0, 60.0, limit, limit + 0.5])
        terms = reward_lib.reward_terms(
            xp, xp.full(5, 0.01), forces, xp.zeros((5, 6)), xp.zeros((5, 6)), UNIT_LIMITS,
            xp.zeros(5, dtype=bool), xp.zeros(5, dtype=bool), cfg,
        )  # fmt: skip
        np.testing.assert_array_equal(np.asarray(terms["strike"]), [0, 0, 0, 0, 1])
    charged = cfg.replace(reward=dataclasses.replace(cfg.reward, strike=-400.0))
    struck = {name: np.asarray(v)[4] for name, v in terms.items()}
    gap = reward_lib.total_reward(struck, charged) - reward_lib.total_reward(struck, cfg)
    assert float(gap) == pytest.approx(-400.0)
    for other in (reach_config(), touch_config("seed")):
        terms = reward_lib.reward_terms(
            np, np.asarray(0.01), np.asarray(500.0), np.zeros(6), np.zeros(6), UNIT_LIMITS,
            False, False, other,
        )  # fmt: skip
        assert float(terms["strike"]) == 0.0


def test_the_press_term_peaks_in_the_middle_of_the_band() -> None:
    """``press`` is 1 at the middle of Touch's band (25.5 N of 1-50 N), falls linearly to 0 at
    both ends, is 0 outside the band and away from the target (beyond ``success_distance``), in
    numpy and JAX; it ships at weight 0."""
    import jax.numpy as jnp

    cfg = touch_config()
    assert cfg.reward.press == 0.0
    low, high = cfg.force_band
    middle = 0.5 * (low + high)
    forces = [0.0, low, 0.5 * (low + middle), middle, 0.5 * (middle + high), high, high + 5.0]
    want = [0.0, 0.0, 0.5, 1.0, 0.5, 0.0, 0.0]
    for xp in (np, jnp):
        for distance, scale in ((0.01, 1.0), (cfg.success_distance + 0.01, 0.0)):
            n = len(forces)
            terms = reward_lib.reward_terms(
                xp, xp.full(n, distance), xp.asarray(forces), xp.zeros((n, 6)),
                xp.zeros((n, 6)), UNIT_LIMITS, xp.zeros(n, dtype=bool), xp.zeros(n, dtype=bool),
                cfg,
            )  # fmt: skip
            np.testing.assert_allclose(np.asarray(terms["press"]), np.asarray(want) * scale,
                                       atol=1e-6)  # fmt: skip
