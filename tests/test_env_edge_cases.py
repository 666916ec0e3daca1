"""Gymnasium's edge cases give the same answer on every engine: the CPU MuJoCo env, the PyBullet
env and the batched vector env (C MuJoCo backend, one env per batch). Real actions of any real
dtype step; complex, string, object, ragged, wrongly shaped and NaN actions are an
InvalidActionError with the same message for the same action; reset() and step() after close()
are Gymnasium's ClosedEnvironmentError."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import mjx_arm  # noqa: F401  (registers the ids)
from mjx_arm.envs.base import InvalidActionError
from mjx_arm.envs.vector import ArmVectorEnv
from mjx_arm.task import task_config

ENGINES = [
    pytest.param("mujoco", id="mujoco"),
    pytest.param("pybullet", id="pybullet", marks=pytest.mark.pybullet),
    pytest.param("batch", id="batch"),
]
REAL = {
    "int": np.zeros(6, np.int64),
    "float64": np.full(6, 0.3),
    "float16": np.full(6, 0.3, np.float16),
    "bool": np.ones(6, bool),
    "list": [0.5] * 6,
    "out of range": np.full(6, 7.0),  # clipped into [-1, 1]
}
BAD = {
    "complex": np.full(6, 0.1 + 0.5j),
    "string": np.array(["0.1"] * 6),
    "list of strings": ["0.1"] * 6,
    "object": np.array([0.1] * 6, dtype=object),
    "ragged": [0.1, [0.2, 0.3], 0.4, 0.5, 0.6, 0.7],
    "nan": np.array([np.nan, 0, 0, 0, 0, 0]),
    "inf": np.array([0, 0, 0, 0, 0, -np.inf]),
}
WRONG_SHAPES = {"too short": np.zeros(5), "matrix": np.zeros((2, 3)), "scalar": np.float64(0.1)}


def _make(engine: str) -> Any:
    if engine == "batch":
        return ArmVectorEnv(task_config("touch"), 1, backend="mujoco")
    return gym.make("mjx_arm/Touch-v0", engine=engine).unwrapped


def _batched(engine: str, action: Any) -> Any:
    """The action as ``engine`` takes it: one row of a batch for the vector env."""
    if engine != "batch":
        return action
    return [action] if isinstance(action, list) else np.asarray(action)[None]


@pytest.fixture(scope="module", params=ENGINES)
def env(request: pytest.FixtureRequest):
    made = _make(request.param)
    made.reset(seed=0)
    yield request.param, made
    made.close()


@pytest.mark.parametrize("name", list(REAL))
def test_real_actions_step(env, name: str) -> None:
    engine, made = env
    obs, reward, *_ = made.step(_batched(engine, REAL[name]))
    space = made.single_observation_space if engine == "batch" else made.observation_space
    first = {k: v[0] for k, v in obs.items()} if engine == "batch" else obs
    assert space.contains(first)
    assert np.all(np.isfinite(reward))


@pytest.mark.parametrize("name", list(BAD))
def test_bad_actions_are_the_same_named_error(env, name: str) -> None:
    """Same class and same message as the CPU MuJoCo env's (a reference computed here)."""
    engine, made = env
    with pytest.raises(InvalidActionError, match=r"^action ") as info:
        made.step(_batched(engine, BAD[name]))
    reference = _reference_message(BAD[name])
    assert str(info.value) == reference


@pytest.mark.parametrize("name", list(WRONG_SHAPES))
def test_wrong_shapes_are_an_invalid_action(env, name: str) -> None:
    engine, made = env
    with pytest.raises(InvalidActionError, match=r"must have shape \((1, )?6,?\), got"):
        made.step(_batched(engine, WRONG_SHAPES[name]))


@pytest.mark.parametrize("engine", [p.values[0] for p in ENGINES])
def test_after_close_reset_and_step_are_closed_environment_errors(engine: str) -> None:
    made = _make(engine)
    made.reset(seed=0)
    made.close()
    made.close()  # a second close is harmless
    with pytest.raises(gym.error.ClosedEnvironmentError, match=r"reset\(\) called after close"):
        made.reset(seed=0)
    with pytest.raises(gym.error.ClosedEnvironmentError, match=r"step\(\) called after close"):
        made.step(_batched(engine, np.zeros(6)))


def _reference_message(action: Any) -> str:
    from mjx_arm.envs.base import check_action

    with pytest.raises(InvalidActionError) as info:
        check_action(action, (-np.ones(6, np.float32), np.ones(6, np.float32)))
    return str(info.value)
