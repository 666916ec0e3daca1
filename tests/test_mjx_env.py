"""The MJX env: pure reset/step, one compilation, batch == single, NaN-safe auto-reset.

MJX (the JAX implementation) compiles slowly on a CPU (about a minute per function here), so the
module compiles few functions and reuses them across tests.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_arm.envs.mjx_env import MjxArmEnv
from mjx_arm.envs.wrappers import wrap_for_training
from mjx_arm.task import reach_config
from mjx_arm.task.observation import OBS_SIZE

BATCH = 2


@pytest.fixture(scope="module")
def env() -> MjxArmEnv:
    return MjxArmEnv(reach_config())


@pytest.fixture(scope="module")
def traced(env):
    """jit(vmap(step)) with a trace counter, and jit(vmap(reset))."""
    count = {"step": 0}

    def counted_step(state, action):
        count["step"] += 1
        return env.step(state, action)

    step = jax.jit(jax.vmap(counted_step))
    reset = jax.jit(jax.vmap(env.reset))
    return step, reset, count


@pytest.mark.slow
def test_step_compiles_once(traced):
    step, reset, count = traced
    state = reset(jax.random.split(jax.random.PRNGKey(0), BATCH))
    rng = np.random.default_rng(0)
    for _ in range(4):
        action = jnp.asarray(rng.uniform(-1, 1, (BATCH, 6)), jnp.float32)
        state = step(state, action)
    jax.block_until_ready(state.obs)
    assert count["step"] == 1
    assert state.obs.shape == (BATCH, OBS_SIZE)
    assert bool(jnp.all(jnp.isfinite(state.obs)))


@pytest.mark.slow
def test_batched_env_equals_single_env(env, traced):
    """Env i of the batch follows the same trajectory as the single env with key i."""
    step, reset, _ = traced
    keys = jax.random.split(jax.random.PRNGKey(7), BATCH)
    actions = jnp.asarray(np.random.default_rng(1).uniform(-1, 1, (3, BATCH, 6)), jnp.float32)
    batch = reset(keys)
    for a in actions:
        batch = step(batch, a)
    single_step = jax.jit(jax.vmap(env.step))  # same compiled function shape: batch of 1
    single_reset = jax.jit(jax.vmap(env.reset))
    for i in range(BATCH):
        one = single_reset(keys[i : i + 1])
        for a in actions:
            one = single_step(one, a[i : i + 1])
        # float32 on the CPU: identical up to rounding of the reductions (1e-5 is loose)
        np.testing.assert_allclose(one.obs[0], batch.obs[i], atol=1e-5)
        np.testing.assert_allclose(one.reward[0], batch.reward[i], rtol=1e-5, atol=1e-5)


@pytest.mark.slow
def test_nan_state_ends_episode_and_never_reaches_obs(env, traced):
    step, reset, _ = traced
    state = reset(jax.random.split(jax.random.PRNGKey(3), BATCH))
    bad = state.pipeline_state.replace(qvel=state.pipeline_state.qvel.at[0].set(jnp.nan))
    state = state.replace(pipeline_state=bad)
    out = step(state, jnp.zeros((BATCH, 6)))
    assert float(out.done[0]) == 1.0 and float(out.done[1]) == 0.0
    assert float(out.metrics["reward/nonfinite"][0]) == 1.0
    assert bool(jnp.all(jnp.isfinite(out.obs))), "a NaN reached the observation"
    assert bool(jnp.all(jnp.isfinite(out.reward)))
    np.testing.assert_allclose(out.obs[0], state.obs[0])  # the last finite observation


@pytest.mark.slow
def test_auto_reset_replaces_nan_state(env):
    """Through the training wrappers the NaN env restarts from its first state."""
    wrapped = wrap_for_training(env, episode_length=150)
    state = jax.jit(wrapped.reset)(jax.random.split(jax.random.PRNGKey(0), BATCH))
    bad = state.pipeline_state.replace(qvel=state.pipeline_state.qvel.at[0].set(jnp.nan))
    out = jax.jit(wrapped.step)(state.replace(pipeline_state=bad), jnp.zeros((BATCH, 6)))
    leaves = jax.tree.leaves(out.pipeline_state)
    assert all(bool(jnp.all(jnp.isfinite(x))) for x in leaves if x.dtype.kind == "f")
    assert bool(jnp.all(jnp.isfinite(out.obs)))


@pytest.mark.slow
def test_reset_is_a_pure_function_of_the_key(env, traced):
    _, reset, _ = traced
    keys = jax.random.split(jax.random.PRNGKey(11), BATCH)
    a, b = reset(keys), reset(keys)
    np.testing.assert_array_equal(a.obs, b.obs)
    c = reset(jax.random.split(jax.random.PRNGKey(12), BATCH))
    assert not np.allclose(a.obs[:, 13:16], c.obs[:, 13:16])  # new targets
