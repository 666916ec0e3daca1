"""The PPO loss: Brax's ``compute_ppo_loss`` with the coefficients of a training config.

As in Brax's ``agents/ppo/losses.py``, the loss of one minibatch is the clipped surrogate policy
loss, the value loss and the entropy bonus, on advantages from generalised advantage estimation
(normalised per minibatch). Its metrics (``policy_loss``, ``v_loss``, ``entropy_loss``, ...) are
what the run logs as ``training/...``.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import jax
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
    """``(params, normaliser, batch, key) -> ((loss, metrics), grads)`` of :func:`ppo_loss`.

    The loss is a mean over the global minibatch: under ``jax.jit`` over a device mesh XLA
    reduces the gradient across devices itself, so no ``pmap`` axis is named.
    """
    return gradients.loss_and_pgrad(ppo_loss(config, network), pmap_axis_name=None, has_aux=True)


def init_params(
    network: ppo_networks.PPONetworks, key_policy: jax.Array, key_value: jax.Array
) -> PPONetworkParams:
    """Fresh policy and value params of ``network`` (the loss's first argument)."""
    return PPONetworkParams(
        policy=network.policy_network.init(key_policy),
        value=network.value_network.init(key_value),
    )
