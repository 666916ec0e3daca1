"""The engine-neutral task contract: config, observation, reward, success, sampling, wrench.

Each task is one file (:mod:`mjx_arm.task.reach`, :mod:`mjx_arm.task.touch`,
:mod:`mjx_arm.task.lift`) holding a :class:`~mjx_arm.task.spec.Task` that declares its rules,
reward terms, scene and training budgets; :mod:`mjx_arm.task.registry` finds them by name.
"""

from mjx_arm.task.config import REWARD_TERMS, RewardConfig, TaskConfig, task_config
from mjx_arm.task.observation import (
    OBS_KEYS,
    OBS_LAYOUT,
    OBS_SIZE,
    assemble_obs,
    flat_observation_space,
    flatten_obs,
    observation_space,
    unflatten_obs,
)
from mjx_arm.task.reach import reach_config
from mjx_arm.task.registry import get_task, register_task, task_names, unregister_task
from mjx_arm.task.spec import Task
from mjx_arm.task.touch import touch_config

__all__ = [
    "OBS_KEYS",
    "OBS_LAYOUT",
    "OBS_SIZE",
    "REWARD_TERMS",
    "RewardConfig",
    "Task",
    "TaskConfig",
    "assemble_obs",
    "flat_observation_space",
    "flatten_obs",
    "get_task",
    "observation_space",
    "reach_config",
    "register_task",
    "task_config",
    "task_names",
    "touch_config",
    "unflatten_obs",
    "unregister_task",
]
