"""Brax PPO as one jitted training epoch over a mesh of devices.

Brax's ``ppo.train`` replicates its training step with ``jax.pmap``, and XLA crashes compiling
MJX's graph under pmap on several GPUs (jax 0.11). This module keeps Brax's PPO (its networks,
its loss, :mod:`mjx_arm.train.losses`, running-statistics normaliser, ``generate_unroll`` and
the same optax optimiser) and compiles the epoch with ``jax.jit`` over a
:class:`jax.sharding.Mesh` instead:

- the env batch is sharded over the mesh axis ``envs`` (each device steps ``num_envs / D`` envs);
- params, optimiser and normaliser state are replicated on every device;
- each minibatch is split over the devices and XLA inserts the gradient all-reduce.

The epoch is written on the global batch, so a run's numbers do not depend on the device count
except through the order of floating-point sums: the same seed on one device or on several gives
the same run within float32 rounding. The environment decides how its physics is partitioned
(:class:`mjx_arm.envs.wrappers.DeviceSplit` runs physics XLA cannot partition, MuJoCo Warp's
kernels, on each device's own slice).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax
from brax.training import acting
from brax.training import types as brax_types
from brax.training.acme import running_statistics, specs
from brax.training.agents.ppo import networks as ppo_networks
from brax.training.agents.ppo.train import TrainingState
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

from mjx_arm.inputs import ConfigError
from mjx_arm.train.config import TrainConfig
from mjx_arm.train.epoch_metrics import before_update, episode_counts, episode_rates, update_view
from mjx_arm.train.losses import init_params, loss_and_grad
from mjx_arm.train.networks import make_networks
from mjx_arm.train.normalizer import fix_force_scale
from mjx_arm.train.normalizer import update as normalizer_update
from mjx_arm.train.schedule import adapted_rate, current_rate, make_optimizer, with_rate

ENV_AXIS = "envs"
# What the loss needs from each transition besides the policy's extras (Brax's names).
STATE_EXTRAS = ("truncation", "episode_metrics", "episode_done")

Params = tuple[Any, Any, Any]  # (normaliser state, policy params, value params)


def local_devices(count: int = 0) -> list[jax.Device]:
    """The first ``count`` local devices of the default backend (0: all of them).

    Raises:
        ConfigError: more devices asked for than there are.
    """
    devices = jax.local_devices()
    if count < 0 or count > len(devices):
        raise ConfigError(
            f"asked for {count} devices, {len(devices)} available ({devices[0].platform}); "
            "choose --devices 0 (all) or fewer"
        )
    return devices[: count or len(devices)]


def train_devices(count: int = 0) -> list[jax.Device]:
    """The devices a training splits its env batch over.

    Where several processes train together (``jax.distributed``, one per GPU), every device of
    every process, each process using all of its own; alone, the first ``count`` local devices
    (0: all of them).

    Raises:
        ConfigError: more local devices asked for than there are.
    """
    if jax.process_count() > 1:
        return list(jax.devices())
    return local_devices(count)


def make_mesh(devices: list[jax.Device]) -> Mesh:
    """A one-axis mesh (``envs``) over ``devices``."""
    return Mesh(np.array(devices), (ENV_AXIS,))


def batch_sharding(mesh: Mesh, tree: Any, batch: int) -> Any:
    """Shardings for ``tree``: leaves with a leading axis of ``batch`` split over the devices.

    Other leaves (MuJoCo Warp's contact pool, counters) are replicated here; inside the physics
    :class:`mjx_arm.envs.wrappers.DeviceSplit` lays them out per device.
    """
    split, whole = NamedSharding(mesh, P(ENV_AXIS)), NamedSharding(mesh, P())

    def pick(x: Any) -> NamedSharding:
        return split if getattr(x, "ndim", 0) >= 1 and x.shape[0] == batch else whole

    return jax.tree.map(pick, tree)


@dataclass(frozen=True)
class EpochSizes:
    """How a training epoch is cut.

    Attributes:
        unrolls: env unrolls per training step (``batch_size * num_minibatches / num_envs``).
        steps_per_epoch: training steps per epoch (one epoch between two evaluations).
        env_steps_per_step: env steps per training step.
    """

    unrolls: int
    steps_per_epoch: int
    env_steps_per_step: int

    @property
    def env_steps_per_epoch(self) -> int:
        """Env steps between two evaluations."""
        return self.steps_per_epoch * self.env_steps_per_step

    @staticmethod
    def of(config: TrainConfig, num_timesteps: int) -> EpochSizes:
        """Brax's arithmetic: ``num_evals - 1`` epochs cover ``num_timesteps`` (rounded up)."""
        per_step = config.batch_size * config.num_minibatches * config.unroll_length
        evals_after_init = max(config.num_evals - 1, 1)
        epoch = int(np.ceil(num_timesteps / (evals_after_init * per_step)))
        unrolls = config.batch_size * config.num_minibatches // config.num_envs
        return EpochSizes(unrolls, epoch, per_step)


class Learner:
    """Brax PPO's networks, loss and optimiser, and the jitted training epoch.

    Args:
        config: the training config (PPO settings, network sizes).
        observation_size: size of the flat observation (22).
        action_size: size of the action (6).
        mesh: the devices; the env batch is split over its ``envs`` axis.
        force_dims: where ``contact_force`` sits in the flat observation (the normaliser's
            ``force_scale`` acts there); None: nowhere.
    """

    def __init__(
        self,
        config: TrainConfig,
        observation_size: int,
        action_size: int,
        mesh: Mesh,
        force_dims: slice | None = None,
    ) -> None:
        self.config, self.mesh, self.force_dims = config, mesh, force_dims
        self.observation_size = observation_size
        self.network = make_networks(config, observation_size, action_size)
        self.make_policy = ppo_networks.make_inference_fn(self.network)
        self.optimizer = make_optimizer(
            config.learning_rate, config.max_grad_norm, config.schedule, config.clip_per_network
        )
        self._loss_and_grad = loss_and_grad(config, self.network)
        self.replicated = NamedSharding(mesh, P())
        # one jitted init per learner: a warm trainer's next run finds it traced
        self._init = jax.jit(self._fresh_state, out_shardings=self.replicated)

    # ------------------------------------------------------------------ state

    def init(self, key_policy: jax.Array, key_value: jax.Array) -> TrainingState:
        """Fresh network params, optimiser and normaliser state, replicated on the mesh.

        One jitted program: built op by op, the initialisers compile some fifty small
        programs one after another.
        """
        return self._init(key_policy, key_value)

    def _fresh_state(self, key_policy: jax.Array, key_value: jax.Array) -> TrainingState:
        params = init_params(self.network, key_policy, key_value)
        obs_spec = specs.Array((self.observation_size,), jnp.dtype("float32"))
        zero = jnp.zeros((), jnp.int32)  # the type jnp.asarray(0) has once made strong
        return TrainingState(
            optimizer_state=self.optimizer.init(params),
            params=params,
            normalizer_params=fix_force_scale(
                running_statistics.init_state(obs_spec), self.config.normalizer, self.force_dims
            ),
            env_steps=brax_types.UInt64(hi=zero, lo=zero),
        )

    def restore(self, state: TrainingState, params: Params) -> TrainingState:
        """``state`` with the (normaliser, policy, value) of a checkpoint."""
        normalizer, policy, value = params
        state = state.replace(
            normalizer_params=normalizer,
            params=state.params.replace(policy=policy, value=value),
        )
        return self.place(state)

    def place(self, tree: Any) -> Any:
        """``tree`` replicated on every device of the mesh (weak types made strong)."""
        tree = jax.tree.map(lambda x: jnp.asarray(x, jnp.asarray(x).dtype), tree)
        return jax.device_put(tree, self.replicated)

    @staticmethod
    def params(state: TrainingState) -> Params:
        """(normaliser, policy, value) of ``state`` as host numpy arrays."""
        return jax.device_get((state.normalizer_params, state.params.policy, state.params.value))

    # ------------------------------------------------------------------ training

    def epoch_programs(self, env: Any, sizes: EpochSizes, env_shardings: Any) -> EpochPrograms:
        """The training step as two jitted programs: the rollout (the env's) and the update
        (the env's only through the sizes of its observation and action).

        The update does not depend on the arm or the task, so JAX's persistent cache serves it
        to every arm and task of the same observation and action sizes and config, and on the
        C MuJoCo backend (whose rollout holds host callbacks JAX cannot store) it is the part
        a new process finds compiled.

        Args:
            env: the batched training env (Brax wrappers), its batch axis first.
            sizes: the epoch's cut.
            env_shardings: shardings of the env state (see :func:`batch_sharding`).
        """
        rep, split = self.replicated, NamedSharding(self.mesh, P(ENV_AXIS))
        rollout = jax.jit(
            functools.partial(self._rollout_step, env, sizes.unrolls),
            in_shardings=(rep, env_shardings, rep),
            out_shardings=(env_shardings, split, rep),
            donate_argnums=(1,),
        )
        update = jax.jit(
            functools.partial(self._update_step, sizes.env_steps_per_step),
            in_shardings=(rep, split, rep),
            out_shardings=(rep, rep),
            donate_argnums=(0,),
        )
        return EpochPrograms(rollout, update, sizes.steps_per_epoch)

    def _rollout_step(self, env: Any, unrolls: int, state: TrainingState, env_state: Any, key):
        """The rollout of one training step: ``(env_state, data, (key_sgd, key_next))``; data
        holds what the update reads, ``(num_envs * unrolls, T, ...)``."""
        key_sgd, key_unroll, key_next = jax.random.split(key, 3)
        policy = self.make_policy(
            (state.normalizer_params, state.params.policy, state.params.value)
        )
        env_state, data = self._rollout(env, env_state, policy, key_unroll, unrolls)
        # strong types: the compiled rollout takes back exactly the types it returns
        env_state = jax.tree.map(lambda x: x.astype(x.dtype), env_state)
        return env_state, update_view(data), jnp.stack([key_sgd, key_next])

    def _update_step(self, env_steps: int, state: TrainingState, data: Any, key_sgd: jax.Array):
        """The PPO update of one training step on ``data``: ``(state, mean metrics)``."""
        normalizer = normalizer_update(
            state.normalizer_params, data.observation, self.config.normalizer, self.force_dims
        )
        read = normalizer  # the statistics the losses read (Brax's order: the moved ones)
        if self.config.normalizer.after_update:
            read = _rollouts_statistics(state.normalizer_params, normalizer)
        (optimizer_state, params, _, _), metrics = jax.lax.scan(
            functools.partial(self._sgd_epoch, data=data, normalizer=read),
            (state.optimizer_state, state.params, key_sgd, jnp.bool_(False)),
            (),
            length=self.config.num_updates_per_batch,
        )
        state = TrainingState(
            optimizer_state=optimizer_state,
            params=params,
            normalizer_params=normalizer,
            env_steps=state.env_steps + env_steps,
        )
        means = jax.tree.map(jnp.mean, metrics)
        return state, {**means, **before_update(metrics), **episode_counts(data)}

    def _rollout(self, env: Any, env_state: Any, policy: Any, key: jax.Array, unrolls: int):
        """``unrolls`` unrolls of every env; transitions as ``(num_envs * unrolls, T, ...)``."""
        length = self.config.unroll_length

        def unroll(carry: tuple, _: Any):
            env_state, key = carry
            key, key_next = jax.random.split(key)
            env_state, data = acting.generate_unroll(
                env, env_state, policy, key, length, extra_fields=STATE_EXTRAS
            )
            return (env_state, key_next), data

        (env_state, _), data = jax.lax.scan(unroll, (env_state, key), (), length=unrolls)
        # (unrolls, T, envs, ...) -> (envs, unrolls, T, ...) -> (envs * unrolls, T, ...): the
        # env axis stays first, so each device keeps the transitions of its own envs.
        data = jax.tree.map(lambda x: jnp.moveaxis(x, 2, 0), data)
        data = jax.tree.map(lambda x: x.reshape((-1, *x.shape[2:])), data)
        return env_state, data

    def _sgd_epoch(self, carry: tuple, _: Any, data: Any, normalizer: Any):
        """One pass over the rollout in ``num_minibatches`` shuffled minibatches; ``carry`` is
        ``(optimizer_state, params, key, stopped)``, ``stopped`` set once the update's KL passed
        ``kl_stop``."""
        optimizer_state, params, key, stopped = carry
        key, key_perm, key_grad = jax.random.split(key, 3)
        count = self.config.num_minibatches
        split = NamedSharding(self.mesh, P(None, ENV_AXIS))

        def minibatches(x: jax.Array) -> jax.Array:
            x = jax.random.permutation(key_perm, x)
            x = x.reshape((count, -1, *x.shape[1:]))
            return jax.lax.with_sharding_constraint(x, split)

        (optimizer_state, params, _, stopped), metrics = jax.lax.scan(
            functools.partial(self._minibatch_step, normalizer=normalizer),
            (optimizer_state, params, key_grad, stopped),
            jax.tree.map(minibatches, data),
            length=count,
        )
        return (optimizer_state, params, key, stopped), metrics

    def _minibatch_step(self, carry: tuple, batch: Any, normalizer: Any):
        """One gradient step on one minibatch ``(batch_size, T, ...)``; with an adaptive
        schedule the rate is first moved by the minibatch's KL (:mod:`mjx_arm.train.schedule`).
        Once a minibatch's KL passes ``kl_stop`` (when set), it and every later minibatch of the
        update leave params and optimiser state as they are (``skipped_fraction`` is 1)."""
        optimizer_state, params, key, stopped = carry
        key, key_loss = jax.random.split(key)
        (_, metrics), grads = self._loss_and_grad(params, normalizer, batch, key_loss)
        schedule, before = self.config.schedule, (optimizer_state, params)
        if schedule.adaptive:
            rate = current_rate(optimizer_state, self.config.learning_rate)
            optimizer_state = with_rate(
                optimizer_state, adapted_rate(rate, metrics["kl_mean"], schedule)
            )
        metrics["grad_norm"] = optax.tree_utils.tree_norm(grads)
        metrics["policy_grad_norm"] = optax.tree_utils.tree_norm(grads.policy)
        metrics["value_grad_norm"] = optax.tree_utils.tree_norm(grads.value)
        updates, optimizer_state = self.optimizer.update(grads, optimizer_state)
        params = optax.apply_updates(params, updates)
        if self.config.kl_stop > 0:
            stopped = stopped | (metrics["kl_mean"] > self.config.kl_stop)
            optimizer_state, params = jax.tree.map(
                lambda old, new: jnp.where(stopped, old, new), before, (optimizer_state, params)
            )
        metrics["learning_rate"] = current_rate(optimizer_state, self.config.learning_rate)
        metrics["skipped_fraction"] = stopped.astype(jnp.float32)
        return (optimizer_state, params, key, stopped), metrics


def _rollouts_statistics(rollout: Any, moved: Any) -> Any:
    """The normaliser statistics the rollout acted with, except before the first update, when
    they are still empty (no observation taken in): then the moved ones, so that the first
    update does not fit the policy to raw observations."""
    count = rollout.count  # Brax's UInt64 (two uint32 halves), or an integer array
    empty = (count.hi == 0) & (count.lo == 0) if hasattr(count, "hi") else count == 0
    return jax.tree.map(lambda old, new: jnp.where(empty, new, old), rollout, moved)


@dataclass(frozen=True)
class EpochPrograms:
    """A training epoch as ``steps`` rounds of two jitted programs.

    Attributes:
        rollout: ``(state, env_state, key) -> (env_state, data, keys (2, ...))``.
        update: ``(state, data, key_sgd) -> (state, mean metrics)``.
        steps: training steps per epoch.
    """

    rollout: Callable
    update: Callable
    steps: int

    def lower(self, state: Any, env_state: Any, key: jax.Array) -> dict[str, Any]:
        """Both programs lowered for these arguments (shapes suffice): name -> Lowered."""
        rollout = self.rollout.lower(state, env_state, key)
        _, data, keys = jax.eval_shape(self.rollout, state, env_state, key)
        key_sgd = jax.ShapeDtypeStruct(keys.shape[1:], keys.dtype)
        return {"rollout": rollout, "update": self.update.lower(state, data, key_sgd)}

    def with_programs(self, rollout: Callable, update: Callable) -> EpochPrograms:
        """The same epoch on other (e.g. compiled) programs."""
        return EpochPrograms(rollout, update, self.steps)

    def __call__(self, state: Any, env_state: Any, key: jax.Array):
        """One epoch: ``(state, env_state, metrics)``, the metrics (host numpy) averaged over
        the epoch's training steps, with ``rollout_s`` and ``update_s``: the epoch's seconds in
        each program (each rollout is waited for before its update is sent, which costs one
        dispatch's overlap)."""
        metrics, seconds = [], {"rollout_s": 0.0, "update_s": 0.0}
        for _ in range(self.steps):
            start = time.perf_counter()
            env_state, data, keys = jax.block_until_ready(self.rollout(state, env_state, key))
            middle = time.perf_counter()
            state, step_metrics = jax.block_until_ready(self.update(state, data, keys[0]))
            seconds["rollout_s"] += middle - start
            seconds["update_s"] += time.perf_counter() - middle
            key = keys[1]
            metrics.append(step_metrics)
        metrics = jax.device_get(metrics)
        rates = episode_rates(metrics)  # sums over the epoch, not means
        mean = jax.tree.map(lambda *xs: np.mean(np.stack(xs)), *metrics)
        return state, env_state, {**mean, **rates, **seconds}
