"""Brax training wrappers: vmap, episode limit and an auto-reset that draws new targets."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from brax.envs.base import Env, State, Wrapper
from brax.envs.wrappers.training import EpisodeWrapper, VmapWrapper


class AutoResetNewTarget(Wrapper):
    """Reset finished envs to their first state with a freshly drawn target.

    Like Brax's ``AutoResetWrapper`` (which restarts from the stored first state), but the base
    env's ``retarget(data, rng)`` gives every new episode a new target. A finished episode's
    physics state, NaN included, is replaced before it reaches the learner.
    """

    def reset(self, rng: jax.Array) -> State:
        """Reset and remember the first state of each env."""
        state = self.env.reset(rng)
        state.info["first_pipeline_state"] = state.pipeline_state
        state.info["first_obs"] = state.obs
        return state

    def step(self, state: State, action: jax.Array) -> State:
        """Step; where an env is done, restart it with a new target."""
        if "steps" in state.info:
            state.info["steps"] = jnp.where(state.done, 0.0, state.info["steps"])
        state = state.replace(done=jnp.zeros_like(state.done))
        state = self.env.step(state, action)
        keys = jax.vmap(jax.random.split)(state.info["rng"])
        state.info["rng"] = keys[:, 0]
        fresh_data, fresh_obs = jax.vmap(self.env.unwrapped.retarget)(
            state.info["first_pipeline_state"], keys[:, 1]
        )

        def where_done(new, old):
            done = jnp.reshape(state.done, state.done.shape + (1,) * (old.ndim - 1))
            return jnp.where(done > 0, new, old)

        data = jax.tree.map(where_done, fresh_data, state.pipeline_state)
        return state.replace(pipeline_state=data, obs=where_done(fresh_obs, state.obs))


def wrap_for_training(env: Env, episode_length: int, action_repeat: int = 1, **_) -> Wrapper:
    """Vmap + episode limit + auto-reset with new targets (Brax's ``wrap_env_fn`` signature)."""
    env = VmapWrapper(env)
    env = EpisodeWrapper(env, episode_length, action_repeat)
    return AutoResetNewTarget(env)
