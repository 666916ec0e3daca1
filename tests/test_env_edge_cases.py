"""Gymnasium's edge cases give the same answer on every engine: the CPU MuJoCo env, the PyBullet
env and the batched vector env (C MuJoCo backend, one env per batch). Real actions of any real
dtype step; complex, string, object, ragged, wrongly shaped and NaN actions are an
InvalidActionError with the same message for the same action; reset() and step() after close()
are Gymnasium's ClosedEnvironmentError. Reset options the contract cannot take (NaN, wrong
shape, out of the observation's bound) are an InvalidResetOptionError, a batch of zero envs a
ConfigError, and a second thread inside an env a ConcurrentEnvUseError (not a crash)."""

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


# --------------------------------------------------------------------------- reset options

CPU_ENGINES = [p for p in ENGINES if p.values[0] != "batch"]
BAD_TARGETS = {
    "nan": [np.nan, np.nan, np.nan],
    "inf": [np.inf, 0.0, 0.3],
    "two numbers": [0.5, 0.1],
    "matrix": [[0.5, 0.1, 0.3]],
    "strings": ["0.5", "0.1", "0.3"],
    "complex": np.full(3, 0.5 + 1j),
    "out of the observation's bound": [5.0, 0.0, 0.3],
}


@pytest.mark.parametrize("engine", [p.values[0] for p in CPU_ENGINES])
def test_reset_targets_the_contract_cannot_take_are_refused(engine: str) -> None:
    """NaN gave NaN observations; each bad target is now a named error, and the env still
    resets to a good target afterwards (every observation inside the space)."""
    from mjx_arm.envs.guards import InvalidResetOptionError

    made = _make(engine)
    try:
        for name, target in BAD_TARGETS.items():
            with pytest.raises(InvalidResetOptionError, match=r"options\['target'\]"):
                made.reset(seed=0, options={"target": target})
            assert issubclass(InvalidResetOptionError, ValueError), name
        obs, info = made.reset(seed=0, options={"target": (0.5, 0.1, 0.04)})
        assert made.observation_space.contains(obs)
        assert np.isfinite(info["distance"])
    finally:
        made.close()


def test_reset_object_options_of_a_gripper_task_are_checked() -> None:
    from mjx_arm.envs.guards import InvalidResetOptionError
    from mjx_arm.envs.mujoco_env import MujocoArmEnv
    from mjx_arm.paths import asset

    made = MujocoArmEnv(task_config("lift"), asset("ur5e_gripper.urdf"))
    bad = {
        "object_mass": [np.nan, 0.0, -1.0, "heavy"],
        "object_friction": [np.inf, -0.5],
        "object_quat": [np.zeros(4), [1.0, 0.0, 0.0], [np.nan, 0, 0, 1]],
    }
    try:
        for key, values in bad.items():
            for value in values:
                with pytest.raises(InvalidResetOptionError, match=rf"options\['{key}'\]"):
                    made.reset(seed=0, options={key: value})
        obs, _ = made.reset(seed=0, options={"object_mass": 0.1, "object_friction": 0.8})
        assert made.observation_space.contains(obs)
    finally:
        made.close()


def test_make_vec_of_zero_envs_is_a_clear_error() -> None:
    from mjx_arm.inputs import ConfigError

    for bad in (0, -2, 1.5, True):
        with pytest.raises(ConfigError, match=r"num_envs must be a whole number >= 1, got"):
            gym.make_vec("mjx_arm/Touch-v0", num_envs=bad, vectorization_mode="vector_entry_point")


# --------------------------------------------------------------------------- threads


@pytest.mark.parametrize("engine", [p.values[0] for p in CPU_ENGINES])
def test_a_second_thread_inside_the_env_is_a_named_error(engine: str, monkeypatch) -> None:
    """Thread A is held inside ``step`` (its physics waits on an event); thread B's ``step``,
    ``reset`` and ``render`` raise ConcurrentEnvUseError at once; A then finishes its step."""
    import threading

    from mjx_arm.envs.guards import ConcurrentEnvUseError

    made = _make(engine)
    made.reset(seed=0)
    inside, release = threading.Event(), threading.Event()
    physics_step = made._physics_step

    def held(n: int) -> None:
        inside.set()
        assert release.wait(30)
        physics_step(n)

    monkeypatch.setattr(made, "_physics_step", held)
    results: list = []
    first = threading.Thread(target=lambda: results.append(made.step(np.zeros(6))))
    first.start()
    try:
        assert inside.wait(30)
        for call in (lambda: made.step(np.zeros(6)), lambda: made.reset(seed=1), made.render):
            with pytest.raises(ConcurrentEnvUseError, match=r"while another thread is inside"):
                call()
    finally:
        release.set()
        first.join(30)
    assert len(results) == 1 and made.observation_space.contains(results[0][0])
    assert issubclass(ConcurrentEnvUseError, RuntimeError)
    made.close()


def test_two_threads_stepping_one_env_do_not_crash_the_process() -> None:
    """Two threads step one CPU MuJoCo env 2,000 times each (mj_step releases the GIL, so they
    overlap): before the guard this crashed the interpreter (SIGSEGV / SIGBUS); now each
    overlapping call is a ConcurrentEnvUseError and the process exits normally."""
    import subprocess
    import sys
    import textwrap

    script = textwrap.dedent(
        """
        import threading
        import numpy as np
        from mjx_arm.envs.guards import ConcurrentEnvUseError
        from mjx_arm.envs.mujoco_env import MujocoArmEnv

        env = MujocoArmEnv()
        env.reset(seed=0)
        counts = {"steps": 0, "refused": 0}

        def work():
            for _ in range(2000):
                try:
                    env.step(np.zeros(6))
                    counts["steps"] += 1
                except ConcurrentEnvUseError:
                    counts["refused"] += 1

        threads = [threading.Thread(target=work) for _ in range(2)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        print(counts["steps"], counts["refused"])
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    steps, refused = map(int, done.stdout.split())
    assert steps + refused == 4000 and steps >= 2000
