"""Gymnasium ids of the tasks, registered on ``import mjx_arm``, and the one CPU env factory.

``gymnasium.make("mjx_arm/Touch-v0", engine=NAME)`` builds a CPU env of a registered engine
(:mod:`mjx_arm.engines`);
``gymnasium.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point")`` the MJX batch;
:func:`make_async_vec` Gymnasium's AsyncVectorEnv of CPU envs, whose workers are not forked.
A task added with :func:`mjx_arm.task.registry.register_task` gets its id from
:func:`register_envs`.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Any

import gymnasium as gym

from mjx_arm import engines
from mjx_arm.names import env_id
from mjx_arm.task.config import TaskConfig, task_config
from mjx_arm.task.registry import task_names

if TYPE_CHECKING:
    from mjx_arm.arm.resolve import ArmTask


def _task(name: str, task: TaskConfig | ArmTask | dict | None) -> TaskConfig | ArmTask:
    from mjx_arm.arm.resolve import ArmTask  # here: ``import mjx_arm`` stays light

    if isinstance(task, TaskConfig | ArmTask):
        return task
    return task_config(name, **(task or {}))


def make_env(
    task_name: str,
    engine: str = "mujoco",
    task: TaskConfig | ArmTask | dict | None = None,
    **kwargs: Any,
) -> gym.Env:
    """Build one env of ``task_name`` on ``engine``, a registered engine with a Gymnasium env
    (:func:`mjx_arm.engines.engine_names` ``("env")``); its class is imported only now (the
    PyBullet reference env lives in its own top-level package).

    Args:
        task_name: a registered task name.
        engine: the CPU engine.
        task: the task on its arm (:class:`~mjx_arm.arm.resolve.ArmTask`: pass no ``arm``),
            the task config, or overrides of the task's preset (None: the preset).
        kwargs: passed to the env class (``arm``: a URDF, an arm file or an ArmConfig;
            ``render_mode``, ...).
    """
    choices = engines.engine_names("env")
    if engine not in choices:
        raise ValueError(f"unknown engine {engine!r}; choose one of {choices}")
    from gymnasium.envs.registration import load_env_creator

    engines.check_installed(engine)
    entry_point = engines.engine(engine).env
    return load_env_creator(entry_point)(_task(task_name, task), **kwargs)


def make_timed_env(task_name: str, **kwargs: Any) -> gym.Env:
    """:func:`make_env` inside a time limit of the env's own ``task.episode_steps``, as the
    arm's setup fills them in (a slow arm's episode is longer: :mod:`mjx_arm.arm.setup`):
    the entry point of the registered ids."""
    env = make_env(task_name, **kwargs)
    return gym.wrappers.TimeLimit(env, env.task.episode_steps)


def make_vector(task_name: str, num_envs: int = 1, **kwargs: Any):
    """The MJX batch of ``num_envs`` envs of ``task_name`` (a Gymnasium vector env)."""
    from mjx_arm.envs.vector import make_vector_env

    return make_vector_env(task_name, num_envs=num_envs, **kwargs)


# Start method of the workers of a Gymnasium AsyncVectorEnv. Forking a process in which JAX has
# started its threads can deadlock the child (JAX warns on ``os.fork()``); a forkserver forks
# the workers from a clean single-threaded server process instead.
ASYNC_CONTEXT = "forkserver"


def make_async_vec(env_name: str, num_envs: int, vector_kwargs: dict | None = None, **kwargs):
    """``gymnasium.make_vec(env_name, num_envs, vectorization_mode="async")`` of the CPU envs,
    its workers started by :data:`ASYNC_CONTEXT` (``vector_kwargs`` may set another)."""
    vector_kwargs = {"context": ASYNC_CONTEXT, **(vector_kwargs or {})}
    return gym.make_vec(
        env_name,
        num_envs=num_envs,
        vectorization_mode="async",
        vector_kwargs=vector_kwargs,
        **kwargs,
    )


def register_envs() -> None:
    """Register the id of every registered task (idempotent; call again after adding one)."""
    for name in task_names():
        if env_id(name) in gym.registry:
            continue
        gym.register(
            id=env_id(name),
            entry_point=functools.partial(make_timed_env, name),
            vector_entry_point=functools.partial(make_vector, name),
            # the time limit comes from the env's own task (make_env): it depends on the arm
            max_episode_steps=None,
        )
