"""Physics that blows up: extreme actions, hammered joint limits and forced divergence.

Every engine: the CPU MuJoCo env, the PyBullet env and the batched JAX env on the C MuJoCo
backend (what runs on a CPU; MJX-JAX compiles too slowly here). Extreme actions held for 1000
control steps must keep every observation finite and inside the space without a divergence
flag; a physics forced to diverge (NaN or huge velocities, a model with near-zero inertia) must
end the episode with ``info["diverged"]``, and the next reset must be clean.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_arm.envs.backend import make_batched_env
from mjx_arm.envs.mujoco_batch import CState
from mjx_arm.envs.registration import make_env
from mjx_arm.envs.vector import ArmVectorEnv
from mjx_arm.envs.wrappers import wrap_for_training
from mjx_arm.task import flat_observation_space, flatten_obs, task_config
from mjx_arm.task.config import TaskConfig

ENGINES = [
    pytest.param("mujoco", id="mujoco"),
    pytest.param("pybullet", id="pybullet", marks=pytest.mark.pybullet),
]
TASKS = ["reach", "touch"]
STEPS = 1000
# How far a hammered joint may pass its URDF limit (rad): the limit constraints are soft.
LIMIT_SLACK = 0.05
HUGE_SPEED = 1e6  # rad/s written into the state: far beyond any divergence limit
BROKEN_STEPS = 30  # control steps a near-massless arm gets to blow up


def _endless(task: str, **changes) -> TaskConfig:
    """A task config whose episodes never end on their own (success, strike, time)."""
    return task_config(
        task,
        terminate_on_success=False,
        episode_steps=10 * STEPS,
        **({"terminate_on_overforce": False} if task == "touch" else {}),
        **changes,
    )


def _pattern(name: str, steps: int, seed: int = 0) -> np.ndarray:
    """Extreme actions ``(steps, 6)``: every entry -1 or +1, held or switched."""
    t = np.arange(steps)[:, None]
    if name == "plus":
        signs = np.ones((steps, 6))
    elif name == "minus":
        signs = -np.ones((steps, 6))
    elif name == "bang_bang":  # every joint reverses at every control step
        signs = np.where(t % 2 == 0, 1.0, -1.0) * np.ones(6)
    elif name == "sweep":  # each joint runs from limit to limit, joints out of phase
        signs = np.where((t // 90 + np.arange(6)) % 2 == 0, 1.0, -1.0)
    else:
        signs = np.random.default_rng(seed).choice([-1.0, 1.0], (steps, 6))
    return signs.astype(np.float32)


PATTERNS = ("plus", "minus", "bang_bang", "sweep", "random")


def _limits_passed_by(qpos: np.ndarray, arm) -> float:
    """How far (rad) joint angles ``(..., 6)`` go beyond the URDF limits (0 when inside)."""
    return float(np.max(np.maximum(arm.lower - qpos, qpos - arm.upper), initial=0.0))


@pytest.fixture(autouse=True)
def _in_tmp_path(tmp_path, monkeypatch) -> None:
    """MuJoCo writes its warnings about the diverged states to MUJOCO_LOG.TXT in the working
    folder: keep it out of the checkout."""
    monkeypatch.chdir(tmp_path)


# --------------------------------------------------------------------------- CPU envs


@pytest.fixture
def closing() -> Iterator[Callable[[gym.Env], gym.Env]]:
    """Registers envs to close after the test."""
    made: list[gym.Env] = []
    yield lambda env: made.append(env) or env
    for env in made:
        env.close()


@pytest.mark.parametrize("pattern", PATTERNS)
@pytest.mark.parametrize("task", TASKS)
@pytest.mark.parametrize("engine", ENGINES)
def test_extreme_actions_keep_observations_finite_inside_the_space(
    engine: str, task: str, pattern: str, closing
):
    env = closing(make_env(task, engine, task=_endless(task)))
    obs, _ = env.reset(seed=1)
    worst = 0.0
    for action in _pattern(pattern, STEPS, seed=1):
        obs, reward, terminated, _, info = env.step(action)
        assert env.observation_space.contains(obs), obs
        assert np.isfinite(reward) and not info["diverged"] and not terminated
        worst = max(worst, _limits_passed_by(env._reading.qpos, env.arm))
    assert worst < LIMIT_SLACK, f"a joint passed its limit by {worst:.3f} rad"


def _corrupt_mujoco(env, kind: str) -> None:
    qvel = env.data.qvel
    if kind == "nan_velocity":
        qvel[env.ids.dof_adr[1]] = np.nan
    elif kind == "huge_velocity":
        qvel[env.ids.dof_adr] = HUGE_SPEED
    elif kind == "nan_position":
        env.data.qpos[env.ids.qpos_adr[2]] = np.nan
    else:  # near-massless links without rotor inertia: the stiff servos blow up
        env.model.dof_armature[:] = 0.0
        env.model.body_mass[1:] = 1e-9
        env.model.body_inertia[1:] = 1e-12


def _corrupt_pybullet(env, kind: str) -> None:
    c, body, joints = env.client, env.body, env.ids.joints
    if kind == "nan_velocity":
        c.resetJointState(body, joints[1], 0.0, float("nan"))
    elif kind == "huge_velocity":
        for j in joints:
            c.resetJointState(body, j, c.getJointState(body, j)[0], HUGE_SPEED)
    elif kind == "nan_position":
        c.resetJointState(body, joints[2], float("nan"), 0.0)
    else:
        for j in joints:
            c.changeDynamics(body, j, mass=1e-9, localInertiaDiagonal=[1e-12] * 3)


CORRUPTIONS = ("nan_velocity", "huge_velocity", "nan_position", "broken_model")


@pytest.mark.parametrize("kind", CORRUPTIONS)
@pytest.mark.parametrize("engine", ENGINES)
def test_forced_divergence_ends_the_episode_flagged_and_the_next_reset_is_clean(
    engine: str, kind: str, closing
):
    env = closing(make_env("touch", engine))
    saved = {k: getattr(env.model, k).copy() for k in ("dof_armature", "body_mass",
             "body_inertia")} if engine == "mujoco" else {}  # fmt: skip
    last, _ = env.reset(seed=2)
    (_corrupt_mujoco if engine == "mujoco" else _corrupt_pybullet)(env, kind)
    for _ in range(BROKEN_STEPS):
        obs, reward, terminated, truncated, info = env.step(np.ones(6, np.float32))
        assert env.observation_space.contains(obs) and np.isfinite(reward)
        if info["diverged"]:
            break
        last = obs
    assert info["diverged"] and terminated and not truncated, kind
    assert info["reward_terms"]["nonfinite"] == 1.0 and not info["is_success"]
    assert np.array_equal(flatten_obs(np, obs), flatten_obs(np, last))  # the last sane one
    for name, value in saved.items():  # a model edited in place is restored by its owner
        getattr(env.model, name)[:] = value
    again, _ = env.reset(seed=5)
    fresh, _ = closing(make_env("touch", engine)).reset(seed=5)
    np.testing.assert_array_equal(flatten_obs(np, again), flatten_obs(np, fresh))


# --------------------------------------------------------------------------- batched JAX env


@pytest.fixture(scope="module")
def batch_env():
    """The Touch task on the C MuJoCo backend, with episodes that never end on their own."""
    return make_batched_env(_endless("touch"), backend="mujoco")


def _corrupt_rows(state: CState, rows: dict[int, float], dofs: np.ndarray, nq: int) -> CState:
    """Write ``value`` into the joint velocities of each batch row (``row -> value``)."""
    qvel = state.state
    for row, value in rows.items():
        qvel = qvel.at[row, 1 + nq + dofs].set(value)
    return state.replace(state=qvel)


def test_batched_env_under_extreme_actions_stays_finite_inside_the_space(batch_env):
    env = batch_env
    actions = jnp.asarray(np.stack([_pattern(p, STEPS, seed=3) for p in PATTERNS], axis=1))
    keys = jax.random.split(jax.random.PRNGKey(3), len(PATTERNS))
    step = jax.vmap(env.step)

    def body(state, action):
        state = step(state, action)
        qpos = jax.vmap(env.physics.read)(state.pipeline_state).qpos
        return state, (state.obs, state.metrics["diverged"], state.reward, qpos)

    run = jax.jit(lambda s, a: jax.lax.scan(body, s, a))
    _, (obs, diverged, reward, qpos) = run(jax.vmap(env.reset)(keys), actions)
    obs, qpos = np.asarray(obs), np.asarray(qpos)
    space = flat_observation_space(env.task.force_clip, coding=env.joint_coding)
    assert obs.shape == (STEPS, len(PATTERNS), space.shape[0])
    assert np.isfinite(obs).all() and np.isfinite(np.asarray(reward)).all()
    assert ((obs >= space.low) & (obs <= space.high)).all()
    assert not np.asarray(diverged).any()
    assert _limits_passed_by(qpos, env.arm) < LIMIT_SLACK


def test_batch_keeps_training_when_some_envs_diverge(batch_env):
    """Through the training wrappers: the diverged envs restart, the others step on unchanged."""
    env = wrap_for_training(batch_env, episode_length=150)
    reset, step = jax.jit(env.reset), jax.jit(env.step)
    n, broken = 6, {1: np.nan, 4: HUGE_SPEED}
    physics = batch_env.physics
    dofs, nq = physics.ids.dof_adr, physics.mj_model.nq
    actions = jnp.asarray(np.random.default_rng(4).uniform(-1, 1, (6, n, 6)), jnp.float32)
    clean = corrupt = reset(jax.random.split(jax.random.PRNGKey(4), n))
    for t, action in enumerate(actions):
        if t == 2:
            data = _corrupt_rows(corrupt.pipeline_state, broken, dofs, nq)
            corrupt = corrupt.replace(pipeline_state=data)
        clean, corrupt = step(clean, action), step(corrupt, action)
        others = np.array([i for i in range(n) if i not in broken])
        obs, reward = np.asarray(corrupt.obs), np.asarray(corrupt.reward)
        # the same backend and inputs: the untouched envs follow the clean run to rounding
        np.testing.assert_allclose(obs[others], np.asarray(clean.obs)[others], atol=1e-6)
        np.testing.assert_allclose(reward[others], np.asarray(clean.reward)[others], atol=1e-5)
        assert np.isfinite(obs).all()
        flagged = np.asarray(corrupt.metrics["diverged"]) > 0
        assert flagged.tolist() == [t == 2 and i in broken for i in range(n)], t
        if t == 2:  # restarted from their first state: at rest where they began
            first = corrupt.info["first_pipeline_state"].state
            np.testing.assert_array_equal(corrupt.pipeline_state.state[1], first[1])
            np.testing.assert_array_equal(corrupt.pipeline_state.state[4], first[4])
            assert (np.asarray(corrupt.done)[np.array(list(broken))] == 1).all()


def test_vector_env_resets_a_diverged_env_in_the_same_step():
    """Gymnasium's vector API: the diverged env is flagged, reset cleanly, the others go on."""
    n, row = 4, 2
    vec, clean = (ArmVectorEnv(_endless("touch"), n, backend="mujoco") for _ in range(2))
    vec.reset(seed=6)
    clean.reset(seed=6)
    physics = vec.env.physics
    data = _corrupt_rows(vec._state.pipeline_state, {row: np.nan}, physics.ids.dof_adr,
                         physics.mj_model.nq)  # fmt: skip
    vec._state = vec._state.replace(pipeline_state=data)
    key = vec._key
    actions = np.zeros((n, 6), np.float32)
    obs, _, terminated, truncated, info = vec.step(actions)
    expected, _, _, _, _ = clean.step(actions)
    assert terminated.tolist() == [i == row for i in range(n)] and not truncated.any()
    assert info["diverged"].tolist() == terminated.tolist()
    assert vec.single_observation_space.contains({k: v[row] for k, v in info["final_obs"].items()})
    fresh = vec._reset(jax.random.split(jax.random.split(key)[1], n))  # the reset it drew
    flat = flatten_obs(np, obs)
    np.testing.assert_array_equal(flat[row], np.asarray(fresh.obs[row]))
    others = [i for i in range(n) if i != row]
    np.testing.assert_allclose(flat[others], flatten_obs(np, expected)[others], atol=1e-6)
    obs, *_ = vec.step(np.ones((n, 6), np.float32))
    assert vec.observation_space.contains(obs)
