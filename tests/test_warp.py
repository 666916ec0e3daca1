"""MJX on MuJoCo Warp: agreement with C MuJoCo and MJX-JAX, batching, buffer overflow, training.

These run where warp-lang is installed (the ``gpu`` extra) and a GPU is present; Warp also runs
on a CPU, slowly (a few minutes of kernel and XLA compilation): set ``MJX_ARM_TEST_WARP_CPU=1``
to run them there. Tolerances are stated beside the figures measured (CPU, warp-lang 1.19.0,
mujoco-mjx 3.17.0; the GPU figures are in ``benchmarks/results/parity_gpu/``).
"""

from __future__ import annotations

import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_arm.envs.physics_config import PhysicsConfig, warp_available

pytestmark = [
    pytest.mark.gpu,
    pytest.mark.skipif(not warp_available(), reason="warp-lang is not installed"),
    pytest.mark.skipif(
        jax.default_backend() == "cpu" and os.environ.get("MJX_ARM_TEST_WARP_CPU") != "1",
        reason="no GPU (set MJX_ARM_TEST_WARP_CPU=1 to run Warp on the CPU)",
    ),
]

WARP = PhysicsConfig(impl="warp")


@pytest.fixture(scope="module")
def figures():
    """Parity of C MuJoCo and both MJX implementations: 16 FK poses, 8 open-loop sequences of
    1 s, 4 presses of 2 s."""
    from mjx_arm.bench.parity import ParityConfig, run_parity

    config = ParityConfig.quick(
        engines=("mujoco", "mjx"), impls=("warp", "jax"), fk_poses=16, press_boxes=4
    )
    return run_parity(config, log=lambda _: None)["figures"]


def test_forward_kinematics_agree(figures):
    """ee point at 16 random joint configurations, MJX (float32) vs C MuJoCo (float64)."""
    for impl in ("warp", "jax"):
        assert figures["fk_m"][f"mujoco vs mjx-{impl}"] < 1e-6  # measured 1.2e-7 / 1.4e-7 m


def test_open_loop_joint_state_agrees(figures):
    """Joint angles after 1 s of the same open-loop actions (free motion, 8 sequences)."""
    pairs = figures["open_loop"]["pairs"]
    warp, jax_ = pairs["mujoco vs mjx-warp"], pairs["mujoco vs mjx-jax"]
    assert warp["at_goal_median"] < 1e-2  # measured 1.5e-3 rad
    assert warp["max"] < 2e-2  # measured 3.2e-3 rad
    assert jax_["at_goal_median"] < 1e-2  # measured 5.1e-3 rad
    for impl in ("warp", "jax"):  # tared F/T in free motion
        # 6e-7 N on a CPU; 2.4e-3 N on an H100 while the tare's matrix product ran at JAX's
        # default precision (TF32 operands on a GPU)
        assert figures["open_loop"]["free_motion_force_max_n"][f"mjx-{impl}"] < 1e-3  # 6e-7 N


def test_press_force_agrees(figures):
    """Tared |F| while pressing the box (mean of the last 10 of 60 steps, 4 box positions).

    Warp runs C MuJoCo's contact and solver algorithms; MJX-JAX its own capsule-box collision
    and a fixed-iteration solver, which press measurably differently.
    """
    press = figures["press"]["engines"]
    assert press["mjx-warp"]["rel_to_reference_max"] < 0.05  # measured 1e-4
    assert press["mjx-jax"]["rel_to_reference_max"] < 0.5  # 0.30 before; 0.002 in results/parity
    assert all(1.0 <= f <= 50.0 for f in press["mjx-warp"]["steady_n"])


def test_warp_env_batches_and_restarts():
    """A Warp batch steps once-compiled, restarts finished envs, and keeps the contact pool."""
    from mjx_arm.envs.backend import make_batched_env
    from mjx_arm.envs.wrappers import wrap_for_training
    from mjx_arm.task import touch_config

    batch = 4
    env = make_batched_env(touch_config(episode_steps=3), "mjx", WARP, batch)
    assert env.physics.impl == "warp"
    assert env.physics.describe()["naconmax"] == env.physics.describe()["model_contacts"] * batch
    wrapped = wrap_for_training(env, episode_length=3)
    state = jax.jit(wrapped.reset)(jax.random.split(jax.random.PRNGKey(0), batch))
    step = jax.jit(wrapped.step)
    first = np.asarray(state.info["first_pipeline_state"].qpos)
    actions = jnp.full((batch, 6), 0.5)
    for _ in range(3):  # the episode limit ends every env at step 3: all restart
        state = step(state, actions)
    np.testing.assert_allclose(np.asarray(state.pipeline_state.qpos), first, atol=1e-6)
    assert np.isfinite(np.asarray(state.obs)).all()
    assert not np.asarray(state.metrics["physics_overflow"]).any()


def test_overflow_is_an_error_not_a_silent_drop():
    """A contact pool of one contact per env and 4 constraint rows per env overflow while the
    arm presses into the table: the vector env raises. With the model's own bound the same
    presses need more than those buffers hold and drop nothing (measured: up to 8 contacts in
    the pool and 24 rows in an env; with the small buffers step 14 set Warp's nefc and
    broadphase bits)."""
    from mjx_arm.envs.backend import make_batched_env
    from mjx_arm.envs.mjx_physics import PhysicsOverflowError
    from mjx_arm.envs.vector import ArmVectorEnv
    from mjx_arm.task import touch_config

    # the seed variant's joint speed: at the gentle variant's (0.15 of the URDF's) the tool
    # stayed 0.27 m above the table through the 60 steps of shoulder +1, elbow -1, and this
    # press first touches it after about 45 steps with one contact and 4 rows (C MuJoCo)
    task = touch_config("seed")
    # shoulder and wrist 1 drive the forearm and the wrist links into the table
    press = np.tile(np.array([0.0, 1.0, 0.0, -1.0, 0.0, 0.0], np.float32), (2, 1))
    env = make_batched_env(task, "mjx", WARP, 2)
    state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), 2))
    step = jax.jit(jax.vmap(env.step))
    contacts = rows = 0
    for _ in range(60):
        state = step(state, jnp.asarray(press))
        assert not np.asarray(state.metrics["physics_overflow"]).any()
        contacts = max(contacts, int(np.asarray(state.pipeline_state._impl.nacon).max()))
        rows = max(rows, int(np.asarray(state.pipeline_state._impl.nefc).max()))
    assert contacts > 2 and rows > 4, (contacts, rows)  # measured 8 and 24

    tiny = PhysicsConfig(impl="warp", naconmax_per_env=1, njmax=4)
    vector = ArmVectorEnv(task, 2, "mjx", tiny)
    vector.reset(seed=0)
    with pytest.raises(PhysicsOverflowError, match="naconmax_per_env"):
        for _ in range(60):  # raised at step 14 (measured)
            vector.step(press)


def test_the_step_compiles_nothing_the_precompile_missed():
    """:func:`step_loads` finds every module the Touch env's reset and step load, without
    compiling any: after the precompile, stepping loads no new module and no new block size.
    On a GPU the env ran the precompile itself before the first step."""
    from mjx_arm.envs import warp_compile
    from mjx_arm.envs.backend import make_batched_env
    from mjx_arm.envs.warp_buffers import warp_compatible
    from mjx_arm.task import touch_config

    env = make_batched_env(touch_config(), "mjx", WARP, 2)
    physics = env.physics
    device = (warp_compile.cuda_devices() or ["cpu"])[0]
    before = warp_compile.loaded_modules()
    model = warp_compatible(physics.mj_model)
    buffers = physics.buffers
    loads = warp_compile.step_loads(model, buffers["naconmax"], buffers["njmax"], device)
    assert warp_compile.loaded_modules() == before  # noting loads compiled nothing
    generated = [m.name for ms in loads.values() for m in ms if "__locals__" in m.name]
    assert len(generated) >= 20, generated  # MuJoCo Warp's per-model kernels (27 measured)
    warp_compile.precompile(2, loads, [device])
    precompiled = warp_compile.loaded_modules()
    state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), 2))
    jax.block_until_ready(jax.jit(jax.vmap(env.step))(state, jnp.zeros((2, 6))))
    after = warp_compile.loaded_modules()
    new = {name: dims for name, dims in after.items() if precompiled.get(name) != dims}
    assert set(new) <= {"mujoco.mjx.warp.ffi"}, new  # the FFI shim holds no kernel
    if jax.default_backend() != "cpu":
        assert physics.precompile_seconds > 0.0


def test_table_height_reaches_warp_collisions():
    """A lowered table lowers the resting cube under MuJoCo Warp as under MJX's JAX
    implementation: Warp places the world body's geoms once, so the env moves the table in
    the data (measured: the cube's height after 10 still steps, -0.020 m both; before the
    fix Warp pushed it back to 0.000)."""
    from mjx_arm.bench import robustness as rb
    from mjx_arm.task import task_config

    table = {p.name: p for p in rb.perturbations_for(True)}["table_height"]
    point = rb.Point("table_height", -0.02, table.config(-0.02), True)
    for impl in ("warp", "jax"):
        env = rb.make_env(task_config("lift"), "mjx", impl, None, 2)
        state = jax.jit(jax.vmap(env.start))(
            jax.random.split(jax.random.PRNGKey(0), 2), rb.point_draws(env, [point], [2], 0)
        )
        step = jax.jit(jax.vmap(env.step))
        for _ in range(10):
            state = step(state, jnp.zeros((2, env.action_size)))
        height = np.asarray(state.metrics["lift_height"])
        np.testing.assert_allclose(height, -0.02, atol=2e-3, err_msg=impl)


def test_box_pairs_take_the_box_box_collider():
    """Under MuJoCo Warp the gripper arm's Lift model collides its boxes (pads, cube, table)
    with the box-box function that C MuJoCo uses: the step launches no convex-collision
    (GJK/EPA) kernel, whose compile alone took 52 s on an H200. The cube still rests on the
    table as in C MuJoCo (``test_table_height_reaches_warp_collisions``)."""
    import mujoco

    from mjx_arm.envs import warp_compile
    from mjx_arm.envs.backend import make_batched_env
    from mjx_arm.envs.warp_buffers import warp_compatible
    from mjx_arm.task import task_config

    no_compile = WARP.replace(compile_threads=0)
    physics = make_batched_env(task_config("lift"), "mjx", no_compile, 2).physics
    model = warp_compatible(physics.mj_model)
    assert model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_NATIVECCD
    buffers = physics.buffers
    loads = warp_compile.step_loads(model, buffers["naconmax"], buffers["njmax"], "cpu")
    names = [m.name for ms in loads.values() for m in ms]
    assert not [n for n in names if "ccd_kernel" in n], names
    assert [n for n in names if "primitive_narrowphase" in n]  # the boxes collide here
