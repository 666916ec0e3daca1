"""The contract on MJX: pure ``reset(rng)`` / ``step(state, action)`` over a pytree State.

The env follows Brax's ``Env`` interface (``brax.envs.base.State``: pipeline_state, obs, reward,
done, metrics, info), so Brax PPO trains on it directly. Physics sits behind a small interface
(:class:`~mjx_arm.envs.mjx_physics.MjxPhysics` on MJX's JAX or Warp implementation, or the C
MuJoCo backend): ``init``, ``step``, ``read``, ``where`` and ``overflow``; everything else
(observation, reward, success, termination) comes from :mod:`mjx_arm.task`, the same code the
CPU envs run. Domain randomisation (:mod:`mjx_arm.envs.randomization`) is applied here, per env
and episode, when configured.

``state.info`` per env: ``rng``; ``task`` (:class:`TaskMemory`: the success rule's progress, the
previous action and distance); ``episode`` (the episode's randomisation draw).

Divergence: a step whose physics reads NaN or infinite values, or a joint faster than
``TaskConfig.divergence_speed_factor`` times its URDF velocity limit, keeps the previous
observation, sets ``done`` and the ``nonfinite`` reward term, and ``metrics["diverged"]`` = 1.
The auto-reset wrappers (:mod:`mjx_arm.envs.wrappers`, the vector env) then replace that env's
physics state; the other envs of the batch step on unaffected.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
from brax.envs.base import Env, State
from flax import struct

from mjx_arm.arm.config import ArmConfig
from mjx_arm.arm.model_io import arm_model
from mjx_arm.arm.resolve import ArmTask, as_arm_task
from mjx_arm.engines import CONVERTER_ENGINE, BatchPhysics
from mjx_arm.envs.base import action_size, gripper_speed
from mjx_arm.envs.mjx_physics import MjxPhysics, Reading
from mjx_arm.envs.physics_config import PhysicsConfig
from mjx_arm.envs.randomization import (
    MAX_LATENCY,
    Episode,
    RandomizationConfig,
    delayed_action,
    ft_noise,
    joint_noise,
    push_action,
    sample_episode,
    step_dynamics,
)
from mjx_arm.task import observation as obs_lib
from mjx_arm.task import reward as reward_lib
from mjx_arm.task import rules, sampling
from mjx_arm.task.config import TaskConfig

__all__ = ["MjxArmEnv", "Reading", "TaskMemory"]


@struct.dataclass
class TaskMemory:
    """What the task remembers between control steps of one env.

    Attributes:
        progress: the success rule's progress (consecutive holds, strike seen).
        prev_action: the previous action, ``(n,)``.
        prev_distance: d at the previous step (m), ``()``.
        object_params: a gripper task's object mass (kg) and friction this episode, ``(2,)``;
            ``(0,)`` for other tasks.
        past_actions: the last :data:`~mjx_arm.envs.randomization.MAX_LATENCY` actions,
            newest first, ``(MAX_LATENCY, n)`` (what a delayed episode applies).
    """

    progress: reward_lib.Progress
    prev_action: jax.Array
    prev_distance: jax.Array
    object_params: jax.Array
    past_actions: jax.Array

    @staticmethod
    def start(
        distance: jax.Array, n_actions: int, obj: Any = None, scale: jax.Array | None = None
    ) -> TaskMemory:
        """The memory at the start of an episode at distance ``d`` (``n_actions`` entries),
        with the episode's object (:class:`mjx_arm.task.grip.ObjectStart`, or None) and the
        multipliers of its mass and friction ``scale (2,)`` (randomisation; default 1)."""
        params = jnp.zeros(0) if obj is None else jnp.stack([obj.mass, obj.friction])
        if obj is not None and scale is not None:
            params = params * scale
        past = jnp.zeros((MAX_LATENCY, n_actions))
        return TaskMemory(
            reward_lib.start_progress(jnp), jnp.zeros(n_actions), distance, params, past
        )


class MjxArmEnv(Env):
    """A batched-ready arm task on MJX (one env; ``jax.vmap`` it or use Brax's wrappers).

    Args:
        task: the task on its arm, resolved once (:class:`~mjx_arm.arm.resolve.ArmTask`), or
            a task configuration (default: Touch) resolved here with ``arm``
            (:func:`~mjx_arm.arm.resolve.resolve_task`: its empty home pose, workspace scale
            and episode length come from the arm).
        arm: with a task configuration, the arm (a URDF, an arm file or an ArmConfig;
            default: the shipped arm), its URDF validated before use; None with an ArmTask.
        physics_factory: builds the physics (a :class:`mjx_arm.engines.BatchPhysics`) from
            (mj_model, arm, task); default: MJX with ``physics`` and ``batch_size``.
        mj_model: a task model converted with other settings (benchmark sweeps); default: the
            task's model from :func:`mjx_arm.arm.model_io.arm_model`.
        physics: MJX implementation and buffers (default: ``impl="auto"``).
        batch_size: the largest batch stepped at once (sizes Warp's contact pool).
        randomization: domain randomisation (default: off).
        background_compile: MJX only; compile MuJoCo Warp's kernels on a background thread
            (:class:`~mjx_arm.envs.mjx_physics.MjxPhysics`).
    """

    def __init__(
        self,
        task: TaskConfig | ArmTask | None = None,
        arm: str | Path | ArmConfig | None = None,
        physics_factory=None,
        mj_model: mujoco.MjModel | None = None,
        physics: PhysicsConfig | None = None,
        batch_size: int = 1,
        randomization: RandomizationConfig | None = None,
        background_compile: bool = False,
    ) -> None:
        start = time.monotonic()
        self.arm_task = as_arm_task(task, arm, CONVERTER_ENGINE)
        self.arm, self.task = self.arm_task.arm, self.arm_task.task
        self.mj_model = mj_model if mj_model is not None else arm_model(self.arm, self.task)
        converted = time.monotonic()
        self.physics: BatchPhysics
        if physics_factory is None:
            self.physics = MjxPhysics(
                self.mj_model, self.arm, self.task, physics, batch_size, background_compile
            )
        else:
            self.physics = physics_factory(self.mj_model, self.arm, self.task)
        # seconds of the build: URDF -> MuJoCo model, then the physics (MJX model, buffers)
        self.build_seconds = {
            "model conversion": converted - start,
            "physics build": time.monotonic() - converted,
            **getattr(self.physics, "build_stages", {}),
        }
        self.randomization = randomization or RandomizationConfig()
        self.task_spec = self.task.spec
        self.joint_coding = self.arm.joint_coding(self.task)
        scale = self.task.joint_speeds(self.arm.v_max)
        if self.task_spec.gripper:  # the gripper's entry moves the finger at up to its speed limit
            scale = [*scale, gripper_speed(self.arm, self.task)]
        self._v_scale = jnp.asarray(scale, jnp.float32)
        limits = (jnp.asarray(self.arm.lower), jnp.asarray(self.arm.upper))
        self._band = reward_lib.joint_band(limits, self.task)
        self._speeds = jnp.asarray(reward_lib.speed_limits(self.arm.v_max, self.task), jnp.float32)

    @property
    def observation_size(self) -> int:
        """Size of the flat observation ``state``: 16 + n (22 for a 6-joint arm), plus the
        task's extra keys."""
        return obs_lib.obs_size(self.arm.n_joints, self.task_spec.extra_obs)

    @property
    def contact_force_dims(self) -> slice:
        """Where ``contact_force`` (6 entries) sits in the flat observation."""
        return obs_lib.obs_slices(self.arm.n_joints, self.task_spec.extra_obs)["contact_force"]

    @property
    def action_size(self) -> int:
        """One joint velocity command in [-1, 1] per arm joint (and one for the gripper)."""
        return action_size(self.arm, self.task)

    @property
    def backend(self) -> str:
        """Name of the physics backend."""
        return "mjx"

    def sample_episode(self, rng: jax.Array) -> tuple[jax.Array, jax.Array, Any]:
        """Start joint angles ``(n,)``, target body position ``(3,)`` and a gripper task's
        object (:class:`mjx_arm.task.grip.ObjectStart`, else None) from ``rng``."""
        n = self.arm.n_joints
        u = jax.random.uniform(rng, (sampling.n_uniforms(n, self.task),))
        return (
            sampling.initial_qpos(jnp, u[:n], self.task),
            sampling.target_body_pos(jnp, u[n:], self.task),
            self.task_spec.object_start(jnp, u[n:], self.task),
        )

    def reset(self, rng: jax.Array) -> State:
        """A new episode from ``rng`` (a single PRNG key)."""
        rng, key, key_rand = jax.random.split(rng, 3)
        episode = sample_episode(key_rand, self.randomization, self.arm.n_joints)
        return self._start(rng, key, episode)

    def start(self, rng: jax.Array, episode: Episode) -> State:
        """A new episode from ``rng`` under a given randomisation draw ``episode`` (one batch
        can hold episodes of different settings; the per-step draws need ``enabled``)."""
        return self._start(*jax.random.split(rng), episode)

    def _start(self, rng: jax.Array, key: jax.Array, episode: Episode) -> State:
        qpos, target_body, obj = self.sample_episode(key)
        data = self.physics.init(qpos, target_body + episode.box_offset, obj)
        reading = self.physics.read(data)
        d, force = self._distance_and_force(reading)
        zero = jnp.zeros(())
        metrics = {f"reward/{name}": zero for name in self.task.reward.term_names()}
        start = reward_lib.start_progress(jnp)
        metrics.update(self._measures(d, force, start, zero, zero, zero))
        metrics.update(self._task_metrics(self._task_measures(reading)))
        metrics["diverged"] = zero
        return State(
            pipeline_state=data,
            obs=self.observe(reading, episode),
            reward=zero,
            done=zero,
            metrics=metrics,
            info={
                "rng": rng,
                "task": TaskMemory.start(d, self.action_size, obj, episode.object_scale),
                "episode": episode,
            },
        )

    def step(self, state: State, action: jax.Array) -> State:
        """Apply ``action (n,)`` for one control step."""
        memory: TaskMemory = state.info["task"]
        episode: Episode = state.info["episode"]
        action = jnp.clip(action, -1.0, 1.0)
        applied = delayed_action(action, memory.past_actions, episode.latency)
        info = dict(state.info)
        keys = None  # (jitter, force-torque noise, joint noise)
        if self.randomization.enabled:
            info["rng"], *keys = jax.random.split(state.info["rng"], 4)
        dynamics = None if keys is None else step_dynamics(keys[0], episode)
        data = self.physics.step(
            state.pipeline_state, applied * self._v_scale, dynamics, memory.object_params
        )
        reading, sane = self._sane_reading(data)
        obs = jnp.where(sane, self._noisy_obs(reading, episode, keys), state.obs)
        d, force = self._distance_and_force(reading)
        change = reward_lib.action_change(jnp, action, memory.prev_action)
        measures = self._task_measures(reading)
        score = rules.score_step(
            jnp, self.task, memory.progress, memory.prev_distance, change, d, force,
            reading.qpos, reading.qvel, self._band, ~sane, measures,
        )  # fmt: skip
        prev_distance = jnp.where(sane, d, memory.prev_distance)
        past = push_action(action, memory.past_actions)
        info["task"] = TaskMemory(score.progress, action, prev_distance, memory.object_params, past)
        metrics = self._step_metrics(state.metrics, data, score, (d, force), measures, sane)
        return state.replace(
            pipeline_state=data,
            obs=obs,
            reward=score.reward.astype(jnp.float32),  # strong: a weak type would retrace
            done=score.done.astype(jnp.float32),
            metrics=metrics,
            info=info,
        )

    def _sane_reading(self, data: Any) -> tuple[Reading, jax.Array]:
        """``data``'s reading, zeroed where it is not sane, and the sane flag ``()``: finite,
        and no joint running away (else the physics diverged)."""
        reading = self.physics.read(data)
        sane = _all_finite(reading) & ~reward_lib.runaway(jnp, reading.qvel, self._speeds)
        return jax.tree.map(lambda x: jnp.where(sane, x, jnp.zeros_like(x)), reading), sane

    def _noisy_obs(self, reading: Reading, episode: Episode, keys: list | None) -> jax.Array:
        """The observation ``(16 + n + k,)`` of ``reading``, with force-torque and joint noise from
        ``keys`` (jitter, force-torque, joint; each ``(2,)``) where randomisation is on."""
        if keys is None:
            return self.observe(reading, episode, None, None)
        return self.observe(
            reading, episode, ft_noise(keys[1], episode), joint_noise(keys[2], episode)
        )

    def _step_metrics(
        self,
        metrics: dict[str, jax.Array],
        data: Any,
        score: Any,
        distance_force: tuple[jax.Array, jax.Array],
        measures: dict[str, jax.Array] | None,
        sane: jax.Array,
    ) -> dict[str, jax.Array]:
        """The step's metrics: ``metrics`` (keys wrappers added kept, e.g. EvalWrapper's
        "reward") with the reward terms as ``reward/<name>``, the measures, the task's own and
        ``diverged``; each ``()`` float32 (strong: a weak type would change the State's type
        and retrace)."""
        metrics = dict(metrics)
        metrics.update({f"reward/{k}": v.astype(jnp.float32) for k, v in score.terms.items()})
        d, force = distance_force
        overflow = self.physics.overflow(data)
        metrics.update(
            self._measures(d, force, score.progress, score.success, score.over, overflow)
        )
        metrics.update(self._task_metrics(measures))
        metrics["diverged"] = (~sane).astype(jnp.float32)
        return metrics

    def restart(self, data: Any, rng: jax.Array) -> tuple[Any, jax.Array, dict[str, Any]]:
        """The same start state with a new target (and randomisation) from ``rng``.

        Automatic resets use it: restarting from the first state of an env (as Brax does)
        keeps each env's start pose but draws a new target every episode, so a small batch
        still trains on many targets.

        Returns:
            (data, obs ``(16 + n,)``, the ``info`` entries of a new episode: task, episode).
        """
        key, key_rand = jax.random.split(rng)
        _, target_body, obj = self.sample_episode(key)
        episode = sample_episode(key_rand, self.randomization, self.arm.n_joints)
        data = self.physics.set_target(data, target_body + episode.box_offset, obj)
        reading = self.physics.read(data)
        d, _ = self._distance_and_force(reading)
        obs = self.observe(reading, episode)
        memory = TaskMemory.start(d, self.action_size, obj, episode.object_scale)
        return data, obs, {"task": memory, "episode": episode}

    def observe(
        self,
        reading: Reading,
        episode: Episode | None = None,
        noise: jax.Array | None = None,
        joint_noise: jax.Array | None = None,
    ) -> jax.Array:
        """The flat observation ``state (16 + n + k,)`` of a reading.

        Args:
            reading: the physics read-out.
            episode: the episode's randomisation: the observed target omits its box offset,
                the observed joint angles and wrench carry its biases.
            noise: added to the observed wrench, ``(6,)``.
            joint_noise: added to the observed joint angles, ``(n,)``.
        """
        target, wrench, qpos = reading.target_pos, reading.wrench, reading.qpos
        if episode is not None:
            target = target - episode.box_offset
            wrench = wrench + episode.ft_bias
            qpos = qpos + episode.joint_bias
        wrench = wrench if noise is None else wrench + noise
        qpos = qpos if joint_noise is None else qpos + joint_noise
        extra = None
        if self.task_spec.extra_obs:
            values = self.task_spec.grip_observation(
                jnp, reading.ee_pos, reading.ee_quat, reading.grip, self.task
            )
            extra = (self.task_spec.extra_obs, values)
        return obs_lib.flat_obs(
            jnp, reading.ee_pos, reading.ee_quat, qpos, target, wrench,
            self.task.force_clip, extra, self.joint_coding,
        )  # fmt: skip

    def _task_measures(self, reading: Reading) -> dict[str, jax.Array] | None:
        """The task's measures of a reading (:meth:`mjx_arm.task.spec.Task.measures`), or
        None where it has none."""
        spec, r = self.task_spec, reading
        return spec.measures(jnp, r.ee_pos, r.ee_quat, r.grip, self.task) or None

    def _task_metrics(self, measures: dict[str, jax.Array] | None) -> dict[str, jax.Array]:
        """The measures the task reports as float32 metrics, under their metric names
        (:attr:`~mjx_arm.task.spec.Task.metrics`; Lift: ``lift_height``, ``grasp``)."""
        if measures is None:
            return {}
        names = self.task_spec.metrics
        return {metric: measures[key].astype(jnp.float32) for key, metric in names.items()}

    def _distance_and_force(self, reading: Reading) -> tuple[jax.Array, jax.Array]:
        d = reward_lib.target_distance(jnp, reading.ee_pos, reading.target_pos)
        clip = self.task.force_clip
        force = reward_lib.contact_force_norm(jnp, jnp.clip(reading.wrench, -clip, clip))
        return d, force

    def _measures(self, d, force, progress, success, over, overflow) -> dict[str, jax.Array]:
        """Per-step measures beside the reward terms (Brax sums them over an eval episode).

        ``touching``: a contact reading of at least the band's lower end, anywhere;
        ``streak``: the success condition has held for 2+ control steps running (a press
        that stays in the band, where a tap shows as ``reward/contact`` without it);
        ``strike``: the reading is above the strike limit (ends a gentle Touch episode).
        """
        f32 = jnp.float32
        low = self.task.force_band[0]
        return {
            "distance": d.astype(f32),
            "contact_force": force.astype(f32),
            "success": jnp.asarray(success).astype(f32),
            "overforce": jnp.asarray(over).astype(f32),
            "physics_overflow": jnp.asarray(overflow).astype(f32),
            "touching": (force >= low).astype(f32),
            "streak": (progress.hold >= 2).astype(f32),
            "strike": (force > reward_lib.strike_limit(self.task)).astype(f32),
        }


def _all_finite(tree: Any) -> jax.Array:
    leaves = jax.tree.leaves(tree)
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in leaves]))
