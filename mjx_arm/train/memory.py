"""The host memory a training run needs, estimated before anything is allocated.

On the C MuJoCo backend (and on any CPU-only JAX) every array of a run lives in host memory: the
training envs' state, the evaluation envs', the rollout's transitions and the update's copies of
them. :func:`check_training_memory` adds them up from the env's shapes and the config's sizes and
refuses a run that cannot fit, naming the estimate, the available memory and the largest
``num_envs`` that fits, instead of letting the run grow until the host swaps or kills it.
"""

from __future__ import annotations

from typing import Any

from mjx_arm.envs.backend import (
    InsufficientMemoryError,
    MemoryEstimate,
    available_memory,
    estimate_env_memory,
    state_on_host,
)
from mjx_arm.train.config import TrainConfig

# Copies of one update's transitions alive at once: the rollout's output, its shuffled
# minibatches and the gradient step's inputs.
TRANSITION_COPIES = 3
# float32 numbers of a transition besides the observations and actions: reward, discount,
# truncation, log-probability and the env's per-step metrics (about 20).
TRANSITION_SCALARS = 24


def transition_bytes(obs_size: int, action_size: int) -> int:
    """Bytes of one stored transition: observation and next observation ``(obs,)``, action and
    raw action ``(act,)``, and :data:`TRANSITION_SCALARS` scalars, float32."""
    return 4 * (2 * obs_size + 2 * action_size + TRANSITION_SCALARS)


def training_estimate(config: TrainConfig, env: Any) -> tuple[MemoryEstimate, int]:
    """(the estimate per training env, the bytes that do not grow with ``num_envs``).

    Per training env: its state (:func:`~mjx_arm.envs.backend.estimate_env_memory`). Apart from
    ``num_envs``: the evaluation envs, and the transitions of one update, ``batch_size *
    num_minibatches * unroll_length`` of them (:meth:`TrainConfig.samples_per_update`), times
    :data:`TRANSITION_COPIES`, plus each minibatch's network activations (float32, three per
    hidden unit: pre-activation, activation, gradient).
    """
    envs = estimate_env_memory(env, randomized=config.randomization.enabled)
    per_sample = transition_bytes(env.observation_size, env.action_size)
    buffers = TRANSITION_COPIES * config.samples_per_update() * per_sample
    hidden = sum(config.policy_hidden) + sum(config.value_hidden)
    activations = 3 * 4 * hidden * config.batch_size * config.unroll_length
    evaluation = envs.per_env * config.num_eval_envs
    return envs, envs.fixed + buffers + activations + evaluation


def check_training_memory(config: TrainConfig, env: Any, available: int | None = None) -> None:
    """Refuse a run whose estimated host memory exceeds the available memory, where the envs'
    state lives in host memory (:func:`~mjx_arm.envs.backend.state_on_host`).

    Raises:
        InsufficientMemoryError: the estimate, the available figure and the largest num_envs
            that fits (with the other settings unchanged).
    """
    if available is None and not state_on_host(env):
        return
    available = available_memory() if available is None else available
    envs, rest = training_estimate(config, env)
    need = rest + envs.per_env * config.num_envs
    if need <= available:
        return
    fits = max(0, (available - rest) // max(envs.per_env, 1))
    samples = config.samples_per_update()
    advice = (
        f"the largest num_envs that fits is about {fits}"
        if fits
        else f"lower batch_size * num_minibatches * unroll_length (now {samples} transitions "
        "per update) first"
    )
    raise InsufficientMemoryError(
        f"num_envs={config.num_envs} with {samples} transitions per update needs about "
        f"{need / 2**30:.1f} GiB of host memory, but {available / 2**30:.1f} GiB is available: "
        f"{advice}"
    )
