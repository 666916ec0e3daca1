"""The episode every checkpoint records (``transitions.npz``): one env and one compiled policy
for all checkpoints of a run, the same episode for the same params and seed."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from mjx_arm.task.config import task_config
from mjx_arm.train.episode import TRANSITIONS_KEPT, CheckpointEpisode


def _make_policy(params, deterministic: bool = False):
    """A linear policy on the first six observation entries (a stand-in for Brax's network)."""
    del deterministic
    return lambda obs, key: (jnp.tanh(obs[..., :6] * params["w"]), {})


def test_checkpoints_share_one_env_and_repeat_an_episode():
    """Two records of the same params and seed are equal to the bit, from one env built once;
    another seed starts elsewhere; the arrays have their documented shapes (at most the last
    100 transitions)."""
    episode = CheckpointEpisode(_make_policy, task_config("reach"))
    params = {"w": np.full(6, 0.5, np.float32)}
    first = episode.record(params, seed=3)
    env = episode._env
    again = episode.record(params, seed=3)
    other = episode.record(params, seed=4)
    assert episode._env is env
    for name, value in first.items():
        np.testing.assert_array_equal(value, again[name], err_msg=name)
    assert not np.array_equal(first["obs"][0], other["obs"][0])
    steps = len(first["reward"])
    assert 0 < steps <= TRANSITIONS_KEPT
    assert first["obs"].shape == (steps, 22) and first["action"].shape == (steps, 6)
    assert first["ee_pos"].shape == (steps, 3) and first["contact_force"].shape == (steps,)
    np.testing.assert_allclose(first["action"], np.tanh(first["obs"][:, :6] * 0.5), atol=1e-6)
    episode.close()
    assert episode._env is None
