"""``BaseRobotEnv``: the Gymnasium side of the contract, shared by every CPU engine.

The base class owns everything engine-neutral: spaces, action checking and scaling, episode
sampling, observation assembly, reward, success and termination (all from :mod:`mjx_arm.task`).
An engine subclass implements the five ``_physics_*`` / ``_render_frame`` hooks and nothing else.
"""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from mjx_arm.envs.arm import ArmInfo, arm_info
from mjx_arm.paths import default_arm_urdf
from mjx_arm.task import observation as obs_lib
from mjx_arm.task import reward as reward_lib
from mjx_arm.task import sampling
from mjx_arm.task.config import TaskConfig, touch_config
from mjx_arm.urdf.validate import validated

DEFAULT_WIDTH, DEFAULT_HEIGHT = 640, 480


@dataclass(frozen=True)
class PhysicsReading:
    """One read-out of the physics after a control step (world frame = base frame).

    Attributes:
        ee_pos: ee point (m), ``(3,)``; ee_quat: ee orientation (w, x, y, z), ``(4,)``.
        qpos, qvel: joint angles (rad) and velocities (rad/s), ``(6,)`` each.
        target_pos: the target point (m), ``(3,)``.
        wrench: tared external wrench on the tool in the ee frame, ``(6,)``, unclipped.
    """

    ee_pos: np.ndarray
    ee_quat: np.ndarray
    qpos: np.ndarray
    qvel: np.ndarray
    target_pos: np.ndarray
    wrench: np.ndarray

    def finite(self) -> bool:
        """True when every quantity is finite."""
        return all(np.all(np.isfinite(v)) for v in vars(self).values())


class BaseRobotEnv(gym.Env):
    """A 6-DoF arm task with the contract's spaces, reward and success rule.

    Args:
        task: the task configuration (default: Touch).
        urdf: the arm URDF (default: the shipped UR5e-class arm). It is validated for the
            engine before anything is loaded; an invalid URDF raises ``UrdfError``.
        render_mode: None, "rgb_array" or "human".
        width, height: frame size (pixels) of ``render()``.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array", "human"], "render_fps": 30}
    engine: str = "none"

    def __init__(
        self,
        task: TaskConfig | None = None,
        urdf: str | Path | None = None,
        render_mode: str | None = None,
        width: int = DEFAULT_WIDTH,
        height: int = DEFAULT_HEIGHT,
    ) -> None:
        self.task = task or touch_config()
        self.metadata = {**self.metadata, "render_fps": round(1.0 / self.task.ctrl_dt)}
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}")
        self.render_mode, self.width, self.height = render_mode, width, height
        path = Path(urdf).expanduser().resolve() if urdf is not None else default_arm_urdf()
        validated(path, self.engine)  # before parsing: a broken file fails with the report
        self.arm: ArmInfo = arm_info(path)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (6,), np.float32)
        self.observation_space = obs_lib.observation_space(self.task.force_clip)
        self._reading: PhysicsReading | None = None
        self._last_obs: dict[str, np.ndarray] | None = None

    # ------------------------------------------------------------------ engine hooks

    @abstractmethod
    def _physics_reset(self, qpos: np.ndarray, target_body_pos: np.ndarray) -> None:
        """Put the arm at ``qpos`` (rad, at rest) and the target body at ``target_body_pos``."""

    @abstractmethod
    def _physics_set_velocity_targets(self, qdot_target: np.ndarray) -> None:
        """Command joint velocity targets (rad/s), torque capped at the URDF effort."""

    @abstractmethod
    def _physics_step(self, n_substeps: int) -> None:
        """Advance the physics by ``n_substeps`` steps of ``task.sim_dt``."""

    @abstractmethod
    def _physics_read(self) -> PhysicsReading:
        """Read the state the contract needs."""

    @abstractmethod
    def _render_frame(self) -> np.ndarray:
        """An RGB frame ``(height, width, 3)`` uint8 from the shared camera pose."""

    # ------------------------------------------------------------------ the six contract methods

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start an episode: home pose plus noise, a new target, both from the seeded generator."""
        super().reset(seed=seed)
        u = self.np_random.uniform(size=sampling.N_UNIFORMS)
        qpos = sampling.initial_qpos(np, u[:6], self.task)
        body = sampling.target_body_pos(np, u[6:], self.task)
        if options and "target" in options:
            body = np.asarray(options["target"], dtype=np.float64)
        self._physics_reset(qpos, body)
        self._reading = self._physics_read()
        obs = self._observe(self._reading)
        return obs, self._info(self._reading, None, False)

    def step(self, action):
        """Apply one action for ``ctrl_dt``: (obs, reward, terminated, truncated, info)."""
        if self._reading is None:
            raise RuntimeError("call reset() before step()")
        self.apply_action(action)
        self._physics_step(self.task.n_substeps)
        reading = self._physics_read()
        finite = reading.finite()
        if finite:
            self._reading = reading
        obs = self._observe(self._reading) if finite else self._last_obs
        success = finite and self.is_success()
        terms = self._reward_terms(self._reading, success, not finite)
        reward = float(reward_lib.total_reward(terms, self.task))
        terminated = (not finite) or (success and self.task.terminate_on_success)
        info = self._info(self._reading, terms, success)
        info["nonfinite"] = not finite
        return obs, reward, bool(terminated), False, info

    def render(self):
        """The current frame (rgb_array) or None after drawing it (human)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None
        frame = self._render_frame()
        if self.render_mode == "human":
            self._show(frame)
            return None
        return frame

    def get_ee_pose(self) -> np.ndarray:
        """End-effector pose (x, y, z, qw, qx, qy, qz), float64, ``w >= 0``."""
        reading = self._physics_read()
        quat = obs_lib.canonical_quat(np, reading.ee_quat)
        return np.concatenate([reading.ee_pos, quat])

    def apply_action(self, action) -> np.ndarray:
        """Check and clip an action, command joint velocity targets; return them (rad/s)."""
        action = check_action(action)
        qdot = action.astype(np.float64) * self.task.action_scale * self.arm.v_max
        self._physics_set_velocity_targets(qdot)
        return qdot

    def is_success(self) -> bool:
        """Success rule of the task on the current state."""
        if self._reading is None:
            return False
        d, force = self._distance_and_force(self._reading)
        return bool(reward_lib.is_success(np, d, force, self.task))

    # ------------------------------------------------------------------ helpers

    def _distance_and_force(self, reading: PhysicsReading) -> tuple[float, float]:
        d = float(reward_lib.target_distance(np, reading.ee_pos, reading.target_pos))
        wrench = np.clip(reading.wrench, -self.task.force_clip, self.task.force_clip)
        return d, float(np.linalg.norm(wrench[:3]))

    def _observe(self, reading: PhysicsReading) -> dict[str, np.ndarray]:
        obs = obs_lib.assemble_obs(
            np,
            reading.ee_pos,
            reading.ee_quat,
            reading.qpos,
            reading.target_pos,
            reading.wrench,
            self.task.force_clip,
        )
        self._last_obs = obs
        return obs

    def _reward_terms(self, reading: PhysicsReading, success: bool, nonfinite: bool) -> dict:
        d, force = self._distance_and_force(reading)
        terms = reward_lib.reward_terms(
            np,
            d,
            force,
            reading.qpos,
            reading.qvel,
            (self.arm.lower, self.arm.upper),
            success,
            nonfinite,
            self.task,
        )
        return {name: float(value) for name, value in terms.items()}

    def _info(self, reading: PhysicsReading, terms: dict | None, success: bool) -> dict:
        d, force = self._distance_and_force(reading)
        return {
            "is_success": bool(success),
            "distance": d,
            "contact_force_norm": force,
            "reward_terms": terms or {},
        }

    def _show(self, frame: np.ndarray) -> None:
        """Draw a frame in a window (needs a display and matplotlib)."""
        import matplotlib.pyplot as plt

        if getattr(self, "_figure", None) is None:
            plt.ion()
            self._figure = plt.figure("mjx_arm")
            self._image = plt.imshow(frame)
            plt.axis("off")
        else:
            self._image.set_data(frame)
        self._figure.canvas.draw_idle()
        plt.pause(1.0 / self.metadata["render_fps"])


def check_action(action) -> np.ndarray:
    """Validate an action: shape ``(6,)``, finite; clip into [-1, 1]; return float32.

    Raises:
        ValueError: wrong shape, or NaN / inf entries.
    """
    arr = np.asarray(action, dtype=np.float64)
    if arr.shape != (6,):
        raise ValueError(f"action must have shape (6,), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"action contains NaN or inf: {arr.tolist()}")
    return np.clip(arr, -1.0, 1.0).astype(np.float32)
