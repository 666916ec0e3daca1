"""Lift: the gripper task in CPU MuJoCo, PyBullet and MJX, its observation, rules and model."""

from __future__ import annotations

import numpy as np
import pytest
from lift_script import run_scripted_lift

from mjx_arm.arm.model_io import arm_model
from mjx_arm.envs.base import action_size
from mjx_arm.envs.mujoco_env import MujocoArmEnv
from mjx_arm.paths import asset
from mjx_arm.task import lift as lift_lib
from mjx_arm.task.grip import ObjectStart
from mjx_arm.task.lift import LIFT_HEIGHT, lift_config
from mjx_arm.task.observation import obs_size
from mjx_arm.train.presets import load_config, preset_config
from mjx_arm.urdf.scene_shapes import CUBE_HALF

GRIPPER = str(asset("ur5e_gripper.urdf"))


@pytest.fixture(scope="module")
def mujoco_env():
    env = MujocoArmEnv(lift_config(), GRIPPER)
    yield env
    env.close()


def test_spaces_add_the_gripper(mujoco_env):
    """7 actions (6 joints and the gripper); the observation adds gripper, object and pads."""
    env = mujoco_env
    assert env.action_space.shape == (7,) == (action_size(env.arm, env.task),)
    keys = list(env.observation_space.spaces)
    assert keys[-3:] == ["gripper", "object_rel", "pad_force"]
    assert obs_size(6, env.task.spec.extra_obs) == 32
    obs, _ = env.reset(seed=3)
    assert env.observation_space.contains(obs)
    assert obs["gripper"][0] == pytest.approx(0.0, abs=1e-6)  # starts open
    np.testing.assert_allclose(obs["pad_force"], 0.0, atol=1e-6)


def test_cube_starts_at_rest_on_the_table(mujoco_env):
    """The cube rests on the table (centre at its half edge) inside the target box, at the
    drawn yaw; the target point is the cube's centre."""
    env = mujoco_env
    for seed in range(5):
        obs, info = env.reset(seed=seed)
        cube = obs["target_rel"]
        assert cube[2] == pytest.approx(CUBE_HALF, abs=1e-6)
        low, high = env.task.target_box()
        assert low[0] - 1e-6 <= cube[0] <= high[0] + 1e-6
        assert low[1] - 1e-6 <= cube[1] <= high[1] + 1e-6
        for _ in range(5):
            obs, _, _, _, info = env.step(np.zeros(7))
        assert abs(info["height"]) < 1e-3  # still resting
        assert info["grasp"] == 0.0


def test_model_steps_at_480_hz_with_240_hz_servo_gains(mujoco_env):
    """The physics steps at 1/480 s; the servo gains are those of the 240 Hz model."""
    env = mujoco_env
    assert env.model.opt.timestep == pytest.approx(1 / 480)
    reach = arm_model(env.arm, env.task.replace(task="reach", sim_dt=1 / 240))
    for name in (*env.arm.joint_names, env.arm.gripper.joint):
        assert env.model.actuator(name).gainprm[0] == reach.actuator(name).gainprm[0]


def test_cube_mass_and_friction_are_drawn_per_episode(mujoco_env):
    """Each episode draws the cube's mass and friction inside the task's ranges; the model
    carries them (friction on the cube and both pads) with the constants MuJoCo derives from
    the mass, as ``mj_setConst`` recomputes them."""
    import copy

    import mujoco

    env, grip = mujoco_env, mujoco_env.grip
    masses = []
    for seed in range(6):
        env.reset(seed=seed)
        mass = env.model.body_mass[grip.cube_body]
        masses.append(mass)
        assert lift_lib.CUBE_MASS_RANGE[0] <= mass <= lift_lib.CUBE_MASS_RANGE[1]
        friction = env.model.geom_friction[grip.friction_geoms, 0]
        assert len(friction) == 3 and np.ptp(friction) == 0.0
        assert lift_lib.FRICTION_RANGE[0] <= friction[0] <= lift_lib.FRICTION_RANGE[1]
    assert np.ptp(masses) > 0.02
    fresh = copy.deepcopy(env.model)
    mujoco.mj_setConst(fresh, mujoco.MjData(fresh))
    for name in ("body_invweight0", "dof_invweight0", "dof_M0", "body_subtreemass"):
        np.testing.assert_allclose(getattr(env.model, name), getattr(fresh, name), rtol=1e-9)


@pytest.mark.parametrize("engine", ["mujoco", "pybullet"])
def test_scripted_pick_holds_the_heaviest_cube(engine):
    """The scripted pick succeeds with the heaviest, most slippery cube of the ranges."""
    from pybullet_ref.env import PybulletArmEnv

    cls = MujocoArmEnv if engine == "mujoco" else PybulletArmEnv
    env = cls(lift_config(), GRIPPER)
    try:
        mass, friction = lift_lib.CUBE_MASS_RANGE[1], lift_lib.FRICTION_RANGE[0]
        result = run_scripted_lift(env, 1, object_mass=mass, object_friction=friction)
        assert result["success"], result["info"]
    finally:
        env.close()


def test_pads_have_touch_sensors(mujoco_env):
    """Each finger link gets a touch sensor over its collision box."""
    names = [mujoco_env.model.sensor(i).name for i in range(mujoco_env.model.nsensor)]
    for link in mujoco_env.arm.gripper.pad_links:
        assert f"{link}_touch" in names


@pytest.mark.parametrize("engine", ["mujoco", "pybullet"])
def test_scripted_pick_succeeds(engine):
    """A scripted pick (over the cube, down, close, lift) succeeds within the episode in each
    CPU engine: the cube ends at least LIFT_HEIGHT up, held by both pads, and the wrist reads
    the cube's weight (about 1 N), not the grip."""
    if engine == "mujoco":
        env = MujocoArmEnv(lift_config(), GRIPPER)
    else:
        from pybullet_ref.env import PybulletArmEnv

        env = PybulletArmEnv(lift_config(), GRIPPER)
    try:
        for seed in (0, 1):
            result = run_scripted_lift(env, seed)
            info = result["info"]
            assert result["success"], (engine, seed, info)
            assert result["steps"] < env.task.episode_steps
            assert info["height"] >= LIFT_HEIGHT and info["grasp"] == 1.0
            assert info["contact_force_norm"] < 3.0
    finally:
        env.close()


def test_success_needs_height_and_both_pads():
    """The step condition: LIFT_HEIGHT up and grasped; either alone is not enough."""
    task, cfg = lift_lib.LIFT, lift_config()
    height = np.array([0.12, 0.12, 0.05])
    grasp = np.array([1.0, 0.0, 1.0])
    holds = task.holds(np, 0.0 * height, 0.0 * height, cfg, {"height": height, "grasp": grasp})
    assert holds.tolist() == [True, False, False]


def test_held_lift_pays_the_height_only_while_both_pads_hold_the_cube():
    """``held_lift`` is ``lift`` (the height over LIFT_HEIGHT, capped at 1) where grasped and 0
    where not; every preset weighs it 0, so no preset's reward changes."""
    task = lift_lib.LIFT
    height = np.array([0.15, 0.15, 0.05, -0.02])
    extra = {"height": height, "grasp": np.array([1.0, 0.0, 1.0, 1.0]),
             "cradle": 0.0 * height, "stray": 0.0 * height}  # fmt: skip
    terms = task.task_terms(np, extra, 0.0 * height)
    np.testing.assert_allclose(terms["lift"], [1.0, 1.0, 0.5, 0.0], atol=1e-12)
    np.testing.assert_allclose(terms["held_lift"], [1.0, 0.0, 0.5, 0.0], atol=1e-12)
    for preset in ("fast", "robust", "cpu"):
        assert preset_config(preset, "lift").task_settings.reward.held_lift == 0.0
    sets = ["task=lift", "task.reward.lift=0", "task.reward.held_lift=20"]
    reward = load_config("fast", overrides=sets).task_settings.reward
    assert (reward.lift, reward.held_lift) == (0, 20)


def test_grasp_needs_the_cube_between_the_pads():
    """Both pads pressing count as a grasp only with the cube's centre near the ee point (a
    gripper closed on nothing, pressing the table, is no grasp)."""
    task, cfg = lift_lib.LIFT, lift_config()
    ee, quat = np.zeros((2, 3)), np.tile([1.0, 0.0, 0.0, 0.0], (2, 1))
    grip = np.zeros((2, 10))
    grip[:, 4] = 1.0  # cube quaternion w
    grip[:, 8:] = 5.0  # both pads press
    grip[0, 1:4] = [0.0, 0.0, 0.01]  # the cube between the pads
    grip[1, 1:4] = [0.0, 0.0, 0.10]  # the cube 10 cm away
    measures = task.measures(np, ee, quat, grip, cfg)
    assert measures["grasp"].tolist() == [1.0, 0.0]


def test_grasp_needs_the_gripper_closed_as_far_as_its_gate():
    """With ``grasp_closure`` set, both pads pressing around the cube count as a grasp only
    from that closure on (pads pressing with the gripper more open press something else, as
    the table under an open hand); 0 (a config with no arm) asks for nothing."""
    task = lift_lib.LIFT
    ee, quat = np.zeros((3, 3)), np.tile([1.0, 0.0, 0.0, 0.0], (3, 1))
    grip = np.zeros((3, 10))
    grip[:, 0] = [0.0, 0.34, 0.36]  # closure: open, just under the gate, just over it
    grip[:, 4] = 1.0  # cube quaternion w
    grip[:, 1:4] = [0.0, 0.0, 0.01]  # the cube between the pads
    grip[:, 8:] = 5.0  # both pads press
    gated = task.measures(np, ee, quat, grip, lift_config(grasp_closure=0.35))["grasp"]
    assert gated.tolist() == [0.0, 0.0, 1.0]
    assert task.measures(np, ee, quat, grip, lift_config())["grasp"].tolist() == [1.0] * 3


def test_the_gate_stands_the_pads_a_centimetre_wider_than_the_cube():
    """Each gripper class's derived ``grasp_closure``: the closure at which its pads stand
    GRASP_SLACK wider apart than its Lift cube (the shipped prismatic fingers: 1 - 5.5/8.5,
    linear; a linkage and a jaw from their kinematics), and a real grasp closes past it (the
    shipped arm's Lift policy holds the cube up at 0.46-0.50)."""
    from mjx_arm.arm.info import arm_info
    from mjx_arm.arm.resolve import task_for_arm

    arm = arm_info(asset("ur5e_gripper.urdf"))
    task = task_for_arm(lift_config(), arm)
    assert task.grasp_closure == pytest.approx(1.0 - 0.055 / 0.085, abs=1e-3)
    for name in ("ur5e_2f85.urdf", "ur5e_xarm_gripper.urdf"):
        arm = arm_info(asset(name))
        task = task_for_arm(lift_config(), arm)
        closures, gaps = zip(*arm.gripper.closure_gaps, strict=True)
        gap = np.interp(task.grasp_closure, closures, gaps)
        assert gap == pytest.approx(2 * CUBE_HALF + lift_lib.GRASP_SLACK, abs=1e-4), name
        assert 0.3 < task.grasp_closure < 0.45, name
    assert task_for_arm(lift_config(grasp_closure=0.2), arm).grasp_closure == 0.2  # as set


def test_cradle_pays_the_closure_only_with_the_cube_between_the_pads():
    """``cradle`` is the closure while the cube's centre is within a half edge of the ee point:
    fingers closing around the cube are paid, fingers closed on its top face (the ee point
    3 cm above its centre) or far from it are not; it weighs in Lift's reward."""
    task, cfg = lift_lib.LIFT, lift_config()
    ee, quat = np.zeros((3, 3)), np.tile([1.0, 0.0, 0.0, 0.0], (3, 1))
    grip = np.zeros((3, 10))
    grip[:, 0] = [0.4, 1.0, 1.0]  # closure
    grip[:, 4] = 1.0  # cube quaternion w
    grip[0, 1:4] = [0.01, 0.0, 0.005]  # the cube between the pads, a little off centre
    grip[1, 1:4] = [0.0, 0.0, -0.03]  # the cube under fingers closed on its top
    grip[2, 1:4] = [0.2, 0.0, 0.0]  # far away
    cradle = task.measures(np, ee, quat, grip, cfg)["cradle"]
    np.testing.assert_allclose(cradle, [0.4, 0.0, 0.0], atol=1e-12)
    assert cfg.reward.cradle > 0


def test_stray_marks_a_finger_pressing_with_the_cube_not_between_the_pads():
    """``stray`` is 1 where a pad presses (0.5 N or more) while the cube's centre is a half edge
    or more from the ee point: a fingertip on the cube's top (centre 4.7 cm below the ee
    point) or a finger on the table, not a grasp around the cube nor fingers touching nothing."""
    task, cfg = lift_lib.LIFT, lift_config()
    ee, quat = np.zeros((4, 3)), np.tile([1.0, 0.0, 0.0, 0.0], (4, 1))
    grip = np.zeros((4, 10))
    grip[:, 4] = 1.0  # cube quaternion w
    grip[:, 1:4] = [[0.0, 0.0, -0.047], [0.2, 0.0, -0.1], [0.005, 0.0, 0.0], [0.0, 0.0, -0.047]]
    grip[:, 8:] = [[3.0, 0.0], [0.0, 0.6], [5.0, 5.0], [0.4, 0.0]]  # pad forces (N)
    stray = task.measures(np, ee, quat, grip, cfg)["stray"]
    np.testing.assert_array_equal(stray, [1.0, 1.0, 0.0, 0.0])
    assert cfg.reward.stray < 0  # a charge in Lift's reward


def test_soft_variant_charges_from_25_n_and_the_touchdown_speed():
    """``variant="soft"``: a 40 N wrist reading costs 0.6 of the band's top (gentle: nothing,
    its band ends at 50 N), ``approach_speed`` weighs -20; every other field is the preset's."""
    from mjx_arm.task import reward as reward_lib

    gentle, soft = lift_config(), lift_config(variant="soft")
    assert reward_lib.force_excess(np, 40.0, gentle) == 0.0
    assert reward_lib.force_excess(np, 40.0, soft) == pytest.approx(15.0 / 25.0)
    assert soft.reward.approach_speed == -20.0 and gentle.reward.approach_speed == 0.0
    same = soft.replace(variant="gentle", force_band=gentle.force_band, reward=gentle.reward)
    assert same == gentle
    with pytest.raises(ValueError, match="unknown lift variant"):
        lift_config(variant="seed")


def test_task_solver_iterations_reach_the_model():
    """``solver_iterations`` / ``ls_iterations`` set the task model's solver (Lift's preset:
    4 and 8); 0 keeps the converter's 2 and 4."""
    from mjx_arm.arm.info import arm_info

    arm = arm_info(GRIPPER)
    model = arm_model(arm, lift_config(solver_iterations=6, ls_iterations=12))
    assert (model.opt.iterations, model.opt.ls_iterations) == (6, 12)
    model = arm_model(arm, lift_config())
    assert (model.opt.iterations, model.opt.ls_iterations) == (4, 8)
    model = arm_model(arm, lift_config(solver_iterations=0, ls_iterations=0))
    assert (model.opt.iterations, model.opt.ls_iterations) == (2, 4)


def test_lift_needs_a_gripper_arm():
    """Lift on the arm without a gripper is a named error that points at the gripper arm;
    without an arm it runs on the gripper arm."""
    with pytest.raises(ValueError, match=r"needs an arm with a gripper.*ur5e_gripper"):
        MujocoArmEnv(lift_config(), asset("ur5e.urdf"))
    env = MujocoArmEnv(lift_config())
    assert env.arm.gripper is not None
    env.close()


def test_gymnasium_id():
    """``mjx_arm/Lift-v0`` makes the Lift env on the gripper arm in both CPU engines."""
    import gymnasium as gym

    from mjx_arm.envs.registration import register_envs

    register_envs()
    for engine in ("mujoco", "pybullet"):
        env = gym.make("mjx_arm/Lift-v0", engine=engine)
        obs, _ = env.reset(seed=0)
        assert env.action_space.shape == (7,) and obs["object_rel"].shape == (7,)
        env.close()


def test_presets_train_the_gripper_arm():
    """A gripper task's presets train the gripper arm; the others the shipped arm."""
    assert preset_config("fast", "lift").arm.urdf.endswith("ur5e_gripper.urdf")
    assert preset_config("fast", "touch").arm.urdf == ""


def test_c_batch_steps_lift():
    """The C batch steps the gripper: the cube starts where the episode puts it, at rest, the
    fingers open, and the episode's cube mass and friction reach the row's model."""
    import jax
    import jax.numpy as jnp

    from mjx_arm.envs.mjx_env import MjxArmEnv
    from mjx_arm.envs.mujoco_batch import MujocoCallbackPhysics

    env = MjxArmEnv(lift_config(), GRIPPER, physics_factory=MujocoCallbackPhysics)
    state = jax.jit(env.reset)(jax.random.PRNGKey(0))
    physics = env.physics
    reading = physics.read(state.pipeline_state)
    assert reading.grip.shape == (10,)
    assert float(reading.grip[0]) < 0.05  # open
    params = state.info["task"].object_params
    state = jax.jit(env.step)(state, jnp.zeros(env.action_size))
    after = physics.read(state.pipeline_state)
    np.testing.assert_allclose(
        np.asarray(after.target_pos), np.asarray(reading.target_pos), atol=2e-3
    )
    model = physics.stepper.copies.models[0]
    grip = physics.grip
    assert model.body_mass[grip.cube_body] == pytest.approx(float(params[0]), rel=1e-5)
    assert model.geom_friction[grip.friction_geoms[0], 0] == pytest.approx(
        float(params[1]), rel=1e-5
    )


@pytest.mark.slow
def test_mjx_reset_matches_cpu_mujoco():
    """MJX (JAX) and CPU MuJoCo start a Lift episode with the same observation layout and, for
    the same cube and arm pose, the same values (float32 tolerance)."""
    import jax
    import jax.numpy as jnp

    from mjx_arm.envs.mjx_env import MjxArmEnv
    from mjx_arm.envs.physics_config import PhysicsConfig

    env = MjxArmEnv(lift_config(), GRIPPER, physics=PhysicsConfig(impl="jax"))
    state = jax.jit(env.reset)(jax.random.PRNGKey(0))
    assert state.obs.shape == (env.observation_size,) == (32,)
    qpos = state.pipeline_state.qpos
    cpu = MujocoArmEnv(lift_config(), GRIPPER)
    start = env.physics.grip.cube_qpos
    cube, quat = np.asarray(qpos[start : start + 3]), np.asarray(qpos[start + 3 : start + 7])
    arm = np.asarray(qpos[np.asarray(env.physics.ids.qpos_adr)])
    mass, friction = np.asarray(state.info["task"].object_params)
    assert 0.05 <= mass <= 0.2 and 0.8 <= friction <= 1.0
    cpu.reset(seed=0)
    cpu._physics_reset(arm, cube, ObjectStart(quat, mass, friction))
    obs = cpu._evaluate(cpu._physics_read())[0]
    flat = np.concatenate(list(obs.values()))
    np.testing.assert_allclose(np.asarray(state.obs), flat, atol=2e-4)
    step = jax.jit(env.step)
    state = step(state, jnp.zeros(7))
    assert float(state.metrics["lift_height"]) == pytest.approx(0.0, abs=1e-3)


def test_gripper_passthrough_rate_limits_the_target():
    """The finger target moves at most v_max * speed_scale per second, inside the travel;
    faster commands are clipped and counted, a non-finite one raises."""
    from mjx_arm.sim2real.gripper import GripperConfig, GripperPassthrough

    chain = GripperPassthrough(0.0, 0.0425, 0.15, 1 / 30, GripperConfig(speed_scale=0.5))
    chain.reset(-1.0)
    assert chain.target == 0.0  # a start outside the travel is brought inside it
    assert chain.step(0.05) == pytest.approx(0.05 / 30, abs=1e-12)
    assert chain.clips == 0
    assert chain.step(1.0) == pytest.approx(0.05 / 30 + 0.075 / 30, abs=1e-12)
    assert chain.clips == 1
    for _ in range(30):
        chain.step(0.075)
    assert chain.target == 0.0425  # held at the closed end
    assert chain.servo_speed(0.0) == pytest.approx(0.15)  # the stand-in's loop, capped
    with pytest.raises(ValueError, match="not finite"):
        chain.step(float("nan"))


def test_position_chain_passes_the_gripper_through():
    """Through the sim-to-real chain (position servos and the gripper's passthrough) the
    scripted pick still lifts the cube; each step logs the finger target, which closes."""
    from mjx_arm.sim2real.position_env import make_position_env

    env = make_position_env(lift_config(), "mujoco", arm=GRIPPER)
    try:
        result = run_scripted_lift(env.unwrapped, 1)
        log = env.unwrapped.episodes[-1]
        assert result["success"], result["info"]
        assert len(log.gripper) == result["steps"]
        assert log.gripper[0] == pytest.approx(0.0, abs=1e-9)
        assert max(log.gripper) == pytest.approx(env.unwrapped.arm.gripper.stroke)
        assert env.unwrapped.gripper_chain.clips == 0
    finally:
        env.close()
