"""One env's step on Python floats gives numpy's numbers: the scalar array namespace, the flat
state in floats, the wrench's features as three gathers and PyBullet's 3-vector helpers, each
against the numpy code it stands in for. No physics engine; about a second."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mjx_arm.envs.scalar.state import ScalarState, distance, finite
from mjx_arm.envs.scalar.xp import SCALAR_XP
from mjx_arm.task import observation as obs_lib
from mjx_arm.task import reward as reward_lib
from mjx_arm.task.lift import LIFT
from mjx_arm.task.wrench import (
    SENSOR_BLOCK_SIZE,
    ToolInertia,
    sensor_feature_factors,
    sensor_wrench,
)
from pybullet_ref.fast import vec3

SPECIALS = [0.0, -0.0, 1.5, -2.25, 1e300, -1e300, math.inf, -math.inf, math.nan]


@pytest.mark.parametrize("name", ["maximum", "minimum"])
def test_scalar_extrema_are_numpys(name: str) -> None:
    """Python scalars in, Python floats out, numpy's value (NaN and signed zeros included)."""
    for a in SPECIALS:
        for b in SPECIALS:
            got, want = getattr(SCALAR_XP, name)(a, b), getattr(np, name)(a, b)
            assert type(got) is float
            assert (math.isnan(got) and math.isnan(want)) or got == want, (a, b)


def test_scalar_functions_are_numpys() -> None:
    """where, exp (an overflow is inf), sqrt (NaN below zero), clip, logic and zeros."""
    for x in [-800.0, -3.0, -0.0, 0.5, 700.0, 800.0, math.inf, math.nan]:
        for name in ("exp", "sqrt"):
            got = getattr(SCALAR_XP, name)(x)
            with np.errstate(all="ignore"):
                want = float(getattr(np, name)(x))
            assert type(got) is float and (got == want or (math.isnan(got) and math.isnan(want)))
        assert SCALAR_XP.clip(x, -1.0, 1.0) == np.clip(x, -1.0, 1.0) or math.isnan(x)
    assert SCALAR_XP.where(True, 2.0, 0.0) == 2.0 and SCALAR_XP.where(False, 2.0, 0.0) == 0.0
    assert SCALAR_XP.logical_not(False) is True and SCALAR_XP.logical_and(True, 1.0) is True
    assert SCALAR_XP.zeros() == 0.0 and SCALAR_XP.zeros((), dtype=bool) is False
    assert SCALAR_XP.zeros_like(3.0, dtype=bool) is False
    arrays = (np.array([1.0, -2.0]), np.array([0.5, 3.0]))  # arrays go to numpy
    np.testing.assert_array_equal(SCALAR_XP.maximum(*arrays), np.maximum(*arrays))
    assert isinstance(SCALAR_XP.where(np.array([True, False]), 1.0, 0.0), np.ndarray)
    assert SCALAR_XP.arctan2 is np.arctan2  # every other name is numpy's


def test_list_functions_match_numpys_arrays() -> None:
    """subtract, abs, greater and matmul on one env's lists: numpy's values, as lists."""
    rng = np.random.default_rng(0)
    for _ in range(200):
        a, b = rng.normal(size=6), rng.normal(size=6)
        diff = SCALAR_XP.subtract(a.tolist(), b.tolist())
        assert diff == (a - b).tolist()
        assert SCALAR_XP.abs(diff) == np.abs(a - b).tolist()
        assert SCALAR_XP.greater(diff, b.tolist()) == ((a - b) > b).tolist()
        total = SCALAR_XP.matmul(SCALAR_XP.abs(diff), np.ones(6))
        assert type(total) is float and total == pytest.approx(np.abs(a - b).sum(), rel=1e-15)


def test_cross_and_stack_match_numpy() -> None:
    """Python-float cross products bit for bit; scalars stacked into numpy's array."""
    rng = np.random.default_rng(1)
    for _ in range(200):
        a, b = rng.normal(size=3), rng.normal(size=3)
        np.testing.assert_array_equal(SCALAR_XP.cross(a, b), np.cross(a, b))
        np.testing.assert_array_equal(vec3.cross(a.tolist(), b.tolist()), np.cross(a, b))
    parts = [np.float64(1.5), np.float64(-2.0), 3.0]
    np.testing.assert_array_equal(SCALAR_XP.stack(parts, axis=-1), np.stack(parts, axis=-1))
    batch = [np.ones((2, 3)), np.zeros((2, 3))]
    np.testing.assert_array_equal(SCALAR_XP.stack(batch, axis=-1), np.stack(batch, axis=-1))


def test_vec3_rotations_match_numpy() -> None:
    """R v and R^T v of a row-major rotation, against numpy's products (1e-15)."""
    rng = np.random.default_rng(2)
    for _ in range(100):
        rot, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        v = rng.normal(size=3)
        r = rot.ravel().tolist()
        np.testing.assert_allclose(vec3.rotate(r, v.tolist()), rot @ v, rtol=0, atol=1e-15)
        np.testing.assert_allclose(vec3.rotate_back(r, v.tolist()), rot.T @ v, atol=1e-15)
    assert vec3.rate((1.0, 2.0, 3.0), (2.0, 4.0, 6.0), 0.5) == (2.0, 4.0, 6.0)


def _tool(rng: np.random.Generator) -> ToolInertia:
    rot, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    inertia = np.diag(rng.uniform(1e-3, 1e-2, 3))
    return ToolInertia(0.8, rng.normal(size=3) * 0.05, inertia, rng.normal(size=3) * 0.1, rot)


def test_wrench_features_as_three_gathers_are_sensor_wrench() -> None:
    """``v[a] * v[b] * v[c]`` with a 1.0 after the block: sensor_wrench's wrench exactly."""
    rng = np.random.default_rng(3)
    tool = _tool(rng)
    one = SENSOR_BLOCK_SIZE + 7  # the reader's layout: block, ee position, ee quaternion, 1.0
    a, b, c = sensor_feature_factors(one)
    for _ in range(50):
        v = np.append(rng.normal(size=one) * 10.0, 1.0)
        features = v.take(a) * v.take(b) * v.take(c)
        want = sensor_wrench(np, v[:SENSOR_BLOCK_SIZE], tool)
        np.testing.assert_array_equal(features.dot(tool.sensor_wrench_matrix), want)


def _centred(n: int) -> obs_lib.JointCoding:
    """The centred encoding of joints limited to +-6 rad."""
    return obs_lib.joint_coding("centred", -np.full(n, 6.0), np.full(n, 6.0), [0] * n, [0] * n)


def _reading(rng: np.random.Generator, n: int = 6):
    quat = rng.normal(size=4)
    return (
        rng.normal(size=3),
        quat / np.linalg.norm(quat) * rng.uniform(0.999, 1.001),
        rng.uniform(-7.0, 7.0, n),
        rng.normal(size=3),
        rng.normal(size=6) * 80.0,  # clipped at +-50 N (force_clip below)
    )


@pytest.mark.parametrize("wrapped", [False, True])
def test_scalar_state_is_raw_state_and_clip_state(wrapped: bool) -> None:
    """The flat state in floats: observation.raw_state and clip_state's values (4 ulp: the
    quaternion's norm adds its squares left to right, numpy's vecdot in the order of the CPU's
    vector unit, which on an AVX-512 CPU ends up to 2 ulp apart in the norm), the force norm and
    the distance of the reward functions, the observation's keys, float32 values and bounds."""
    rng = np.random.default_rng(4 + wrapped)
    n = 6
    coding = obs_lib.wrapped_coding(n) if wrapped else _centred(n)
    flat = ScalarState(50.0, coding)
    bounds = obs_lib.state_bounds(50.0, n, (), coding)
    for _ in range(100):
        ee, quat, qpos, target, wrench = _reading(rng, n)
        raw = flat.raw(ee, quat, qpos, target, wrench)
        want = obs_lib.raw_state(np, ee, quat, qpos, target, wrench, coding=coding)
        np.testing.assert_array_max_ulp(np.array(raw), want, maxulp=4)
        state = flat.clip(raw)
        np.testing.assert_array_equal(state, obs_lib.clip_state(np, np.array(raw), bounds))
        force = reward_lib.contact_force_norm(np, np.array(state)[obs_lib.force_slice(n)])
        assert flat.force_norm(state) == pytest.approx(float(force), rel=1e-15)
        d = reward_lib.target_distance(np, ee, target)
        assert distance(ee, target) == pytest.approx(float(d), rel=1e-15)
        obs = flat.observation(state)
        assert list(obs) == list(obs_lib.OBS_KEYS)
        np.testing.assert_array_equal(np.concatenate(list(obs.values())), np.float32(state))


def test_scalar_state_shows_what_is_not_finite() -> None:
    """A NaN or infinite input, or a zero quaternion, is not finite in the raw state; clipping
    keeps NaN (numpy's clip does); the extra keys follow the contract's four."""
    rng = np.random.default_rng(6)
    flat = ScalarState(50.0, _centred(6), LIFT.extra_obs)
    ee, quat, qpos, target, wrench = _reading(rng)
    extra = np.arange(10.0) / 10.0
    assert finite(flat.raw(ee, quat, qpos, target, wrench, extra))
    assert flat.raw(ee, quat, qpos, target, wrench, extra)[-10:] == extra.tolist()
    for bad in (math.nan, math.inf):
        q = qpos.copy()
        q[2] = bad
        raw = flat.raw(ee, quat, q, target, wrench, extra)
        assert not finite(raw)
        assert math.isnan(flat.clip(raw)[9]) == math.isnan(bad)
    assert not finite(flat.raw(ee, np.zeros(4), qpos, target, wrench, extra))
    assert finite([1e308, 1e308, -1e308])  # overflowing sums are checked entry by entry
