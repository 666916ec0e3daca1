"""The contract on MJX: pure ``reset(rng)`` / ``step(state, action)`` over a pytree State.

The env follows Brax's ``Env`` interface (``brax.envs.base.State``: pipeline_state, obs, reward,
done, metrics, info), so Brax PPO trains on it directly. Physics sits behind a small interface
(:class:`MjxPhysics`): ``init``, ``step`` and ``read``; everything else (observation, reward,
success, termination) comes from :mod:`mjx_arm.task`, the same code the CPU envs run.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
from brax.envs.base import Env, State
from flax import struct
from mujoco import mjx

from mjx_arm.envs.arm import ArmInfo, validated_arm_info
from mjx_arm.envs.model_io import SensorReader, arm_model
from mjx_arm.task import observation as obs_lib
from mjx_arm.task import reward as reward_lib
from mjx_arm.task import sampling
from mjx_arm.task.config import REWARD_TERMS, TaskConfig, touch_config
from mjx_arm.urdf.scene import TARGET_BODY


@struct.dataclass
class Reading:
    """What the contract reads from the physics, one env (add a leading batch axis under vmap).

    Attributes:
        ee_pos ``(3,)``, ee_quat ``(4,)`` (w, x, y, z), qpos ``(6,)``, qvel ``(6,)``,
        target_pos ``(3,)``, wrench ``(6,)`` (tared, ee frame, unclipped).
    """

    ee_pos: jax.Array
    ee_quat: jax.Array
    qpos: jax.Array
    qvel: jax.Array
    target_pos: jax.Array
    wrench: jax.Array


class MjxPhysics:
    """MJX physics of the task model: ``n_substeps`` ``mjx.step`` per control step.

    Args:
        mj_model: the compiled task model (arm + scene).
        arm: the arm facts (joint names, tool mass properties).
        task: the task configuration (substeps, target geometry).
    """

    def __init__(self, mj_model: mujoco.MjModel, arm: ArmInfo, task: TaskConfig) -> None:
        self.mj_model = mj_model
        self.model = mjx.put_model(mj_model)
        self.ids = SensorReader(mj_model, arm)
        self.task = task
        self.mocap = int(mj_model.body_mocapid[mj_model.body(TARGET_BODY).id])
        self.n_substeps = task.n_substeps

    def init(self, qpos: jax.Array, target_body: jax.Array) -> mjx.Data:
        """Data at rest at joint angles ``qpos (6,)`` with the target body at ``(3,)``."""
        data = mjx.make_data(self.model)
        data = data.replace(
            qpos=data.qpos.at[self.ids.qpos_adr].set(qpos),
            mocap_pos=data.mocap_pos.at[self.mocap].set(target_body),
        )
        return mjx.forward(self.model, data)

    def set_target(self, data: mjx.Data, target_body: jax.Array) -> mjx.Data:
        """Move the target body; takes effect in the next step's collision detection."""
        return data.replace(mocap_pos=data.mocap_pos.at[self.mocap].set(target_body))

    def step(self, data: mjx.Data, ctrl: jax.Array) -> mjx.Data:
        """One control step: hold ``ctrl (6,)`` for ``n_substeps`` physics steps."""
        data = data.replace(ctrl=data.ctrl.at[self.ids.actuators].set(ctrl))

        def substep(d: mjx.Data, _: Any) -> tuple[mjx.Data, None]:
            return mjx.step(self.model, d), None

        data, _ = jax.lax.scan(substep, data, None, length=self.n_substeps)
        # kinematics and sensors stay those of the last substep's forward pass (1/240 s before
        # the integrated qpos/qvel), as in the CPU env: no extra forward per control step
        return data

    def read(self, data: mjx.Data) -> Reading:
        """The contract's read-out of ``data``."""
        ids = self.ids
        return Reading(
            ee_pos=data.site_xpos[ids.ee_site],
            ee_quat=data.xquat[ids.ee_body],
            qpos=data.qpos[ids.qpos_adr],
            qvel=data.qvel[ids.dof_adr],
            target_pos=sampling.target_point(jnp, data.mocap_pos[self.mocap], self.task),
            wrench=ids.wrench(jnp, data.sensordata),
        )


class MjxArmEnv(Env):
    """A batched-ready arm task on MJX (one env; ``jax.vmap`` it or use Brax's wrappers).

    Args:
        task: the task configuration (default: Touch).
        urdf: the arm URDF (default: the shipped arm); validated before use.
        physics_factory: builds the physics from (mj_model, arm, task); default MJX.
        mj_model: a task model converted with other settings (benchmark sweeps); default: the
            task's model from :func:`mjx_arm.envs.model_io.arm_model`.
    """

    def __init__(
        self,
        task: TaskConfig | None = None,
        urdf: str | Path | None = None,
        physics_factory=MjxPhysics,
        mj_model: mujoco.MjModel | None = None,
    ) -> None:
        self.task = task or touch_config()
        self.arm = validated_arm_info(urdf, "mujoco")
        self.mj_model = mj_model if mj_model is not None else arm_model(self.arm.urdf, self.task)
        self.physics = physics_factory(self.mj_model, self.arm, self.task)
        self._v_scale = jnp.asarray(self.task.action_scale * self.arm.v_max, jnp.float32)
        self._limits = (jnp.asarray(self.arm.lower), jnp.asarray(self.arm.upper))

    @property
    def observation_size(self) -> int:
        """Size of the flat observation ``state``: 22."""
        return obs_lib.OBS_SIZE

    @property
    def action_size(self) -> int:
        """Six joint velocity commands in [-1, 1]."""
        return 6

    @property
    def backend(self) -> str:
        """Name of the physics backend."""
        return "mjx"

    def sample_episode(self, rng: jax.Array) -> tuple[jax.Array, jax.Array]:
        """Start joint angles ``(6,)`` and target body position ``(3,)`` from ``rng``."""
        u = jax.random.uniform(rng, (sampling.N_UNIFORMS,))
        return (
            sampling.initial_qpos(jnp, u[:6], self.task),
            sampling.target_body_pos(jnp, u[6:], self.task),
        )

    def reset(self, rng: jax.Array) -> State:
        """A new episode from ``rng`` (a single PRNG key)."""
        rng, key = jax.random.split(rng)
        qpos, target_body = self.sample_episode(key)
        data = self.physics.init(qpos, target_body)
        reading = self.physics.read(data)
        zero = jnp.zeros(())
        metrics = {f"reward/{name}": zero for name in REWARD_TERMS}
        metrics.update(self._measures(*self._distance_and_force(reading), zero))
        return State(
            pipeline_state=data,
            obs=self.observe(reading),
            reward=zero,
            done=zero,
            metrics=metrics,
            info={"rng": rng},
        )

    def step(self, state: State, action: jax.Array) -> State:
        """Apply ``action (6,)`` for one control step."""
        ctrl = jnp.clip(action, -1.0, 1.0) * self._v_scale
        data = self.physics.step(state.pipeline_state, ctrl)
        reading = self.physics.read(data)
        finite = _all_finite(reading)
        reading = jax.tree.map(lambda x: jnp.where(finite, x, jnp.zeros_like(x)), reading)
        obs = jnp.where(finite, self.observe(reading), state.obs)
        d, force = self._distance_and_force(reading)
        success = reward_lib.is_success(jnp, d, force, self.task) & finite
        terms = reward_lib.reward_terms(
            jnp, d, force, reading.qpos, reading.qvel, self._limits, success, ~finite, self.task
        )
        # strong float32 everywhere: a weak type would change the State's type and retrace
        terms = {
            k: jnp.where(finite | (k == "nonfinite"), v, 0.0).astype(jnp.float32)
            for k, v in terms.items()
        }
        reward = reward_lib.total_reward(terms, self.task).astype(jnp.float32)
        done = ~finite | (success & self.task.terminate_on_success)
        metrics = dict(state.metrics)  # keep keys wrappers added (EvalWrapper's "reward")
        metrics.update({f"reward/{name}": value for name, value in terms.items()})
        metrics.update(self._measures(d, force, success))
        return state.replace(
            pipeline_state=data,
            obs=obs,
            reward=reward,
            done=done.astype(jnp.float32),
            metrics=metrics,
        )

    def retarget(self, data: Any, rng: jax.Array) -> tuple[Any, jax.Array]:
        """The same start state with a new target from ``rng``: (data, obs ``(22,)``).

        Automatic resets use it: restarting from the first state of an env (as Brax does)
        keeps each env's start pose but draws a new target every episode, so a small batch
        still trains on many targets.
        """
        _, target_body = self.sample_episode(rng)
        data = self.physics.set_target(data, target_body)
        return data, self.observe(self.physics.read(data))

    def observe(self, reading: Reading) -> jax.Array:
        """The flat observation ``state (22,)`` of a reading."""
        return obs_lib.flat_obs(
            jnp,
            reading.ee_pos,
            reading.ee_quat,
            reading.qpos,
            reading.target_pos,
            reading.wrench,
            self.task.force_clip,
        )

    def _distance_and_force(self, reading: Reading) -> tuple[jax.Array, jax.Array]:
        d = reward_lib.target_distance(jnp, reading.ee_pos, reading.target_pos)
        clip = self.task.force_clip
        force = reward_lib.contact_force_norm(jnp, jnp.clip(reading.wrench, -clip, clip))
        return d, force

    @staticmethod
    def _measures(d: jax.Array, force: jax.Array, success: jax.Array) -> dict[str, jax.Array]:
        return {
            "distance": d.astype(jnp.float32),
            "contact_force": force.astype(jnp.float32),
            "success": jnp.asarray(success).astype(jnp.float32),
        }


def _all_finite(tree: Any) -> jax.Array:
    leaves = jax.tree.leaves(tree)
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in leaves]))
