"""The KL-adaptive learning rate, the normaliser's floor and clip, and the device scaling, each
against hand-worked values."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from mjx_arm.inputs import ConfigError
from mjx_arm.train.normalizer import NormalizerConfig, normalize_fn, update
from mjx_arm.train.presets import load_config
from mjx_arm.train.schedule import (
    ScheduleConfig,
    adapted_rate,
    clip_each_network,
    current_rate,
    make_optimizer,
    with_rate,
)

ADAPTIVE = ScheduleConfig(kind="adaptive", desired_kl=0.01, factor=1.5, minimum=1e-5, maximum=1e-2)


@pytest.mark.parametrize(
    ("kl", "expected"),
    [
        (0.05, 1e-3 / 1.5),  # above 2 x target: divided
        (0.02, 1e-3),  # at the band's edge: kept
        (0.01, 1e-3),  # on target: kept
        (0.004, 1e-3 * 1.5),  # below target / 2: multiplied
        (0.0, 1e-3),  # nothing measured: kept
    ],
)
def test_the_kl_rule_moves_the_rate_by_its_factor(kl: float, expected: float) -> None:
    rate = adapted_rate(jnp.float32(1e-3), jnp.float32(kl), ADAPTIVE)
    assert float(rate) == pytest.approx(expected, rel=1e-6)


def test_the_adaptive_rate_stays_within_its_bounds() -> None:
    assert float(adapted_rate(jnp.float32(1.2e-5), jnp.float32(1.0), ADAPTIVE)) == pytest.approx(
        1e-5
    )
    assert float(adapted_rate(jnp.float32(9e-3), jnp.float32(1e-4), ADAPTIVE)) == pytest.approx(
        1e-2
    )


def test_the_rate_lives_in_the_optimiser_state_and_steps_with_it() -> None:
    params = {"w": jnp.ones(3)}
    grads = {"w": jnp.full(3, 0.1)}
    optimizer = make_optimizer(1e-3, 0.5, ADAPTIVE)
    state = optimizer.init(params)
    assert float(current_rate(state, 1e-3)) == pytest.approx(1e-3)
    state = with_rate(state, 2e-3)
    assert float(current_rate(state, 1e-3)) == pytest.approx(2e-3)
    updates, _ = optimizer.update(grads, state)
    # Adam's first step moves each weight by about the rate
    np.testing.assert_allclose(np.asarray(updates["w"]), -2e-3, rtol=1e-3)


def test_a_constant_schedule_keeps_adams_plain_state() -> None:
    optimizer = make_optimizer(1e-3, 0.5, ScheduleConfig())
    state = optimizer.init({"w": jnp.ones(2)})
    assert not hasattr(state[1], "hyperparams")
    assert float(current_rate(state, 3e-4)) == pytest.approx(3e-4)


def test_each_network_is_clipped_apart_with_the_same_state() -> None:
    """A value gradient of norm 1e6 beside a policy gradient of norm 10 (as seed 8219's
    second epoch had): one global clip to 0.5 leaves the policy 5e-6 of it, the per-network clip
    0.5 each. Both optimisers keep the same state layout, so checkpoints resume under either."""
    import jax
    import optax

    from mjx_arm.train.losses import PPONetworkParams

    grads = PPONetworkParams(policy={"w": jnp.array([6.0, 8.0])}, value={"w": jnp.array([1e6])})

    def norms(clip: optax.GradientTransformation) -> tuple[float, float]:
        out, _ = clip.update(grads, clip.init(grads))
        return float(jnp.linalg.norm(out.policy["w"])), float(jnp.linalg.norm(out.value["w"]))

    assert norms(optax.clip_by_global_norm(0.5)) == pytest.approx((5e-6, 0.5), rel=1e-4)
    assert norms(clip_each_network(0.5)) == pytest.approx((0.5, 0.5), rel=1e-5)
    states = [make_optimizer(1e-3, 0.5, ScheduleConfig(), each).init(grads) for each in (0, 1)]
    assert jax.tree.structure(states[0]) == jax.tree.structure(states[1])


def test_bad_schedule_and_normalizer_settings_are_named() -> None:
    with pytest.raises(ConfigError, match=r"schedule\.kind"):
        load_config("cpu", None, ["schedule.kind=cosine"])
    with pytest.raises(ConfigError, match=r"schedule\.factor"):
        load_config("cpu", None, ["schedule.factor=1"])
    with pytest.raises(ConfigError, match=r"normalizer\.clip"):
        load_config("cpu", None, ["normalizer.clip=-1"])
    with pytest.raises(ConfigError, match=r"normalizer\.force_scale"):
        load_config("cpu", None, ["normalizer.force_scale=-50"])


def test_the_std_floor_and_clip_bound_a_dimension_that_was_constant() -> None:
    """A dimension that read 0 in every first observation (a wrist force before any touch):
    Brax's floor (1e-6) turns a 5 N reading into millions, a floor of 0.01 and a clip of 10
    into 10."""
    from brax.training.acme import running_statistics, specs

    spec = specs.Array((2,), jnp.dtype("float32"))
    first = jnp.array([[0.0, 1.0], [0.0, -1.0]] * 8)
    touch = jnp.array([[5.0, 0.0]])
    brax = NormalizerConfig()
    state = update(running_statistics.init_state(spec), first, brax)
    assert float(normalize_fn(brax)(touch, state)[0, 0]) > 1e6
    bounded = NormalizerConfig(std_floor=0.01, clip=10.0)
    state = update(running_statistics.init_state(spec), first, bounded)
    assert float(normalize_fn(bounded)(touch, state)[0, 0]) == pytest.approx(10.0)


def test_a_fixed_force_scale_holds_through_updates() -> None:
    """``force_scale``: the entries named stay at mean 0 and the scale whatever they read (a
    25 N reading is 0.5 at a scale of 50 from the first touch on); the others move."""
    from brax.training.acme import running_statistics, specs

    spec = specs.Array((3,), jnp.dtype("float32"))
    first = jnp.array([[2.0, 0.0, 0.0], [4.0, 0.0, 0.0]] * 8)
    touch = jnp.array([[3.0, 25.0, -75.0]])
    fixed = NormalizerConfig(force_scale=50.0)
    state = update(running_statistics.init_state(spec), first, fixed, slice(1, 3))
    state = update(state, touch, fixed, slice(1, 3))
    assert jnp.allclose(state.mean[1:], 0.0) and jnp.allclose(state.std[1:], 50.0)
    assert 2.0 < float(state.mean[0]) < 4.0 and 0.5 < float(state.std[0]) < 1.5
    assert normalize_fn(fixed)(touch, state)[0, 1:].tolist() == [0.5, -1.5]
    plain = update(running_statistics.init_state(spec), first, fixed, None)
    assert float(plain.std[1]) == pytest.approx(1e-6)  # no dims named: Brax's statistics


def test_devices_scale_the_envs_minibatch_and_budget_when_asked() -> None:
    """By default ``--devices N`` splits the preset's batch (the config is unchanged);
    ``scale_with_devices`` grows envs, minibatch, budget and first evaluation N times, and the
    rate and clip only where ``devices_lr_power`` and ``devices_clip`` say."""
    preset = load_config("fast", None, ["task=touch"])
    assert preset.scaled_for_devices(2) == preset
    config = preset.replace(scale_with_devices=True)
    two = config.scaled_for_devices(2)
    assert (two.num_envs, two.batch_size) == (2 * config.num_envs, 2 * config.batch_size)
    assert two.num_timesteps == 2 * config.num_timesteps
    assert two.eval_from_step == 2 * config.eval_from_step > 0  # as many updates unevaluated
    assert two.num_minibatches == config.num_minibatches
    assert (two.learning_rate, two.clipping_epsilon) == (1e-3, 0.2)  # kept by default
    rule = config.replace(devices_lr_power=1.0, devices_clip=0.4).scaled_for_devices(2)
    assert rule.learning_rate == pytest.approx(2 * config.learning_rate, rel=1e-12)
    assert rule.clipping_epsilon == 0.4
    four = config.replace(devices_lr_power=0.5).scaled_for_devices(4)
    assert four.learning_rate == pytest.approx(2 * config.learning_rate, rel=1e-12)
    assert four.clipping_epsilon == config.clipping_epsilon
    assert config.scaled_for_devices(1) == config


def test_the_seeds_summary_gives_an_interval_and_collapses() -> None:
    from mjx_arm.bench.seeds_config import SeedRun
    from mjx_arm.bench.seeds_summary import summarize, wilson_interval

    low, high = wilson_interval(29, 30)
    assert low == pytest.approx(0.8333, abs=1e-3) and high == pytest.approx(0.9941, abs=1e-3)
    nan = float("nan")
    solved = SeedRun(1, 0.97, 0.97, 10, 20.0, 10, 30.0, 5.0, 1e5, [(20.0, 10, 0.97)])
    collapsed = SeedRun(2, 0.96, 0.96, 10, 25.0, 20, 40.0, 5.0, 1e5, [(25.0, 10, 0.96)])
    collapsed.curve.append((40.0, 20, 0.0))
    failed = SeedRun(3, 0.1, 0.1, None, None, 20, 50.0, nan, nan, [(50.0, 20, 0.1)])
    summary = summarize([solved, collapsed, failed], 0.95)
    assert summary["solved"] == 2 and summary["collapsed"] == [2]
    assert summary["time_to_threshold_p90_all"] is None  # the failed seed is in the top 10%


def test_an_exported_policy_clips_as_training_did(tmp_path) -> None:
    """A policy file with ``obs_clip``: the numpy runtime and the ONNX graph both clip the
    normalised observation, and agree (float32 rounding) on an observation far outside it."""
    pytest.importorskip("onnxruntime")
    import onnx

    from input_fuzz.corpus import build
    from mjx_arm.policy import load
    from mjx_arm.policy.numpy_policy import read_npz, write_npz
    from mjx_arm.policy.onnx_export import build_model

    arrays, meta = read_npz(build(tmp_path / "corpus").policy)
    meta = {**meta, "obs_clip": 2.0}
    onnx.save(build_model(arrays, meta), str(tmp_path / "clipped.onnx"))
    clipped = load(tmp_path / "clipped.onnx")
    far = np.asarray(arrays["obs_mean"]) + 1e4 * np.asarray(arrays["obs_std"])
    edge = np.asarray(arrays["obs_mean"]) + 2.0 * np.asarray(arrays["obs_std"])
    np.testing.assert_allclose(clipped(far), clipped(edge), atol=1e-5)
    numpy_policy = load(write_npz(tmp_path / "clipped.npz", arrays, meta))
    np.testing.assert_allclose(numpy_policy(far), clipped(far), atol=1e-5)
