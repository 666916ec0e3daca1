"""The PPO run: devices, env batch, epochs between evaluations, and the callbacks.

The order of events follows Brax's ``ppo.train``: an evaluation of the initial policy (when more
than one evaluation is asked for), then ``num_evals - 1`` epochs, each followed by
``policy_params_fn(step, make_policy, params)`` and ``progress_fn(step, metrics)``. Metric names
are Brax's (``eval/...``, ``training/...``), so run directories read the same as before.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
from jax.sharding import NamedSharding
from jax.sharding import PartitionSpec as P

from mjx_arm.envs.wrappers import wrap_for_training
from mjx_arm.train.config import TrainConfig
from mjx_arm.train.learner import (
    ENV_AXIS,
    EpochSizes,
    Learner,
    Params,
    batch_sharding,
    evaluator,
    local_devices,
    make_mesh,
)


@dataclass
class Callbacks:
    """What the run reports to: Brax's ``progress_fn`` and ``policy_params_fn`` signatures."""

    progress: Callable[[int, dict[str, Any]], None]
    policy_params: Callable[[int, Callable, Params], None]


def resolve_partition(config: TrainConfig, impl: str) -> str:
    """``auto``: ``xla`` for MJX-JAX; ``per_device`` for Warp and C MuJoCo (foreign calls)."""
    if config.partition != "auto":
        return config.partition
    return "xla" if impl == "jax" else "per_device"


def strong(tree: Any) -> Any:
    """``tree`` without weak types (a weak type changes the jitted epoch's signature)."""
    return jax.tree.map(lambda x: jnp.asarray(x).astype(jnp.asarray(x).dtype), tree)


def _run_keys(seed: int) -> tuple[jax.Array, ...]:
    """The run's keys from its seed: (policy init, value init, env reset, evaluation, epochs)."""
    global_key, local_key = jax.random.split(jax.random.PRNGKey(seed))
    local_key, key_env, key_eval = jax.random.split(local_key, 3)
    key_policy, key_value = jax.random.split(global_key)
    return key_policy, key_value, key_env, key_eval, local_key


def _training_metrics(metrics: dict[str, Any], sps: float, walltime: float) -> dict[str, Any]:
    """An epoch's metrics as Brax names them: ``training/sps``, ``training/walltime``, ..."""
    named = {f"training/{name}": value for name, value in metrics.items()}
    return {"training/sps": sps, "training/walltime": walltime, **named}


def run_ppo(
    config: TrainConfig,
    env: Any,
    eval_env: Any,
    episode_length: int,
    callbacks: Callbacks,
    restore: Params | None = None,
    step_offset: int = 0,
) -> dict[str, Any]:
    """Train PPO up to ``config.num_timesteps`` env steps; return the devices and partition.

    The run is cut into ``num_evals - 1`` epochs of equal size (rounded up, as Brax does); a
    resumed run (``step_offset`` > 0) runs the epochs that remain, so it ends at the same step
    and logs the same steps as a run that was never stopped.

    Args:
        config: PPO settings, devices and partition.
        env, eval_env: the unwrapped training and evaluation envs (``MjxArmEnv``).
        episode_length: control steps before an episode is truncated.
        callbacks: where evaluations and params go (steps are the run's global steps).
        restore: (normaliser, policy, value) to start from.
        step_offset: env steps already trained (a resumed run's checkpoint step).
    """
    devices = local_devices(config.devices)
    config.check_devices(len(devices))
    mesh = make_mesh(devices)
    partition = resolve_partition(config, env.physics.impl)
    key_policy, key_value, key_env, key_eval, local_key = _run_keys(config.seed + step_offset)

    split_mesh = mesh if partition == "per_device" else None
    train_env = wrap_for_training(env, episode_length, mesh=split_mesh, axis=ENV_AXIS)
    learner = Learner(config, env.observation_size, env.action_size, mesh)
    state = learner.init(key_policy, key_value)
    if restore is not None:
        state = learner.restore(state, restore)
    env_state, shardings = _reset(train_env, mesh, key_env, config.num_envs)
    sizes = EpochSizes.of(config, config.num_timesteps)
    epoch = learner.epoch_fn(train_env, sizes, shardings)
    evaluate = evaluator(
        learner, wrap_for_training(eval_env, episode_length), config, episode_length, key_eval
    )

    params = learner.params(state)
    if config.num_evals > 1 and step_offset == 0:
        callbacks.progress(0, evaluate.run_evaluation(params, {}))
    walltime, step = 0.0, step_offset
    while step < config.num_timesteps:
        epoch_key, local_key = jax.random.split(local_key)
        start = time.monotonic()
        state, env_state, metrics = epoch(state, strong(env_state), epoch_key)
        metrics = jax.device_get(metrics)
        seconds = time.monotonic() - start
        walltime += seconds
        step += sizes.env_steps_per_epoch
        params = learner.params(state)
        callbacks.policy_params(step, learner.make_policy, params)
        training = _training_metrics(metrics, sizes.env_steps_per_epoch / seconds, walltime)
        callbacks.progress(step, evaluate.run_evaluation(params, training))
    return {"devices": [str(d) for d in devices], "partition": partition}


def _reset(env: Any, mesh: Any, key: jax.Array, num_envs: int) -> tuple[Any, Any]:
    """The first env state, its batch split over the mesh, and the state's shardings."""
    keys = jax.random.split(key, num_envs)
    shardings = batch_sharding(mesh, jax.eval_shape(env.reset, keys), num_envs)
    reset = jax.jit(
        env.reset, in_shardings=NamedSharding(mesh, P(ENV_AXIS)), out_shardings=shardings
    )
    return strong(reset(keys)), shardings
