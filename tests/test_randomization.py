"""Domain randomisation and the task's memory in the batched env (C MuJoCo backend: fast here).

The same env code runs on MJX; the C backend is used because it compiles in seconds on a CPU.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_arm.envs.mjx_env import MjxArmEnv
from mjx_arm.envs.mjx_physics import Dynamics
from mjx_arm.envs.mujoco_batch import MujocoCallbackPhysics
from mjx_arm.envs.physics_config import RandomizationConfig
from mjx_arm.envs.randomization import nominal_episode, sample_episode
from mjx_arm.envs.wrappers import wrap_for_training
from mjx_arm.task import touch_config
from mjx_arm.task.observation import obs_slices

ON = RandomizationConfig(enabled=True)
SLICES = obs_slices()


def _env(randomization=None, **task):
    return MjxArmEnv(
        touch_config(**task), physics_factory=MujocoCallbackPhysics, randomization=randomization
    )


def test_draws_stay_in_their_ranges_and_off_is_nominal():
    draws = jax.vmap(lambda k: sample_episode(k, ON))(jax.random.split(jax.random.PRNGKey(0), 512))
    for name in ("friction", "damping", "armature", "gain"):
        low, high = getattr(ON, name)
        values = np.asarray(getattr(draws.dynamics, name))
        assert values.min() >= low and values.max() <= high
        assert values.max() - values.min() > 0.8 * (high - low)  # the range is used
    offset = np.asarray(draws.box_offset)
    assert np.abs(offset[:, :2]).max() <= ON.box_offset and not offset[:, 2].any()
    assert 0.2 < float(np.mean(np.asarray(draws.latency))) < 0.4  # latency_prob 0.3, n = 512
    off = sample_episode(jax.random.PRNGKey(0), RandomizationConfig())
    nominal = nominal_episode()
    for a, b in zip(jax.tree.leaves(off), jax.tree.leaves(nominal), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_dynamics_multipliers_reach_each_row_of_the_c_batch():
    """Servo gain x0.5 in one row slows that env's joints and no other's."""
    env = _env()
    physics = env.physics
    states = jax.vmap(env.reset)(jax.random.split(jax.random.PRNGKey(1), 3))
    data = states.pipeline_state
    ctrl = jnp.tile(jnp.array([0.5, -0.5, 0.5, 0.5, 0.5, 0.5]), (3, 1))
    nominal = Dynamics.nominal()
    dyn = jax.tree.map(lambda x: jnp.stack([x, x, x]), nominal)
    half = dyn.replace(gain=dyn.gain.at[1].set(0.5))
    step = jax.jit(jax.vmap(physics.step))
    base = step(data, ctrl, dyn)
    slow = step(data, ctrl, half)
    qvel = lambda d: np.asarray(jax.vmap(physics.read)(d).qvel)  # noqa: E731
    np.testing.assert_allclose(qvel(slow)[[0, 2]], qvel(base)[[0, 2]], atol=1e-6)
    assert np.abs(qvel(slow)[1] - qvel(base)[1]).max() > 1e-2
    # nominal multipliers reproduce the un-randomised model
    plain = jax.jit(jax.vmap(lambda d, c: physics.step(d, c)))(data, ctrl)
    np.testing.assert_allclose(qvel(base), qvel(plain), atol=1e-6)


def test_observation_hides_the_box_offset_and_adds_ft_noise():
    env = _env(ON)
    state = jax.jit(env.reset)(jax.random.PRNGKey(4))
    episode = state.info["episode"]
    reading = env.physics.read(state.pipeline_state)
    target_rel = np.asarray(state.obs[SLICES["target_rel"]])
    np.testing.assert_allclose(
        target_rel, np.asarray(reading.target_pos - episode.box_offset), atol=1e-6
    )
    state = jax.jit(env.step)(state, jnp.zeros(6))
    ft = np.asarray(state.obs[SLICES["contact_force"]])
    assert 0 < np.abs(ft[:3]).max() < 5 * ON.ft_force_noise  # noise, not contact


def test_restart_clears_the_task_memory():
    """After an episode ends, the restarted env's hold counter, strike flag and previous
    action are those of a new episode."""
    env = wrap_for_training(_env(episode_steps=2), episode_length=2)
    state = jax.jit(env.reset)(jax.random.split(jax.random.PRNGKey(2), 2))
    memory = state.info["task"]
    memory = dataclasses.replace(
        memory,
        progress=memory.progress._replace(hold=jnp.array([2.0, 2.0]), over=jnp.array([True, True])),
    )
    state.info["task"] = memory
    step = jax.jit(env.step)
    state = step(state, jnp.ones((2, 6)))
    assert np.asarray(state.info["task"].prev_action).min() == 1.0  # remembered mid-episode
    state = step(state, jnp.ones((2, 6)))  # the episode limit ends both envs here
    fresh = state.info["task"]
    np.testing.assert_array_equal(np.asarray(fresh.progress.hold), [0.0, 0.0])
    assert not np.asarray(fresh.progress.over).any()
    assert not np.asarray(fresh.prev_action).any()


@pytest.mark.parametrize("latency", [0.0, 1.0])
def test_latency_applies_the_previous_action(latency):
    """With a one-step delay the first action moves nothing (the delayed action is zero).

    Action scale 0.5 (the seed variant's) so that full speed stands well clear of gravity sag.
    """
    randomization = RandomizationConfig(enabled=True, latency_prob=latency, ft_force_noise=0.0)
    env = _env(randomization, action_scale=0.5)
    state = jax.jit(env.reset)(jax.random.PRNGKey(5))
    qpos0 = np.asarray(env.physics.read(state.pipeline_state).qpos)
    state = jax.jit(env.step)(state, jnp.ones(6))
    moved = np.abs(np.asarray(env.physics.read(state.pipeline_state).qpos) - qpos0).max()
    if latency:
        assert moved < 5e-3  # only gravity sag against the servo holding zero velocity
    else:
        assert moved > 2e-2  # 0.048 rad: full speed (0.5 * pi rad/s) for most of 1/30 s
