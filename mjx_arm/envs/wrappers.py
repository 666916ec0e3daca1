"""Brax training wrappers: vmap, a per-device split, episode limit, auto-reset with new targets."""

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


def wrap_for_training(
    env: Env,
    episode_length: int,
    action_repeat: int = 1,
    mesh: jax.sharding.Mesh | None = None,
    axis: str = "envs",
    **_,
) -> Wrapper:
    """Vmap + episode limit + auto-reset with new targets (Brax's ``wrap_env_fn`` signature).

    With a ``mesh``, the batched physics runs on each device's own slice of the batch
    (:class:`DeviceSplit`, over mesh axis ``axis``).
    """
    env = VmapWrapper(env)
    if mesh is not None:
        env = DeviceSplit(env, mesh, axis)
    env = EpisodeWrapper(env, episode_length, action_repeat)
    return AutoResetNewTarget(env)


class DeviceSplit(Wrapper):
    """Each device resets and steps its own slice of the batch (``jax.shard_map``).

    Under ``jax.jit`` over a mesh XLA partitions MJX's JAX graph itself, but not MuJoCo Warp's
    kernels (foreign function calls). Placed right above the ``VmapWrapper``, this runs the
    batched physics once per device on its ``num_envs / D`` envs; the physics says which state
    leaves are cut per device (``physics.splits``).

    Args:
        env: the batched env (a Brax ``VmapWrapper``).
        mesh: the devices.
        axis: the mesh axis the batch is split over.
    """

    def __init__(self, env: Env, mesh: jax.sharding.Mesh, axis: str) -> None:
        super().__init__(env)
        self.mesh, self.axis = mesh, axis

    def _specs(self, tree):
        splits = self.env.unwrapped.physics.splits
        cut, whole = jax.sharding.PartitionSpec(self.axis), jax.sharding.PartitionSpec()
        return jax.tree_util.tree_map_with_path(lambda p, _: cut if splits(p) else whole, tree)

    def reset(self, rng: jax.Array) -> State:
        """Reset ``rng (num_envs, 2)``, each device its own envs."""
        specs = self._specs(jax.eval_shape(self.env.reset, rng))
        split = jax.shard_map(
            self.env.reset,
            mesh=self.mesh,
            in_specs=jax.sharding.PartitionSpec(self.axis),
            out_specs=specs,
            check_vma=False,
        )
        return split(rng)

    def step(self, state: State, action: jax.Array) -> State:
        """Step ``action (num_envs, 6)``, each device its own envs."""
        specs = self._specs(state)
        split = jax.shard_map(
            self.env.step,
            mesh=self.mesh,
            in_specs=(specs, jax.sharding.PartitionSpec(self.axis)),
            out_specs=specs,
            check_vma=False,
        )
        return split(state, action)
