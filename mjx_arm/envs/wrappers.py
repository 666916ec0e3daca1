"""Brax training wrappers: vmap, episode limit and an auto-reset that draws new targets."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from brax.envs.base import Env, State, Wrapper
from brax.envs.wrappers.training import EpisodeWrapper, VmapWrapper

from mjx_arm.envs.mjx_physics import batched_where


class AutoResetNewTarget(Wrapper):
    """Reset finished envs to their first state with a freshly drawn target.

    Like Brax's ``AutoResetWrapper`` (which restarts from the stored first state), but the base
    env's ``restart(data, rng)`` gives every new episode a new target (and randomisation draw)
    and clears the task's memory. A finished episode's physics state, NaN included, is replaced
    before it reaches the learner; the physics merges states (``physics.where``), since Warp's
    contact pool has no batch axis.
    """

    def reset(self, rng: jax.Array) -> State:
        """Reset and remember the first state of each env."""
        state = self.env.reset(rng)
        state.info["first_pipeline_state"] = state.pipeline_state
        return state

    def step(self, state: State, action: jax.Array) -> State:
        """Step; where an env is done, restart it with a new target."""
        if "steps" in state.info:
            state.info["steps"] = jnp.where(state.done, 0.0, state.info["steps"])
        state = state.replace(done=jnp.zeros_like(state.done))
        state = self.env.step(state, action)
        base = self.env.unwrapped
        keys = jax.vmap(jax.random.split)(state.info["rng"])
        state.info["rng"] = keys[:, 0]
        fresh_data, fresh_obs, fresh_info = jax.vmap(base.restart)(
            state.info["first_pipeline_state"], keys[:, 1]
        )
        done = state.done > 0
        data = base.physics.where(done, fresh_data, state.pipeline_state)
        for name, value in fresh_info.items():
            state.info[name] = batched_where(done, value, state.info[name])
        return state.replace(pipeline_state=data, obs=batched_where(done, fresh_obs, state.obs))


def wrap_for_training(env: Env, episode_length: int, action_repeat: int = 1, **_) -> Wrapper:
    """Vmap + episode limit + auto-reset with new targets (Brax's ``wrap_env_fn`` signature)."""
    env = VmapWrapper(env)
    env = EpisodeWrapper(env, episode_length, action_repeat)
    return AutoResetNewTarget(env)
