"""``BaseRobotEnv``: the Gymnasium side of the contract, shared by every CPU engine.

The base class owns everything engine-neutral: spaces, action checking and scaling, episode
sampling, observation assembly, reward, success and termination (all from :mod:`mjx_arm.task`).
An engine subclass implements the five ``_physics_*`` / ``_render_frame`` hooks and nothing else.

Divergence: after every control step the reading is checked. A NaN or infinite value, or a joint
faster than ``TaskConfig.divergence_speed_factor`` times its URDF velocity limit, means the
physics diverged. The step then returns the last sane observation (finite and inside the
observation space), ``terminated=True``, ``info["diverged"] = True`` (also under its older name
``info["nonfinite"]``) and the ``nonfinite`` reward term; the next ``reset()`` starts from a
clean physics state.

After ``close()`` every call that needs the physics (``reset``, ``step``, ``apply_action``,
``render``, ``get_ee_pose``) raises Gymnasium's own ``ClosedEnvironmentError`` in every engine, as
Gymnasium's vector envs do: ``close()`` frees the engine (PyBullet's server is gone), so an env
that went on working in one engine and failed in another would hide a use-after-close bug.
``close()`` itself may be called again.

One thread at a time: a second thread that calls ``reset``, ``step``, ``render``,
``get_ee_pose`` or ``apply_action`` while another is inside raises ``ConcurrentEnvUseError``
(a RuntimeError, :mod:`mjx_arm.envs.guards`) instead of crashing the engine.
"""

from __future__ import annotations

import math
import operator
import warnings
from abc import abstractmethod
from pathlib import Path
from typing import Any, ClassVar, NamedTuple

import gymnasium as gym
import numpy as np

from mjx_arm.arm.config import ArmConfig
from mjx_arm.arm.info import ArmInfo
from mjx_arm.arm.resolve import ArmTask, as_arm_task
from mjx_arm.envs.guards import SingleThreadEnv, reset_overrides
from mjx_arm.envs.scalar.codegen import Scorer, step_scorers
from mjx_arm.envs.scalar.state import ScalarState, finite
from mjx_arm.envs.scalar.step import StepInput
from mjx_arm.envs.scalar.xp import SCALAR_XP
from mjx_arm.task import observation as obs_lib
from mjx_arm.task import reward as reward_lib
from mjx_arm.task import sampling
from mjx_arm.task.config import TaskConfig
from mjx_arm.task.grip import ObjectStart
from mjx_arm.video import FrameWindow

DEFAULT_WIDTH, DEFAULT_HEIGHT = 640, 480


class PhysicsReading(NamedTuple):
    """One read-out of the physics after a control step (world frame = base frame).

    Immutable; the arrays belong to the reading (copies, not views into the engine's state).

    Attributes:
        ee_pos: ee point (m), ``(3,)``; ee_quat: ee orientation (w, x, y, z), ``(4,)``.
        qpos, qvel: joint angles (rad) and velocities (rad/s), ``(n,)`` each.
        target_pos: the target point (m), ``(3,)``.
        wrench: tared external wrench on the tool in the ee frame, ``(6,)``, unclipped.
        grip: a gripper task's read-out (:data:`mjx_arm.task.grip.GRIP_LAYOUT`), ``(10,)``;
            ``(0,)`` for the other tasks.
    """

    ee_pos: np.ndarray
    ee_quat: np.ndarray
    qpos: np.ndarray
    qvel: np.ndarray
    target_pos: np.ndarray
    wrench: np.ndarray
    grip: np.ndarray = np.zeros(0)

    def finite(self) -> bool:
        """True when every quantity is finite."""
        return bool(np.isfinite(np.concatenate(self)).all())


# What the contract makes of one reading (:meth:`BaseRobotEnv._evaluate`): obs, reward,
# success, info. A plain tuple: it is built at every step.
_Evaluation = tuple[dict[str, np.ndarray], float, bool, dict[str, Any]]


class BaseRobotEnv(SingleThreadEnv, gym.Env):
    """An arm task with the contract's spaces, reward and success rule.

    Args:
        task: the task on its arm, resolved once (:class:`~mjx_arm.arm.resolve.ArmTask`), or
            a task configuration (default: Touch) to resolve with ``arm`` here
            (:func:`~mjx_arm.arm.resolve.resolve_task`: its empty ``home_qpos``,
            ``workspace_scale`` and ``episode_steps`` are filled in from the arm).
        arm: with a task configuration, the arm: a URDF path, an arm file (.toml/.json) or an
            :class:`~mjx_arm.arm.config.ArmConfig` (default: the shipped UR5e-class arm);
            None with an ``ArmTask``. Its URDF is validated for the engine before anything is
            loaded; an invalid URDF raises ``UrdfError``.
        render_mode: None, "rgb_array" or "human".
        width, height: frame size (pixels) of ``render()``.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array", "human"], "render_fps": 30}
    engine: str = "none"
    _closed: bool = False

    def __init__(
        self,
        task: TaskConfig | ArmTask | None = None,
        arm: str | Path | ArmConfig | None = None,
        render_mode: str | None = None,
        width: int = DEFAULT_WIDTH,
        height: int = DEFAULT_HEIGHT,
    ) -> None:
        self.arm_task = as_arm_task(task, arm, self.engine)
        self.arm: ArmInfo = self.arm_task.arm
        self.task = self.arm_task.task
        self.metadata = {**self.metadata, "render_fps": round(1.0 / self.task.ctrl_dt)}
        self._set_render(render_mode, width, height)
        n = self.arm.n_joints
        self.task_spec = self.task.spec
        self._extra = self.task_spec.extra_obs
        self._gripper_scale = gripper_speed(self.arm, self.task)
        na = action_size(self.arm, self.task)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (na,), np.float32)
        self._coding = self.arm.joint_coding(self.task)
        self.observation_space = obs_lib.observation_space(
            self.task.force_clip, n, self._extra, self._coding
        )
        # constants of the per-step evaluation, computed once
        self._n_substeps = self.task.n_substeps
        # a * (action_scale * v_max) where the limit is inside [V_LOW, V_HIGH] (TaskConfig):
        # bit-identical to (a * action_scale) * v_max for power-of-two scales
        self._qdot_scale = self.task.joint_speeds(self.arm.v_max)
        self._band = reward_lib.joint_band((self.arm.lower, self.arm.upper), self.task)
        self._band_lists = reward_lib.JointBand(*(part.tolist() for part in self._band))
        self._speed_limits = reward_lib.speed_limits(self.arm.v_max, self.task)
        self._speed_list = self._speed_limits.tolist()
        self._flat = ScalarState(self.task.force_clip, self._coding, self._extra)
        self._reading: PhysicsReading | None = None
        self._last_obs: dict[str, np.ndarray] | None = None
        # what the success rule and the motion terms remember within an episode (Python
        # scalars: the rules score one env's step through SCALAR_XP)
        self._progress = reward_lib.start_progress(SCALAR_XP)
        self._action = np.zeros(na, np.float32)
        self._action_bounds = (np.full(na, -1.0, np.float32), np.full(na, 1.0, np.float32))
        self._distance = 0.0
        self._scores = self._scorers()

    def _set_render(self, render_mode: str | None, width: int, height: int) -> None:
        """Check ``render_mode`` and keep the frame size; "human" opens its window (on a
        machine without a display: a warning that says so and how to get frames, not
        silence; the env still runs, as Gymnasium's checker expects of every listed mode)."""
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}")
        self.render_mode, self.width, self.height = render_mode, width, height
        self._window = None
        if render_mode == "human":
            try:
                self._window = FrameWindow(self.metadata["render_fps"])
            except RuntimeError as err:
                warnings.warn(f"{err}; nothing will be shown", stacklevel=3)

    @property
    def dt(self) -> float:
        """Seconds one ``step()`` advances (the task's ``ctrl_dt``)."""
        return self.task.ctrl_dt

    # ------------------------------------------------------------------ engine hooks

    @abstractmethod
    def _physics_reset(
        self, qpos: np.ndarray, target_body_pos: np.ndarray, obj: ObjectStart | None = None
    ) -> None:
        """Put the arm at ``qpos`` (rad, at rest) and the target body at ``target_body_pos``;
        a gripper task's free object goes there too, at rest, with the orientation, mass and
        friction of ``obj``, and the gripper opens."""

    def _physics_set_gripper(self, speed: float) -> None:
        """Command the driven finger's velocity target (m/s; positive closes): gripper engines."""
        raise NotImplementedError(f"the {self.engine} env has no gripper")

    @abstractmethod
    def _physics_set_velocity_targets(self, qdot_target: np.ndarray) -> None:
        """Command joint velocity targets (rad/s), torque capped at the URDF effort."""

    @abstractmethod
    def _physics_step(self, n_substeps: int) -> None:
        """Advance the physics by ``n_substeps`` steps of ``task.sim_dt``."""

    @abstractmethod
    def _physics_read(self) -> PhysicsReading:
        """Read the state the contract needs, into arrays of its own (no views of the engine's
        state: the last finite reading is kept while the physics steps on)."""

    @abstractmethod
    def _render_frame(self) -> np.ndarray:
        """An RGB frame ``(height, width, 3)`` uint8 from the shared camera pose."""

    # ------------------------------------------------------------------ the six contract methods

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start an episode: home pose plus noise, a new target, both from the seeded generator.

        ``options``: ``target`` (the target body's position, m, within the observation's
        +-2 m) and, for a gripper task, ``object_quat`` (the object's orientation, w x y z),
        ``object_mass`` (kg) and ``object_friction`` replace the drawn ones; a value of the
        wrong shape, NaN or out of range raises
        :class:`~mjx_arm.envs.guards.InvalidResetOptionError`.
        """
        self._ensure_open("reset")
        super().reset(seed=seed)
        n = self.arm.n_joints
        u = self.np_random.uniform(size=sampling.n_uniforms(n, self.task))
        qpos = sampling.initial_qpos(np, u[:n], self.task)
        body = sampling.target_body_pos(np, u[n:], self.task)
        obj = self.task_spec.object_start(np, u[n:], self.task)
        body, obj = reset_overrides(options, body, obj)
        self._physics_reset(qpos, body, obj)
        self._reading = reading = self._physics_read()
        _, state, d, force = self._measure(reading)
        self._last_obs = obs = self._observation(state)
        self._progress = reward_lib.start_progress(SCALAR_XP)
        self._action = np.zeros(self.action_space.shape, np.float32)
        self._distance = d
        info = {"is_success": False, "distance": d, "contact_force_norm": force, "reward_terms": {}}
        return obs, info

    def step(self, action):
        """Apply one action for ``ctrl_dt``: (obs, reward, terminated, truncated, info)."""
        self._ensure_open("step")
        if self._reading is None:
            raise RuntimeError("call reset() before step()")
        clipped = check_action(action, self._action_bounds)
        self._command(clipped)
        self._physics_step(self._n_substeps)
        reading = self._physics_read()
        change = float(reward_lib.action_change(SCALAR_XP, clipped, self._action))
        self._action = clipped
        result = self._evaluate(reading, change=change)
        if result is None:  # diverged: keep the last sane reading and observation, and stop
            _, reward, _, info = self._evaluate(self._reading, diverged=True, change=change)
            return self._last_obs, reward, True, False, info
        self._reading = reading
        self._last_obs, reward, done, info = result
        return result[0], reward, done, False, info

    def render(self):
        """The current frame (rgb_array) or None after drawing it (human)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None
        self._ensure_open("render")
        frame = self._render_frame()
        if self.render_mode == "human":
            if self._window is not None:  # None: no display, said when the env was made
                self._window.show(frame)
            return None
        return frame

    def get_ee_pose(self) -> np.ndarray:
        """End-effector pose (x, y, z, qw, qx, qy, qz), float64, ``w >= 0``."""
        self._ensure_open("get_ee_pose")
        reading = self._physics_read()
        quat = obs_lib.canonical_quat(np, reading.ee_quat)
        return np.concatenate([reading.ee_pos, quat])

    def apply_action(self, action) -> np.ndarray:
        """Check and clip an action, command joint velocity targets; return them (rad/s)."""
        self._ensure_open("apply_action")
        return self._command(check_action(action, self._action_bounds))

    def close(self) -> None:
        """Mark the env closed (engines free their resources first); calling it again is fine."""
        self._closed = True
        super().close()

    def _ensure_open(self, method: str) -> None:
        if self._closed:
            raise gym.error.ClosedEnvironmentError(
                f"{method}() called after close(); make a new {self.engine} env"
            )

    def _command(self, clipped: np.ndarray) -> np.ndarray:
        """Send a clipped action to the physics: the arm's joint velocity targets (returned,
        rad/s) and, for a gripper task, the last entry as the finger's speed."""
        n = self.arm.n_joints
        qdot = clipped[:n] * self._qdot_scale
        self._physics_set_velocity_targets(qdot)
        if self._gripper_scale:
            self._physics_set_gripper(float(clipped[n]) * self._gripper_scale)
        return qdot

    def is_success(self) -> bool:
        """Whether the episode has succeeded: the success condition held for
        ``success_hold_steps`` control steps (and, where configured, no strike)."""
        if self._reading is None:
            return False
        success = self._progress.hold >= self.task.success_hold_steps
        if self.task.fail_on_overforce:
            success = success and not self._progress.over
        return bool(success)

    # ------------------------------------------------------------------ helpers

    def _measure(self, reading: PhysicsReading) -> tuple[list, list, float, float]:
        """The flat state before and after clipping (``16 + n + k`` floats), distance d (m)
        and contact force norm (N) of a reading, each computed once, in Python floats
        (:mod:`mjx_arm.envs.scalar.state`)."""
        r, spec, extra = reading, self.task_spec, None
        if self._extra:
            extra = spec.grip_observation(SCALAR_XP, r.ee_pos, r.ee_quat, r.grip, self.task)
        return self._flat.measure(r.ee_pos, r.ee_quat, r.qpos, r.target_pos, r.wrench, extra)

    def _measures(self, reading: PhysicsReading) -> dict[str, float] | None:
        """The task's measures of a reading, or None where it has none."""
        spec, r = self.task_spec, reading
        values = spec.measures(SCALAR_XP, r.ee_pos, r.ee_quat, r.grip, self.task)
        return {key: float(value) for key, value in values.items()} or None

    def _scorers(self) -> tuple[Scorer, Scorer]:
        """The step rules of this env's task and arm as two functions of a
        :class:`~mjx_arm.envs.scalar.step.StepInput`, for a sane step and a diverged one
        (:func:`mjx_arm.envs.scalar.codegen.step_scorers`)."""
        n = self.arm.n_joints
        grip = np.zeros(10 if self.task_spec.gripper else 0)
        probe = PhysicsReading(np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(n),
                               np.zeros(n), np.zeros(3), np.zeros(6), grip)  # fmt: skip
        keys = tuple(self._measures(probe) or ())  # the names of the task's measures
        return step_scorers(self.task, n, self._band_lists, keys)

    def _evaluate(
        self, reading: PhysicsReading, diverged: bool = False, change: float = 0.0
    ) -> _Evaluation | None:
        """Observation, reward, termination and info of a reading, everything computed once.

        Advances the episode's success rule and motion memory, unless it returns None.

        Args:
            reading: the physics read-out after a control step.
            diverged: score ``reading`` (the last sane one) for a step whose physics diverged:
                no success, the ``nonfinite`` term set, ``info["diverged"]``, the episode ends.
            change: sum of the squared action change since the previous step.

        Returns:
            (obs, reward, terminated, info), or None when ``reading`` shows a diverged physics
            (and ``diverged`` is False): a NaN or infinite value, or a joint faster than its
            divergence limit (``TaskConfig.divergence_speed_factor``). Every quantity of the
            reading shows in the unclipped state (the quaternion through its norm, the joint
            angles through sin/cos) except the joint velocities, which show in the joint
            velocity term (a sum of magnitudes).
        """
        raw, state, d, force = self._measure(reading)
        if not (diverged or finite(raw)):
            return None
        qvel = reading.qvel.tolist()  # the rules take lists
        if not diverged and self._runaway(qvel):
            return None
        measures = self._measures(reading)
        values = () if measures is None else tuple(measures.values())
        step = StepInput(self._progress, self._distance, change, d, force,
                         reading.qpos.tolist(), qvel, values)  # fmt: skip
        out = self._scores[diverged](step)
        self._progress, self._distance = out.progress, d
        info = {
            "is_success": out.success,
            "distance": d,
            "contact_force_norm": force,
            "reward_terms": out.terms,  # Python floats: the rules ran on Python scalars
            "diverged": diverged,
            "nonfinite": diverged,  # the older name of ``diverged``
            "overforce": out.over_now,
        }
        if measures is not None:
            info.update(measures)
        return self._flat.observation(state), out.reward, out.done, info

    def _observation(self, state: list[float]) -> dict[str, np.ndarray]:
        """The observation dict of a clipped flat state: views of one new float32 array (the
        caller may keep it; the next step does not write into it)."""
        return self._flat.observation(state)

    def _runaway(self, qvel: list[float]) -> bool:
        """Non-finite or runaway joint velocities ``qvel`` (n floats): not every joint within
        its divergence limit (:func:`mjx_arm.task.reward.runaway` and the finite test in one
        comparison, NaN compares False; on six floats Python's comparisons cost a third of
        numpy's calls)."""
        return not all(map(operator.le, map(abs, qvel), self._speed_list))


_FLOAT32 = np.dtype(np.float32)
_SHIPPED_BOUNDS = (np.full(6, -1.0, np.float32), np.full(6, 1.0, np.float32))


def action_size(arm: ArmInfo, task: TaskConfig) -> int:
    """Entries of an action: one per arm joint, plus the gripper's for a gripper task."""
    return arm.n_joints + int(task.spec.gripper)


def gripper_speed(arm: ArmInfo, task: TaskConfig) -> float:
    """The driven finger's velocity (m/s) at a gripper action of 1, which closes it (negative
    where the finger closes towards its lower limit); 0 for tasks without one."""
    if not (task.spec.gripper and arm.gripper):
        return 0.0
    return arm.gripper.v_max * arm.gripper.closing_sign


class InvalidActionError(ValueError, TypeError):
    """An action that is not ``(n,)`` finite real numbers (both a ValueError and a TypeError)."""


def check_action(action, bounds: tuple[np.ndarray, np.ndarray] = _SHIPPED_BOUNDS) -> np.ndarray:
    """Validate an action: shape ``(n,)``, real (bool, int or float), finite; clip into [-1, 1];
    return float32. Every engine's env checks its actions here.

    Args:
        action: the action, ``(n,)``.
        bounds: ``(-1, 1)`` arrays of float32, ``(n,)`` each (default: 6 joints).

    Raises:
        InvalidActionError: not an array of real numbers (complex, strings, objects, ragged
            lists), wrong shape, or NaN / inf entries.
    """
    try:
        arr = np.asarray(action)
    except (ValueError, TypeError) as exc:
        raise InvalidActionError(f"action must be an array of real numbers: {exc}") from None
    if arr.dtype.kind not in "biuf":
        raise InvalidActionError(f"action must hold real numbers, got dtype {arr.dtype}")
    if arr.dtype is not _FLOAT32:  # float32 clips exactly as its float64 widening would
        arr = arr.astype(np.float64)
    low, high = bounds
    if arr.shape != low.shape:
        raise InvalidActionError(f"action must have shape {low.shape}, got {arr.shape}")
    # finite sum of squares <=> finite entries, barring overflow, which the exact test rules out
    if not (math.isfinite(arr.dot(arr)) or np.isfinite(arr).all()):
        raise InvalidActionError(f"action contains NaN or inf: {arr.tolist()}")
    return np.minimum(np.maximum(arr, low), high).astype(np.float32, copy=False)
