"""The episode a checkpoint records: the policy of that checkpoint, deterministic, for one
episode in the CPU MuJoCo env of the run's task, its last transitions kept for ``mjx-arm
replay``.

One :class:`CheckpointEpisode` serves every checkpoint of a run: the env is built once and the
policy compiled once, and the policy runs on JAX's CPU device (where the process has one), so
that its 150 small calls neither wait behind the training programs on the GPU nor add a GPU
round trip per step.
"""

from __future__ import annotations

from typing import Any

import jax
import numpy as np

from mjx_arm.arm.resolve import ArmTask
from mjx_arm.task.config import TaskConfig

TRANSITIONS_KEPT = 100
COLUMNS = ("obs", "action", "reward", "done", "ee_pos", "contact_force")


def host_device() -> Any:
    """JAX's CPU device, or None where the process has none (``JAX_PLATFORMS=cuda``)."""
    try:
        return jax.devices("cpu")[0]
    except RuntimeError:
        return None


class CheckpointEpisode:
    """Records one evaluation episode of a policy per call (see the module's docstring).

    Args:
        make_policy: ``(params, deterministic) -> policy`` (Brax's).
        task: the run's task on its arm (an :class:`~mjx_arm.arm.resolve.ArmTask`), or a task
            config on ``arm`` (default: the shipped arm).
    """

    def __init__(self, make_policy, task: TaskConfig | ArmTask, arm: Any = None) -> None:
        self._task, self._arm = task, arm
        self._env: Any = None
        self._device = host_device()
        self._key = jax.device_put(jax.random.PRNGKey(0), self._device)
        # params as an argument, not a constant: one program for every checkpoint
        self._act = jax.jit(lambda p, obs, key: make_policy(p, deterministic=True)(obs, key))

    def record(self, params: Any, seed: int) -> dict[str, np.ndarray]:
        """One episode of ``params`` from the env's reset with ``seed``; its last 100
        transitions.

        Returns:
            obs ``(T, 16 + n)``, action ``(T, n)``, reward ``(T,)``, done ``(T,)``, ee_pos
            ``(T, 3)``, contact_force ``(T,)`` with T <= 100.
        """
        from mjx_arm.task.observation import flatten_obs

        env = self._make_env()
        params = jax.device_put(params, self._device) if self._device is not None else params
        obs, _ = env.reset(seed=int(seed) % (2**31))
        rows: dict[str, list] = {k: [] for k in COLUMNS}
        for _ in range(env.task.episode_steps):
            flat = flatten_obs(np, obs)
            action = np.asarray(self._act(params, flat, self._key)[0], dtype=np.float32)
            obs, reward, terminated, _, info = env.step(action)
            values = (flat, action, reward, terminated, obs["ee_pose"][:3])
            for name, value in zip(COLUMNS, (*values, info["contact_force_norm"]), strict=True):
                rows[name].append(value)
            if terminated:
                break
        return {k: np.asarray(v[-TRANSITIONS_KEPT:]) for k, v in rows.items()}

    def _make_env(self) -> Any:
        if self._env is None:
            from mjx_arm.envs.mujoco_env import MujocoArmEnv

            self._env = MujocoArmEnv(self._task, self._arm)
        return self._env

    def close(self) -> None:
        if self._env is not None:
            self._env.close()
            self._env = None
