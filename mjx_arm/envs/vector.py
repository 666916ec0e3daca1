"""A Gymnasium ``VectorEnv`` backed by the batched JAX env (MJX or C MuJoCo physics).

``gymnasium.make_vec("mjx_arm/Touch-v0", num_envs=N, vectorization_mode="vector_entry_point")``
returns :class:`ArmVectorEnv`: numpy in and out, the contract's Dict observation, and the
``SAME_STEP`` autoreset mode (a finished env is reset inside the step that ends it; its last
observation and info are in ``info["final_obs"]`` / ``info["final_info"]``). ``info["diverged"]``
``(num_envs,)`` flags the envs whose physics diverged in this step (a NaN or infinite state, or a
runaway joint speed); they are terminated and reset like any finished env, and the other envs
step on unaffected.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from mjx_arm.arm.resolve import ArmTask
from mjx_arm.envs.backend import (
    MemoryEstimate,
    check_memory,
    estimate_env_memory,
    make_batched_env,
    state_on_host,
)
from mjx_arm.envs.base import InvalidActionError, check_action
from mjx_arm.envs.mjx_physics import batched_where
from mjx_arm.envs.physics_config import PhysicsConfig
from mjx_arm.inputs import ConfigError
from mjx_arm.task import observation as obs_lib
from mjx_arm.task.config import TaskConfig, task_config


class ArmVectorEnv(VectorEnv):
    """``num_envs`` copies of a task stepped as one jitted batch.

    Args:
        task: the task on its arm (:class:`~mjx_arm.arm.resolve.ArmTask`), or a task
            configuration resolved with ``arm``.
        num_envs: batch size.
        backend: "auto" (MJX on an accelerator, C MuJoCo on a CPU), "mjx" or "mujoco".
        physics: the MJX implementation (``mjx`` only; default ``impl="auto"``: Warp on a GPU
            where it is installed).
        arm: with a task configuration, the arm (a URDF, an arm file or an ArmConfig; default:
            the shipped arm); None with an ArmTask.

    Raises:
        ConfigError: ``num_envs`` is not a whole number >= 1 (a ValueError).
        InsufficientMemoryError: the batch would not fit in the host's available memory
            (checked before anything of the batch is allocated).
    """

    metadata: ClassVar[dict[str, Any]] = {
        "autoreset_mode": AutoresetMode.SAME_STEP,
        "render_modes": [],
    }

    def __init__(
        self,
        task: TaskConfig | ArmTask,
        num_envs: int,
        backend: str = "auto",
        physics: PhysicsConfig | None = None,
        arm=None,
    ) -> None:
        self.num_envs = check_num_envs(num_envs)
        self.env = make_batched_env(task, backend, physics, batch_size=num_envs, arm=arm)
        self.task, n = self.env.task, self.env.action_size
        if state_on_host(self.env):
            check_memory(self.memory_estimate(), num_envs, "num_envs")
        joints, extra = self.env.arm.n_joints, self.env.task_spec.extra_obs
        coding = self.env.arm.joint_coding(self.task)
        self.single_observation_space = obs_lib.observation_space(
            self.task.force_clip, joints, extra, coding
        )
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.single_action_space = gym.spaces.Box(-1.0, 1.0, (n,), np.float32)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._reset = jax.jit(jax.vmap(self.env.reset))
        self._step = jax.jit(jax.vmap(self.env.step))
        self._select = jax.jit(self._merge)
        self._state = None
        self._steps = np.zeros(num_envs, np.int64)
        self._key = jax.random.PRNGKey(0)

    def memory_estimate(self) -> MemoryEstimate:
        """Host bytes of the batch: the env's (:func:`estimate_env_memory`) plus, per env, the
        spaces' float32 bounds (low and high of the observation and the action) and three float32
        observations (returned, final, reset) and float64 actions, rewards and flags."""
        obs, act = self.env.observation_size, self.env.action_size
        env = estimate_env_memory(self.env)
        host = 4 * 2 * (obs + act) + 4 * 3 * obs + 8 * (act + 4)
        return MemoryEstimate(env.fixed, env.per_env + host)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset every env; ``seed`` seeds the batch's PRNG key."""
        self._ensure_open("reset")
        if seed is not None:
            self._key = jax.random.PRNGKey(seed)
        self._key, key = jax.random.split(self._key)
        self._state = self._reset(jax.random.split(key, self.num_envs))
        self._steps[:] = 0
        return self._obs(self._state.obs), {}

    def step(self, actions):
        """Step every env with ``actions (num_envs, n)``; finished envs reset in the same step."""
        self._ensure_open("step")
        if self._state is None:
            raise RuntimeError("call reset() before step()")
        actions = self._check_actions(actions)
        state = self._step(self._state, jnp.asarray(actions))
        self.env.physics.check_overflow(state.metrics["physics_overflow"])
        self._steps += 1
        terminated = np.asarray(state.done) > 0
        truncated = (self._steps >= self.task.episode_steps) & ~terminated
        obs = self._obs(state.obs)
        info = self._info(state)
        rewards = np.asarray(state.reward, dtype=np.float64)
        done = terminated | truncated
        if done.any():
            info["final_obs"] = obs
            info["final_info"] = dict(info)
            info["_final_obs"] = info["_final_info"] = done
            self._key, key = jax.random.split(self._key)
            fresh = self._reset(jax.random.split(key, self.num_envs))
            state = self._select(jnp.asarray(done), fresh, state)
            self._steps[done] = 0
            obs = self._obs(state.obs)
        self._state = state
        return obs, rewards, terminated, truncated, info

    def _check_actions(self, actions) -> np.ndarray:
        """``actions (num_envs, n)`` checked as each engine's env checks one (real, finite:
        :func:`~mjx_arm.envs.base.check_action`), clipped into [-1, 1], float32.

        Raises:
            InvalidActionError: not an array of real numbers, of another shape, NaN or inf.
        """
        bounds = (self.single_action_space.low, self.single_action_space.high)
        try:
            rows = np.asarray(actions)
        except (ValueError, TypeError) as exc:
            if isinstance(actions, Sequence) and len(actions) == self.num_envs:
                for row in actions:  # a ragged row: the error of the single env
                    check_action(row, bounds)
            raise InvalidActionError(f"action must be an array of real numbers: {exc}") from None
        shape = (self.num_envs, self.env.action_size)
        if rows.shape != shape:
            raise InvalidActionError(f"actions must have shape {shape}, got {rows.shape}")
        return np.stack([check_action(a, bounds) for a in rows])

    def close_extras(self, **kwargs: Any) -> None:
        """Drop the batch's state; reset() and step() then raise ClosedEnvironmentError."""
        self._state = None

    def _ensure_open(self, method: str) -> None:
        if self.closed:
            raise gym.error.ClosedEnvironmentError(
                f"{method}() called after close(); make a new batched env"
            )

    def _merge(self, done: jax.Array, fresh, state):
        """Per env: the ``fresh`` state where done, else ``state`` (the physics merges data)."""
        data = self.env.physics.where(done, fresh.pipeline_state, state.pipeline_state)
        rest = batched_where(
            done, fresh.replace(pipeline_state=None), state.replace(pipeline_state=None)
        )
        return rest.replace(pipeline_state=data)

    def _obs(self, flat) -> dict[str, np.ndarray]:
        flat = np.asarray(flat, dtype=np.float32)
        return {
            k: np.ascontiguousarray(v)
            for k, v in obs_lib.unflatten_obs(flat, self.env.task_spec.extra_obs).items()
        }

    @staticmethod
    def _info(state) -> dict[str, Any]:
        m = {k: np.asarray(v) for k, v in state.metrics.items()}
        info = {
            "is_success": m["success"] > 0,
            "distance": m["distance"],
            "contact_force_norm": m["contact_force"],
            "reward_terms": {k[7:]: v for k, v in m.items() if k.startswith("reward/")},
            "diverged": m["diverged"] > 0,
        }
        return info


def check_num_envs(num_envs: Any) -> int:
    """``num_envs`` checked to be a whole number >= 1 (Python's or numpy's; not a bool).

    Raises:
        ConfigError: anything else (zero envs have nothing to step or stack).
    """
    if isinstance(num_envs, bool) or not isinstance(num_envs, int | np.integer) or num_envs < 1:
        raise ConfigError(f"num_envs must be a whole number >= 1, got {num_envs!r}")
    return int(num_envs)


def make_vector_env(
    task_name: str,
    num_envs: int = 1,
    task: TaskConfig | dict | None = None,
    backend: str = "auto",
    max_episode_steps: int | None = None,
    physics: PhysicsConfig | dict | None = None,
    arm=None,
    **kwargs: Any,
) -> ArmVectorEnv:
    """Vector entry point of the registered ids (``max_episode_steps`` sets the episode length)."""
    if kwargs:
        raise TypeError(f"unexpected arguments for the batched env: {sorted(kwargs)}")
    cfg = task if isinstance(task, TaskConfig) else task_config(task_name, **(task or {}))
    if max_episode_steps is not None:
        cfg = cfg.replace(episode_steps=int(max_episode_steps))
    if isinstance(physics, dict):
        physics = PhysicsConfig.from_dict(physics)
    return ArmVectorEnv(cfg, num_envs, backend, physics, arm)
