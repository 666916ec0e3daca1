"""A task added in one file (tests/toy_task.py) runs in the CPU MuJoCo env and the C batch.

The toy task changes the sampling, the target point, the hold length and the reward weights,
and declares its own reward term, scene and budget; nothing else in the package knows it. It is
registered for this module's tests and taken out after them. With the spot right below the home
pose's tool tip and no start noise, the arm at rest holds the hover point, so both engines must
succeed on exactly the 5th step (the toy's hold) and score the same rewards, its own term
included: 1e-4, as for the built-in tasks (float32 state between control steps in the C batch,
tests/test_mujoco_batch.py).
"""

from __future__ import annotations

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from toy_task import HOVER, HOVER_BUDGET, HOVER_HEIGHT

from mjx_arm.envs.backend import make_batched_env
from mjx_arm.envs.registration import make_env, register_envs
from mjx_arm.task import get_task, register_task, task_config, task_names
from mjx_arm.task.registry import is_task, unregister_task

REWARD_ATOL = 1e-4
HOME_TIP_XY = (0.4919, 0.1333)  # the tool tip at the home pose (m, base frame)


@pytest.fixture(autouse=True, scope="module")
def hover_registered():
    """The toy task, registered for this module's tests only."""
    register_task(HOVER)
    yield HOVER
    unregister_task(HOVER.name)
    assert not is_task(HOVER.name)


@pytest.fixture
def at_rest():
    """The toy task with the spot below the home tool tip and no start noise."""
    spot = (*HOME_TIP_XY, 0.0)
    return task_config("hover", init_noise=0.0, target_low=spot, target_high=spot)


def test_the_toy_task_is_registered_by_name() -> None:
    assert "hover" in task_names() and get_task("hover") is HOVER
    assert task_config("hover").success_hold_steps == 5
    register_envs()
    env = gym.make("mjx_arm/Hover-v0", engine="mujoco")
    obs, _ = env.reset(seed=0)
    # the task's own sampling and target point: above a spot on the table
    target = obs["target_rel"]  # the target point (m, base frame)
    assert abs(target[2] - HOVER_HEIGHT) < 1e-5 and 0.40 <= target[0] <= 0.60
    env.close()


def _cpu_rewards(task) -> tuple[list[float], list[bool]]:
    env = make_env("hover", engine="mujoco", task=task)
    env.reset(seed=0)
    rewards, dones = [], []
    for _ in range(8):
        _, reward, terminated, _, info = env.step(np.zeros(6, np.float32))
        rewards.append(reward)
        dones.append(terminated)
        if terminated:
            assert info["is_success"]
            break
    env.close()
    return rewards, dones


def test_cpu_mujoco_env_succeeds_on_the_toy_hold(at_rest) -> None:
    rewards, dones = _cpu_rewards(at_rest)
    assert dones == [False] * 4 + [True]  # the toy's 5-step hold, not Reach's single step
    assert rewards[-1] > rewards[0] + 9.0  # the toy's success weight (10)


def test_c_batch_matches_the_cpu_env_on_the_toy_task(at_rest) -> None:
    env = make_batched_env(at_rest, backend="mujoco")
    state = jax.jit(env.reset)(jax.random.PRNGKey(0))
    step = jax.jit(env.step)
    rewards, dones = [], []
    for _ in range(5):
        state = step(state, jnp.zeros(6))
        rewards.append(float(state.reward))
        dones.append(bool(state.done))
    cpu_rewards, cpu_dones = _cpu_rewards(at_rest)
    assert dones == cpu_dones
    np.testing.assert_allclose(rewards, cpu_rewards, atol=REWARD_ATOL)


def test_installed_packages_add_tasks_through_entry_points(monkeypatch) -> None:
    """A package's ``mjx_arm.tasks`` entry point is found by name and loaded on first use."""
    from importlib.metadata import EntryPoint

    from mjx_arm.task import registry

    point = EntryPoint(name="hover_pkg", value="toy_task:HOVER", group=registry.ENTRY_POINT_GROUP)
    monkeypatch.setattr(registry, "entry_points", lambda group: [point])
    monkeypatch.setattr(registry, "_TASKS", dict(registry._TASKS))
    registry._load_entry_points.cache_clear()
    try:
        assert "hover_pkg" in task_names()
        assert get_task("hover_pkg") is HOVER
    finally:
        registry._load_entry_points.cache_clear()


def test_the_toy_tasks_own_reward_term_is_paid(at_rest) -> None:
    """The CPU MuJoCo env reports the toy's ``height`` term (the tool tip at rest, 0.37 m up)
    and pays it at the toy's weight: the reward drops by 2 x height when that weight is 0."""
    env = make_env("hover", engine="mujoco", task=at_rest)
    env.reset(seed=0)
    _, paid, _, _, info = env.step(np.zeros(6, np.float32))
    env.close()
    height = info["reward_terms"]["height"]
    assert abs(height - HOVER_HEIGHT) < 0.01
    unpaid_task = at_rest.replace(reward={"height": 0.0})
    env = make_env("hover", engine="mujoco", task=unpaid_task)
    env.reset(seed=0)
    _, unpaid, _, _, _ = env.step(np.zeros(6, np.float32))
    env.close()
    assert abs((paid - unpaid) - 2.0 * height) < 1e-9


def test_the_toy_scene_is_built_from_its_declaration() -> None:
    """Table and target, no box, no cube, the marker not drawn; PyBullet builds the same scene
    and pays the same term."""
    env = make_env("hover", engine="mujoco")
    model = env.unwrapped.model
    names = {model.geom(i).name for i in range(model.ngeom)}
    assert "table_0" in names and "target_box" not in names and "cube" not in names
    assert model.geom("target_marker").rgba[3] == 0.0
    env.close()
    env = make_env("hover", engine="pybullet")
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(6, np.float32))
    env.close()
    assert abs(info["reward_terms"]["height"] - HOVER_HEIGHT) < 0.05


def test_the_toy_budget_reaches_its_preset() -> None:
    from mjx_arm.train.presets import FAST, preset_config

    cpu = preset_config("cpu", "hover")
    assert (
        (cpu.num_timesteps, cpu.num_evals)
        == (50_000, 2)
        == (
            HOVER_BUDGET.num_timesteps,
            HOVER_BUDGET.num_evals,
        )
    )
    assert preset_config("fast", "hover").num_timesteps == FAST.num_timesteps
    assert cpu.task_config().reward.height == 2.0
