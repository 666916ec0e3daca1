"""The step rules run once for every engine: numpy one env at a time (the CPU envs) and
jax.numpy on a batch under jit (the MJX env) score the same steps the same."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_arm.task import reach_config, touch_config
from mjx_arm.task import reward as reward_lib
from mjx_arm.task.config import REWARD_TERMS
from mjx_arm.task.rules import score_step

N = 64
LIMITS = (-np.full(6, 2.0), np.full(6, 2.0))


def _inputs(seed: int) -> dict[str, np.ndarray]:
    """A batch of steps: near and far, forces below, in and above the band, strikes, holds
    under way, joints beyond their soft limits, and a few diverged steps."""
    rng = np.random.default_rng(seed)
    return {
        "hold": rng.integers(0, 4, N).astype(float),
        "over": rng.random(N) < 0.2,
        "prev_distance": rng.uniform(0.0, 0.2, N),
        "change": rng.uniform(0.0, 2.0, N),
        "distance": rng.choice([0.004, 0.015, 0.04, 0.3], N) * rng.uniform(0.5, 1.5, N),
        "force": rng.choice([0.0, 0.5, 10.0, 45.0, 70.0, 130.0], N),
        "qpos": rng.uniform(-2.1, 2.1, (N, 6)),
        "qvel": rng.normal(0.0, 1.0, (N, 6)),
        "diverged": rng.random(N) < 0.1,
    }


def _numpy_one_by_one(cfg, x) -> list:
    band = reward_lib.joint_band(LIMITS, cfg)
    out = []
    for i in range(N):
        progress = reward_lib.Progress(np.asarray(x["hold"][i]), np.asarray(x["over"][i]))
        score = score_step(
            np, cfg, progress, float(x["prev_distance"][i]), float(x["change"][i]),
            float(x["distance"][i]), float(x["force"][i]), x["qpos"][i], x["qvel"][i],
            band, bool(x["diverged"][i]),
        )  # fmt: skip
        out.append(score)
    return out


def _jax_batch(cfg, x):
    band = reward_lib.joint_band(tuple(map(jnp.asarray, LIMITS)), cfg)

    @jax.jit
    def run(x):
        progress = reward_lib.Progress(x["hold"], x["over"])
        return score_step(
            jnp, cfg, progress, x["prev_distance"], x["change"], x["distance"], x["force"],
            x["qpos"], x["qvel"], band, x["diverged"],
        )  # fmt: skip

    f32 = {k: jnp.float32 if v.dtype.kind == "f" else v.dtype for k, v in x.items()}
    batch = {k: jnp.asarray(v, f32[k]) for k, v in x.items()}
    return run(batch)


@pytest.mark.parametrize("make_cfg", [reach_config, touch_config, lambda: touch_config("seed")])
def test_numpy_and_jax_score_the_same_steps(make_cfg) -> None:
    """Flags agree exactly; terms and rewards within float32 rounding of the JAX batch
    (rtol 1e-5 on the reward, whose terms reach 1000)."""
    cfg = make_cfg()
    x = _inputs(0)
    ones = _numpy_one_by_one(cfg, x)
    batch = jax.device_get(_jax_batch(cfg, x))
    for name in ("success", "over", "done"):
        np.testing.assert_array_equal([bool(getattr(s, name)) for s in ones], getattr(batch, name))
    np.testing.assert_array_equal([float(s.progress.hold) for s in ones], batch.progress.hold)
    np.testing.assert_array_equal([bool(s.progress.over) for s in ones], batch.progress.over)
    for term in REWARD_TERMS:
        values = [float(s.terms[term]) for s in ones]
        np.testing.assert_allclose(values, batch.terms[term], rtol=1e-5, atol=1e-5, err_msg=term)
    np.testing.assert_allclose([float(s.reward) for s in ones], batch.reward, rtol=1e-5, atol=1e-4)
    assert any(bool(s.success) for s in ones) or cfg.task == "touch"  # the batch covers success


def test_a_diverged_step_scores_only_its_penalty() -> None:
    """Divergence: every term but ``nonfinite`` is zero, no success, and the episode ends."""
    cfg = touch_config()
    band = reward_lib.joint_band(LIMITS, cfg)
    progress = reward_lib.Progress(np.asarray(2.0), np.asarray(False))
    score = score_step(
        np, cfg, progress, 0.01, 0.5, 0.005, 10.0, np.zeros(6), np.ones(6), band, True
    )
    assert not score.success and bool(score.done)
    assert score.terms["nonfinite"] == 1.0
    assert all(float(v) == 0.0 for k, v in score.terms.items() if k != "nonfinite")
    assert float(score.reward) == pytest.approx(cfg.reward.nonfinite)
