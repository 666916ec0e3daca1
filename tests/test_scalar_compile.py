"""The step rules traced into one Python function score every step as the rules do through the
scalar namespace: the same values, bit for bit, and the same Python types, for every task, on
sane and diverged steps, NaN and infinities included; a rule that branches on a value is not
traced. No physics engine except the last test (one CPU MuJoCo episode, about a second)."""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np
import pytest

from mjx_arm.envs.scalar.codegen import Untraceable, compile_score
from mjx_arm.envs.scalar.step import StepInput, score_generic
from mjx_arm.envs.scalar.xp import SCALAR_XP
from mjx_arm.task import reach_config, register_task, touch_config
from mjx_arm.task import reward as reward_lib
from mjx_arm.task.lift import lift_config
from mjx_arm.task.reach import Reach
from mjx_arm.task.rules import score_step
from mjx_arm.task.wrench import ToolInertia, external_wrench, external_wrench_features

BAND = reward_lib.JointBand([0.1, -0.2, 0.0, 0.3, 0.0, -1.0], [1.8, 2.0, 1.5, 2.2, 3.0, 2.5])
ODD = [math.nan, math.inf, -math.inf, -0.0]  # values the rules must carry as numpy would


def _same(a: Any, b: Any) -> bool:
    """Equal values of the same type, NaN equal to NaN."""
    if type(a) is not type(b):
        return False
    if isinstance(a, dict):
        return list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, float) and math.isnan(a):
        return math.isnan(b)
    return a == b and (not isinstance(a, float) or math.copysign(1, a) == math.copysign(1, b))


def _steps(rng: np.random.Generator, n: int, lift: bool):
    """Steps near and far, forces below, in and above the band, holds under way, joints beyond
    their band, and now and then a NaN or an infinity in any input."""
    for _ in range(n):
        x = {
            "hold": float(rng.integers(0, 12)),
            "over": bool(rng.random() < 0.2),
            "prev_distance": float(rng.uniform(0.0, 0.2)),
            "change": float(rng.uniform(0.0, 2.0)),
            "distance": float(rng.choice([0.004, 0.015, 0.04, 0.3]) * rng.uniform(0.5, 1.5)),
            "force": float(rng.choice([0.0, 0.5, 10.0, 45.0, 70.0, 130.0])),
            "qpos": rng.uniform(-2.5, 3.5, 6).tolist(),
            "qvel": rng.normal(0.0, 1.0, 6).tolist(),
            "measures": [
                float(rng.choice([0.0, 0.05, 0.1, 0.2])),
                float(rng.random() < 0.5),
                float(rng.choice([0.0, 0.4, 1.0])),
                float(rng.random() < 0.3),
            ]
            if lift
            else [],
        }
        if rng.random() < 0.15:  # an odd value somewhere
            key = rng.choice(["prev_distance", "change", "distance", "force", "qpos", "qvel"])
            odd = float(rng.choice(ODD))
            if key in ("qpos", "qvel"):
                x[key][int(rng.integers(6))] = odd
            else:
                x[key] = odd
        yield x


@pytest.mark.parametrize(
    "make_cfg",
    [reach_config, touch_config, lambda: touch_config("seed"), lift_config,
     lambda: touch_config(success_hold_steps=1, terminate_on_overforce=False)],
)  # fmt: skip
@pytest.mark.parametrize("diverged", [False, True])
def test_traced_rules_are_the_scalar_rules_bit_for_bit(make_cfg, diverged: bool) -> None:
    cfg = make_cfg()
    lift = cfg.task == "lift"
    keys = ("height", "grasp", "cradle", "stray") if lift else ()
    score = compile_score(cfg, 6, BAND, diverged, keys)
    for x in _steps(np.random.default_rng(7), 400, lift):
        extra = dict(zip(keys, x["measures"], strict=True)) or None
        ref = score_step(
            SCALAR_XP, cfg, reward_lib.Progress(x["hold"], x["over"]), x["prev_distance"],
            x["change"], x["distance"], x["force"], x["qpos"], x["qvel"], BAND, diverged, extra,
        )  # fmt: skip
        out = score(StepInput(
            reward_lib.Progress(x["hold"], x["over"]), x["prev_distance"], x["change"],
            x["distance"], x["force"], x["qpos"], x["qvel"], tuple(x["measures"]),
        ))  # fmt: skip
        got = (*out.progress, *out[1:])
        want = (*ref.progress, ref.success, ref.over, ref.terms, ref.reward, ref.done)
        assert all(_same(a, b) for a, b in zip(got, want, strict=True)), (x, got, want)


class _Branchy(Reach):
    """A task whose success test branches on the distance in Python."""

    name = "branchy"

    def holds(self, xp: Any, distance, force_norm, cfg, extra=None):
        return bool(distance < cfg.success_distance)  # a Python truth test of a value


def test_rules_that_branch_on_a_value_are_not_traced(monkeypatch) -> None:
    from mjx_arm.task import registry

    register_task(_Branchy())
    monkeypatch.setitem(registry._TASKS, "branchy", registry._TASKS["branchy"])  # undone after
    cfg = reach_config().replace(task="branchy")
    with pytest.raises(Untraceable):
        compile_score(cfg, 6, BAND, False)


def test_one_env_wrench_features_are_external_wrench() -> None:
    rng = np.random.default_rng(3)
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    tool = ToolInertia(1.3, rng.normal(size=3), np.diag([0.01, 0.02, 0.03]), rng.normal(size=3),
                       rot)  # fmt: skip
    for _ in range(50):
        parts = [rng.normal(size=3) for _ in range(5)]  # force, torque, acc, omega, alpha
        want = external_wrench(np, *parts, tool)
        got = np.array(external_wrench_features(*(p.tolist() for p in parts)))
        np.testing.assert_array_equal(got.dot(tool.wrench_matrix), want)


def test_an_env_scores_its_steps_as_the_rules_do() -> None:
    """One Touch episode on CPU MuJoCo with the traced rules and again through SCALAR_XP:
    the same observations, rewards, flags and info."""
    import gymnasium as gym

    import mjx_arm  # noqa: F401  (registers the ids)

    env = gym.make("mjx_arm/Touch-v0").unwrapped
    actions = np.random.default_rng(0).uniform(-1, 1, (60, 6)).astype(np.float32)
    traced = env._scores
    assert all(hasattr(fn, "source") for fn in traced)  # the traced functions
    keys = ()
    generic = tuple(
        functools.partial(score_generic, env.task, env._band_lists, d, keys) for d in (False, True)
    )
    runs = []
    for scores in (traced, generic):
        env._scores = scores
        env.reset(seed=4)
        runs.append([env.step(a) for a in actions])
    for a, b in zip(*runs, strict=True):
        obs_a, reward_a, done_a, _, info_a = a
        obs_b, reward_b, done_b, _, info_b = b
        assert all(np.array_equal(obs_a[k], obs_b[k]) for k in obs_a)
        assert _same(reward_a, reward_b) and done_a is done_b
        assert all(_same(info_a[k], info_b[k]) for k in info_b)
    env.close()
