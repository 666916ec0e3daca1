"""The step rules run once for every engine: Python scalars one env at a time (the CPU envs,
through ``SCALAR_XP``), numpy and jax.numpy on a batch under jit (the MJX env) score the same
steps the same."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_arm.envs.scalar.xp import SCALAR_XP
from mjx_arm.task import reach_config, touch_config
from mjx_arm.task import reward as reward_lib
from mjx_arm.task.config import REWARD_TERMS
from mjx_arm.task.lift import lift_config
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


def _forfeiting() -> object:
    """Touch whose press pay ends once a reading over the band has ruled success out."""
    return touch_config(pay_after_overforce=False)


@pytest.mark.parametrize(
    "make_cfg", [reach_config, touch_config, lambda: touch_config("seed"), _forfeiting]
)
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


@pytest.mark.parametrize("pays_on", [True, False])
def test_a_reading_over_the_band_can_forfeit_the_press_pay(pays_on: bool) -> None:
    """A press held in the band at the box (25 N, 4 mm, its second step): before any reading
    over the band it pays ``contact`` and ``streak``; after one (success ruled out) it pays them
    on only with ``pay_after_overforce`` (the default), else nothing, and the reward is lower by
    exactly their weighted sum (the other terms are the same)."""
    cfg = touch_config(pay_after_overforce=pays_on)
    band = reward_lib.joint_band(LIMITS, cfg)

    def press(over: bool):
        progress = reward_lib.Progress(np.asarray(1.0), np.asarray(over))
        return score_step(np, cfg, progress, 0.005, 0.0, 0.004, 25.0, np.zeros(6), np.zeros(6),
                          band, False)  # fmt: skip

    clean, after = press(False), press(True)
    assert float(clean.terms["contact"]) == 1.0 and float(clean.terms["streak"]) == 0.5
    assert not clean.success and not after.success  # two steps of three: not yet
    paid = {k: float(after.terms[k]) for k in ("contact", "streak")}
    assert paid == ({"contact": 1.0, "streak": 0.5} if pays_on else {"contact": 0.0, "streak": 0.0})
    lost = 0.0 if pays_on else cfg.reward.contact + 0.5 * cfg.reward.streak
    assert float(clean.reward) - float(after.reward) == pytest.approx(lost)


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


def _extra(seed: int) -> dict[str, np.ndarray]:
    """Lift's measures of the batch: heights below, at and above the lift, grasped or not,
    the fingers open, half closed or closed around the cube."""
    rng = np.random.default_rng(seed)
    height = rng.choice([0.0, 0.05, 0.1, 0.15], N) * rng.uniform(0.9, 1.1, N)
    cradle = rng.choice([0.0, 0.4, 1.0], N)
    stray = (rng.random(N) < 0.3) * 1.0
    return {
        "height": height,
        "grasp": (rng.random(N) < 0.5) * 1.0,
        "cradle": cradle,
        "stray": stray,
    }


def _one_by_one(xp, cfg, x, extra=None) -> list:
    """Each step scored alone: numpy on 0-d arrays and ``(6,)`` arrays, or ``SCALAR_XP`` on
    Python floats, bools and lists, as the CPU envs pass them."""
    band = reward_lib.joint_band(LIMITS, cfg)
    python = xp is SCALAR_XP
    if python:
        band = reward_lib.JointBand(band.mid.tolist(), band.reach.tolist())
    scalar = float if python else np.asarray
    out = []
    for i in range(N):
        qpos, qvel = x["qpos"][i], x["qvel"][i]
        if python:
            qpos, qvel = qpos.tolist(), qvel.tolist()
        measures = None if extra is None else {k: float(v[i]) for k, v in extra.items()}
        progress = reward_lib.Progress(scalar(x["hold"][i]), bool(x["over"][i]))
        score = score_step(
            xp, cfg, progress, float(x["prev_distance"][i]), float(x["change"][i]),
            float(x["distance"][i]), float(x["force"][i]), qpos, qvel, band,
            bool(x["diverged"][i]), measures,
        )  # fmt: skip
        out.append(score)
    return out


@pytest.mark.parametrize(
    "make_cfg", [reach_config, touch_config, lambda: touch_config("seed"), lift_config, _forfeiting]
)
def test_python_scalars_score_the_steps_numpy_scores(make_cfg) -> None:
    """``SCALAR_XP`` gives numpy's flags and hold counts exactly and its terms and rewards to
    1e-12 (the same IEEE operations; ``math.exp`` may differ from a SIMD ``np.exp`` by an ulp),
    every value a Python float or bool (what the envs' info carries)."""
    cfg = make_cfg()
    x = _inputs(1)
    extra = None
    if cfg.task == "lift":  # a lift succeeds after 10 steps held: holds under way near that
        extra, x["hold"] = _extra(1), np.random.default_rng(1).choice([0.0, 8.0, 9.0], N)
    fast, ref = _one_by_one(SCALAR_XP, cfg, x, extra), _one_by_one(np, cfg, x, extra)
    for a, b in zip(fast, ref, strict=True):
        for name in ("success", "over", "done"):
            assert type(getattr(a, name)) is bool and getattr(a, name) == bool(getattr(b, name))
        assert type(a.progress.hold) is float and a.progress.hold == float(b.progress.hold)
        assert type(a.progress.over) is bool and a.progress.over == bool(b.progress.over)
        assert all(type(v) is float for v in a.terms.values()) and type(a.reward) is float
        values = [a.terms[t] for t in REWARD_TERMS]
        np.testing.assert_allclose(values, [float(b.terms[t]) for t in REWARD_TERMS], rtol=1e-12)
        assert a.reward == pytest.approx(float(b.reward), rel=1e-12, abs=1e-12)
    assert any(s.success for s in fast) or cfg.task == "touch"
    assert any(s.done for s in fast) and not all(s.done for s in fast)


def test_python_scalars_and_jax_score_the_same_steps() -> None:
    """Touch's steps, one by one on Python scalars against the JAX batch: flags exactly, the
    reward within float32 rounding."""
    cfg = touch_config()
    x = _inputs(2)
    fast = _one_by_one(SCALAR_XP, cfg, x)
    batch = jax.device_get(_jax_batch(cfg, x))
    for name in ("success", "over", "done"):
        np.testing.assert_array_equal([getattr(s, name) for s in fast], getattr(batch, name))
    np.testing.assert_allclose([s.reward for s in fast], batch.reward, rtol=1e-5, atol=1e-4)
