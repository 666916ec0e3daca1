"""What an epoch logs beside its losses, from the rollout's transitions and the update's
metrics: the KL and clip fraction before the update's first step, and the training episodes
that ended and succeeded (``training/episodes``, ``training/episode_success``)."""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp


def before_update(metrics: dict[str, jax.Array]) -> dict[str, jax.Array]:
    """The first minibatch's KL and clip fraction, ``(passes, minibatches)`` metrics at
    ``[0, 0]``: measured before the update's first gradient step, so the policy differs from the
    rollout's only by the observation normaliser, which the update moved first."""
    return {
        "kl_before_update": metrics["kl_mean"][0, 0],
        "clip_fraction_before_update": metrics["clip_fraction"][0, 0],
    }


def update_view(data: Any) -> Any:
    """The transitions as the update reads them: the task's episode metrics (the env's, which
    would make the update's program differ from task to task) replaced by ``episode_success``
    ``(N, T)``: 1 where an episode ended with a success, else 0."""
    extras = dict(data.extras)
    state_extras = dict(extras["state_extras"])
    episode = state_extras.pop("episode_metrics")
    ended = state_extras["episode_done"]
    success = episode.get("success", jnp.zeros_like(ended))
    state_extras["episode_success"] = ended * (success > 0).astype(ended.dtype)
    extras["state_extras"] = state_extras
    return data._replace(extras=extras)


def episode_counts(data: Any) -> dict[str, jax.Array]:
    """The training episodes that ended in ``data`` and those of them that succeeded (their
    policy samples its actions, unlike an evaluation's): scalar sums over every env."""
    extras = data.extras["state_extras"]
    return {
        "episodes": jnp.sum(extras["episode_done"]),
        "episode_successes": jnp.sum(extras["episode_success"]),
    }


EPISODE_COUNTS = ("episodes", "episode_successes")


def episode_rates(steps_metrics: list[dict[str, Any]]) -> dict[str, Any]:
    """The episode counts of :func:`episode_counts` taken out of each training step's metrics
    (host values, in place) and summed over the epoch: ``episodes`` (ended in the epoch) and
    ``episode_success`` (the fraction of them that succeeded; 0 where none ended)."""
    episodes, successes = (sum(float(m.pop(k)) for m in steps_metrics) for k in EPISODE_COUNTS)
    return {
        "episodes": round(episodes),
        "episode_success": successes / episodes if episodes else 0.0,
    }
