"""The engine-neutral task contract: config, observation, reward, success, sampling, wrench."""

from mjx_arm.task.config import (
    REWARD_TERMS,
    RewardConfig,
    TaskConfig,
    reach_config,
    task_config,
    touch_config,
)
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

__all__ = [
    "OBS_KEYS",
    "OBS_LAYOUT",
    "OBS_SIZE",
    "REWARD_TERMS",
    "RewardConfig",
    "TaskConfig",
    "assemble_obs",
    "flat_observation_space",
    "flatten_obs",
    "observation_space",
    "reach_config",
    "task_config",
    "touch_config",
    "unflatten_obs",
]
