"""Gymnasium ids of the tasks, registered on ``import mjx_arm``.

``gymnasium.make("mjx_arm/Touch-v0", engine="mujoco" | "pybullet")`` builds a CPU env;
``gymnasium.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point")`` the MJX batch.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from mjx_arm.names import CPU_ENGINES as ENGINES
from mjx_arm.names import TASK_IDS as _IDS_OF_TASKS
from mjx_arm.task.config import TaskConfig, task_config

TASK_IDS = {env_id: task for task, env_id in _IDS_OF_TASKS.items()}  # id -> task


def _task(name: str, task: TaskConfig | dict | None) -> TaskConfig:
    if isinstance(task, TaskConfig):
        return task
    return task_config(name, **(task or {}))


# The env class of each CPU engine, as an entry-point string: the PyBullet reference env lives
# in its own top-level package, which is imported only when a PyBullet env is made.
ENGINE_ENTRY_POINTS = {
    "mujoco": "mjx_arm.envs.mujoco_env:MujocoArmEnv",
    "pybullet": "pybullet_ref.env:PybulletArmEnv",
}


def make_env(
    task_name: str, engine: str = "mujoco", task: TaskConfig | dict | None = None, **kwargs: Any
) -> gym.Env:
    """Build one env of ``task_name`` on ``engine`` ("mujoco" or "pybullet")."""
    if engine not in ENGINE_ENTRY_POINTS:
        raise ValueError(f"unknown engine {engine!r}; choose one of {ENGINES}")
    from gymnasium.envs.registration import load_env_creator

    return load_env_creator(ENGINE_ENTRY_POINTS[engine])(_task(task_name, task), **kwargs)


def make_reach(**kwargs: Any) -> gym.Env:
    """Entry point of ``mjx_arm/Reach-v0``."""
    return make_env("reach", **kwargs)


def make_touch(**kwargs: Any) -> gym.Env:
    """Entry point of ``mjx_arm/Touch-v0``."""
    return make_env("touch", **kwargs)


def make_reach_vector(num_envs: int = 1, **kwargs: Any):
    """Vector entry point of ``mjx_arm/Reach-v0``: the MJX batch."""
    from mjx_arm.envs.vector import make_vector_env

    return make_vector_env("reach", num_envs=num_envs, **kwargs)


def make_touch_vector(num_envs: int = 1, **kwargs: Any):
    """Vector entry point of ``mjx_arm/Touch-v0``: the MJX batch."""
    from mjx_arm.envs.vector import make_vector_env

    return make_vector_env("touch", num_envs=num_envs, **kwargs)


def register_envs() -> None:
    """Register both ids (idempotent)."""
    entries = {
        "mjx_arm/Reach-v0": (make_reach, make_reach_vector),
        "mjx_arm/Touch-v0": (make_touch, make_touch_vector),
    }
    for env_id, (entry, vector_entry) in entries.items():
        if env_id in gym.registry:
            continue
        gym.register(
            id=env_id,
            entry_point=entry,
            vector_entry_point=vector_entry,
            max_episode_steps=TaskConfig().episode_steps,
        )
