"""Brax PPO's policy and value networks, built in one place for training and for checking an
exported policy against the training code."""

from __future__ import annotations

from brax.training import types as brax_types
from brax.training.agents.ppo import networks as ppo_networks

from mjx_arm.train.config import TrainConfig
from mjx_arm.train.normalizer import normalize_fn

# The "normal" policy's std at the start, per action entry: the tanh-normal policy's starting
# std before the tanh (softplus(0) = 0.69).
NORMAL_INIT_STD = 0.7


def make_networks(
    config: TrainConfig, observation_size: int, action_size: int
) -> ppo_networks.PPONetworks:
    """The PPO networks of ``config`` (layer sizes, observation normalisation, the policy's
    action distribution: :attr:`~mjx_arm.train.config.TrainConfig.policy_distribution`).

    Args:
        config: the training config.
        observation_size: size of the flat observation (22 for the shipped arm).
        action_size: size of the action (6 for the shipped arm).
    """
    normalize = (
        normalize_fn(config.normalizer)
        if config.normalize_observations
        else brax_types.identity_observation_preprocessor
    )
    distribution = {}
    if config.policy_distribution == "normal":
        distribution = {
            "distribution_type": "normal",
            "noise_std_type": "log",
            "init_noise_std": NORMAL_INIT_STD,
            "state_dependent_std": False,
            "mean_clip_scale": 1.0,
        }
    return ppo_networks.make_ppo_networks(
        observation_size,
        action_size,
        preprocess_observations_fn=normalize,
        policy_hidden_layer_sizes=config.policy_hidden,
        value_hidden_layer_sizes=config.value_hidden,
        **distribution,
    )
