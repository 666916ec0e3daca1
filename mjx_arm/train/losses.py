"""The PPO loss: Brax's ``compute_ppo_loss`` with the coefficients of a training config.

As in Brax's ``agents/ppo/losses.py``, the loss of one minibatch is the clipped surrogate policy
loss, the value loss and the entropy bonus, on advantages from generalised advantage estimation
(normalised per minibatch). Its metrics (``policy_loss``, ``v_loss``, ``entropy_loss``,
``kl_mean``, ``policy_dist_mean_std``, ...) are what the run logs as ``training/...``, with the
figures PPO practitioners read beside them (:func:`diagnostics`): the clip fraction, an
estimate of the KL from the action log-probabilities, the entropy itself and the value
function's explained variance.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from brax.training import gradients
from brax.training.agents.ppo import losses as ppo_losses
from brax.training.agents.ppo import networks as ppo_networks

from mjx_arm.train.config import TrainConfig

PPONetworkParams = ppo_losses.PPONetworkParams

# (params, normaliser state, transitions (batch, T, ...), key) -> (loss, metrics)
Loss = Callable[[PPONetworkParams, Any, Any, jax.Array], tuple[jax.Array, dict[str, jax.Array]]]


def ppo_loss(config: TrainConfig, network: ppo_networks.PPONetworks) -> Loss:
    """The PPO loss of ``network`` with the discount, GAE, clipping and loss weights of
    ``config``."""
    return functools.partial(
        ppo_losses.compute_ppo_loss,
        ppo_network=network,
        entropy_cost=config.entropy_cost,
        discounting=config.discounting,
        reward_scaling=config.reward_scaling,
        gae_lambda=config.gae_lambda,
        clipping_epsilon=config.clipping_epsilon,
        normalize_advantage=True,
        vf_coefficient=config.vf_loss_coefficient,
    )


def loss_and_grad(config: TrainConfig, network: ppo_networks.PPONetworks) -> Callable:
    """``(params, normaliser, batch, key) -> ((loss, metrics), grads)`` of :func:`ppo_loss`,
    the metrics with :func:`diagnostics` added.

    The loss is a mean over the global minibatch: under ``jax.jit`` over a device mesh XLA
    reduces the gradient across devices itself, so no ``pmap`` axis is named.
    """
    loss = ppo_loss(config, network)

    def with_diagnostics(params, normalizer, data, key):
        value, metrics = loss(params, normalizer, data, key)
        extra = diagnostics(config, network, params, normalizer, data, key)
        return value, {**metrics, **extra}

    return gradients.loss_and_pgrad(with_diagnostics, pmap_axis_name=None, has_aux=True)


def diagnostics(
    config: TrainConfig, network: ppo_networks.PPONetworks, params, normalizer, data, key
) -> dict[str, jax.Array]:
    """What a PPO update does to the policy and how well the value function fits, for one
    minibatch ``data`` (transitions ``(batch, T, ...)``), outside the gradient.

    Returns:
        Scalars: ``clip_fraction`` (share of transitions whose probability ratio left
        ``1 +- clipping_epsilon``), ``approx_kl`` (the estimator ``mean(r - 1 - log r)`` of
        KL(rollout policy || current), from log-probabilities), ``entropy`` (the policy's
        entropy itself, not its cost), ``explained_variance`` (``1 - var(vs - V) / var(vs)``
        of the GAE value targets ``vs``; 1 is a perfect fit, 0 no better than their mean), and
        the largest ``|reward|`` (scaled) and ``|vs|`` of the minibatch (``reward_abs_max``,
        ``value_target_abs_max``: what a value loss far from its usual size comes from).
    """
    params, data = jax.lax.stop_gradient((params, data))
    data = jax.tree.map(lambda x: jnp.swapaxes(x, 0, 1), data)  # time first, as Brax's loss
    dist = network.parametric_action_distribution
    logits = network.policy_network.apply(normalizer, params.policy, data.observation)
    extras = data.extras["policy_extras"]
    log_ratio = dist.log_prob(logits, extras["raw_action"]) - extras["log_prob"]
    ratio = jnp.exp(log_ratio)
    values = network.value_network.apply(normalizer, params.value, data.observation)
    targets = _value_targets(config, network, params, normalizer, data, values)
    residual = jnp.var(targets - values) / jnp.maximum(jnp.var(targets), 1e-8)
    return {
        "clip_fraction": jnp.mean(jnp.abs(ratio - 1.0) > config.clipping_epsilon),
        "approx_kl": jnp.mean(ratio - 1.0 - log_ratio),
        "entropy": jnp.mean(dist.entropy(logits, key)),
        "explained_variance": 1.0 - residual,
        "reward_abs_max": jnp.max(jnp.abs(data.reward * config.reward_scaling)),
        "value_target_abs_max": jnp.max(jnp.abs(targets)),
    }


def _value_targets(config: TrainConfig, network, params, normalizer, data, values) -> jax.Array:
    """The GAE value targets ``vs`` ``(T, batch)`` of time-first ``data``, as Brax's loss."""
    last = jax.tree.map(lambda x: x[-1], data.next_observation)
    bootstrap = network.value_network.apply(normalizer, params.value, last)
    truncation = data.extras["state_extras"]["truncation"]
    targets, _ = ppo_losses.compute_gae(
        truncation=truncation,
        termination=(1 - data.discount) * (1 - truncation),
        rewards=data.reward * config.reward_scaling,
        values=values,
        bootstrap_value=bootstrap,
        lambda_=config.gae_lambda,
        discount=config.discounting,
    )
    return targets


def init_params(
    network: ppo_networks.PPONetworks, key_policy: jax.Array, key_value: jax.Array
) -> PPONetworkParams:
    """Fresh policy and value params of ``network`` (the loss's first argument)."""
    return PPONetworkParams(
        policy=network.policy_network.init(key_policy),
        value=network.value_network.init(key_value),
    )
