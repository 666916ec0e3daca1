"""C MuJoCo physics for the batched env: multithreaded rollouts behind a JAX host callback.

On a CPU, MJX (the JAX implementation) steps this arm about 100x slower than C MuJoCo and takes
minutes to compile a training step. :class:`MujocoCallbackPhysics` has the same interface as
:class:`mjx_arm.envs.mjx_env.MjxPhysics`, but a control step of the whole batch is one
``jax.pure_callback`` into ``mujoco.rollout`` (``nthread`` = CPU cores). Everything around it
(observation, reward, success, auto-reset, Brax PPO) is the same JAX code as on MJX.

State precision: between control steps the physics state (time, qpos, qvel) and the target
position live in JAX arrays of the default dtype, float32 unless ``jax_enable_x64`` is set; the
rollout itself runs in float64. Joint angles therefore carry a rounding of about 1e-7 rad per
control step compared with a float64 CPU env. The solver's warm start is not carried between
control steps (each control step starts it cold).

Gripper tasks (Lift) step here too: the state carries the cube's free joint and the fingers, and
each episode's cube mass and friction are a per-row model change like the randomised dynamics.
"""

from __future__ import annotations

import copy
import os
import threading

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from flax import struct
from mujoco import rollout as mj_rollout

from mjx_arm.arm.info import ArmInfo
from mjx_arm.arm.model_io import GripReader, SensorReader
from mjx_arm.envs.mjx_physics import Dynamics, Reading, batched_where
from mjx_arm.inputs import ConfigError
from mjx_arm.task import sampling
from mjx_arm.task.config import TaskConfig
from mjx_arm.urdf.scene import TARGET_BODY

STATE_SPEC = mujoco.mjtState.mjSTATE_FULLPHYSICS
CONTROL_SPEC = mujoco.mjtState.mjSTATE_CTRL | mujoco.mjtState.mjSTATE_MOCAP_POS


@struct.dataclass
class CState:
    """Physics state of one env for the C backend.

    Attributes:
        state: MuJoCo full physics state (time, qpos, qvel), ``(nstate,)``.
        mocap_pos: target body position (m), ``(3,)``.
        sensordata: sensors at ``state`` (as after ``mj_forward``), ``(nsensordata,)``.
    """

    state: jax.Array
    mocap_pos: jax.Array
    sensordata: jax.Array


def dynamics_row(dyn: Dynamics, object_params: jax.Array | None = None) -> jax.Array:
    """The changes as one row ``(5 + 4n [+ 2],)``: friction, damping (n), armature (n), gain
    (n), frictionloss (n), payload, table, timestep, then a gripper task's cube mass and
    friction."""
    scalars = [jnp.reshape(x, (1,)) for x in (dyn.payload, dyn.table, dyn.timestep)]
    parts = [jnp.reshape(dyn.friction, (1,)), dyn.damping, dyn.armature, dyn.gain]
    parts += [dyn.frictionloss, *scalars]
    if object_params is not None and object_params.shape[-1] > 0:
        parts.append(object_params)
    return jnp.concatenate(parts)


class _ModelCopies:
    """One model per batch row, with the changes of :func:`dynamics_row` applied."""

    def __init__(
        self, model: mujoco.MjModel, ids: SensorReader, grip: GripReader | None = None
    ) -> None:
        self.base, self.dofs, self.act, self.ids, self.grip = (
            model, ids.dof_adr, ids.actuators, ids, grip
        )  # fmt: skip
        self.models: list[mujoco.MjModel] = []
        self.width = 4 + 4 * len(self.dofs) + (2 if grip else 0)
        self.applied = np.zeros((0, self.width))

    def __call__(self, rows: np.ndarray) -> list[mujoco.MjModel]:
        """The models of ``rows (B, 1 + 3n)``, each updated where its row changed."""
        while len(self.models) < len(rows):
            self.models.append(copy.copy(self.base))
            self.applied = np.concatenate([self.applied, np.full((1, self.width), np.nan)])
        changed = np.flatnonzero((self.applied[: len(rows)] != rows).any(axis=1))
        for i in changed:
            self._apply(self.models[i], rows[i])
            self.applied[i] = rows[i]
        return self.models[: len(rows)]

    def _apply(self, m: mujoco.MjModel, row: np.ndarray) -> None:
        base, dofs, act = self.base, self.dofs, self.act
        n, ids = len(dofs), self.ids
        damping, armature, gain, frictionloss = (row[1 + k * n : 1 + (k + 1) * n] for k in range(4))
        payload, table, timestep = row[1 + 4 * n : 4 + 4 * n]
        m.geom_friction[:] = base.geom_friction * row[0]
        m.dof_damping[dofs] = base.dof_damping[dofs] * damping
        m.dof_armature[dofs] = base.dof_armature[dofs] * armature
        m.dof_frictionloss[dofs] = base.dof_frictionloss[dofs] + frictionloss
        m.actuator_gainprm[act, 0] = base.actuator_gainprm[act, 0] * gain
        m.actuator_biasprm[act, 2] = base.actuator_biasprm[act, 2] * gain
        flange, mass0 = ids.flange_body, base.body_mass[ids.flange_body]
        m.body_mass[flange] = mass0 + payload
        m.body_gravcomp[flange] = base.body_gravcomp[flange] * mass0 / (mass0 + payload)
        m.geom_pos[ids.table_geoms, 2] = base.geom_pos[ids.table_geoms, 2] + table
        m.opt.timestep = base.opt.timestep * timestep
        if self.grip is not None:
            self.grip.dress(m, row[4 + 4 * n], row[5 + 4 * n])


def new_data(model: mujoco.MjModel) -> mujoco.MjData:
    """``mujoco.MjData(model)``, its allocation failure a named error.

    Raises:
        ConfigError: MuJoCo could not allocate the data (the process is out of memory or of
            address space).
    """
    try:
        return mujoco.MjData(model)
    except mujoco.FatalError as err:
        raise ConfigError(
            f"MuJoCo could not allocate its data ({err}; the model asks for "
            f"{model.narena / 2**20:.0f} MiB of arena per copy): free memory, lower num_envs "
            "or the threads (nthread), or raise the process's memory limit"
        ) from err


class _Stepper:
    """Host side: a thread pool of MjData stepping batches with ``mujoco.rollout``."""

    def __init__(self, model: mujoco.MjModel, nthread: int, copies: _ModelCopies) -> None:
        self.model = model
        self.nthread = nthread
        self.datas = [new_data(model) for _ in range(nthread)]
        self.rollout = mj_rollout.Rollout(nthread=nthread)
        self.copies = copies
        self.lock = threading.Lock()

    def __call__(
        self,
        state: np.ndarray,
        ctrl: np.ndarray,
        mocap: np.ndarray,
        nstep: int,
        dynamics: np.ndarray | None = None,
    ):
        """Advance each row of ``state`` by ``nstep`` steps; return (state, sensordata).

        Args:
            state: ``(..., nstate)``; ctrl: ``(..., nu)``; mocap: ``(..., 3)``.
            nstep: physics steps to take; the sensors returned are those at the final state.
            dynamics: per-row multipliers ``(..., 1 + 3n)`` (:func:`dynamics_row`), or None for
                the nominal model.
        """
        lead = state.shape[:-1]
        state2 = np.ascontiguousarray(state.reshape(-1, state.shape[-1]), dtype=np.float64)
        control = np.concatenate([ctrl.reshape(-1, ctrl.shape[-1]), mocap.reshape(-1, 3)], -1)
        control = np.ascontiguousarray(control[:, None, :], dtype=np.float64)
        # The sensors of step k are computed by mj_step's forward pass at the state before
        # step k, so the last step's sensors lag the returned state by one substep, exactly as
        # the CPU env reads them. nstep == 0 runs one step only for its sensors (at ``state``).
        with self.lock:
            model = self.model
            if dynamics is not None:
                model = self.copies(np.asarray(dynamics, np.float64).reshape(-1, self.copies.width))
            states, sensors = self.rollout.rollout(
                model,
                self.datas,
                state2,
                control,
                control_spec=int(CONTROL_SPEC),
                nstep=max(nstep, 1),
            )
        new_state = states[:, nstep - 1] if nstep > 0 else state2
        return (
            new_state.reshape(*lead, -1).astype(np.float32),
            sensors[:, max(nstep, 1) - 1].reshape(*lead, -1).astype(np.float32),
        )


class MujocoCallbackPhysics:
    """Batched C MuJoCo physics with the interface of ``MjxPhysics``.

    Args:
        mj_model: the compiled task model.
        arm: the arm facts.
        task: the task configuration.
        nthread: rollout threads (default: the CPU count).
    """

    def __init__(
        self, mj_model: mujoco.MjModel, arm: ArmInfo, task: TaskConfig, nthread: int | None = None
    ) -> None:
        self.mj_model = mj_model
        self.ids = SensorReader(mj_model, arm)
        self.grip = GripReader(mj_model, arm) if task.spec.gripper else None
        acts = list(self.ids.actuators) + ([self.grip.finger_act] if self.grip else [])
        self._actuators = np.asarray(acts)  # the arm's, then the gripper's
        self.task = task
        self.n_substeps = task.n_substeps
        self.mocap = int(mj_model.body_mocapid[mj_model.body(TARGET_BODY).id])
        copies = _ModelCopies(mj_model, self.ids, self.grip)
        self.stepper = _Stepper(mj_model, nthread or os.cpu_count() or 1, copies)
        self.impl = "c"
        data = new_data(mj_model)
        template = np.zeros(mujoco.mj_stateSize(mj_model, STATE_SPEC))
        mujoco.mj_getState(mj_model, data, template, STATE_SPEC)
        self._template = template
        self._qpos_slice = slice(1, 1 + mj_model.nq)  # state = [time, qpos, qvel]
        self._qvel_slice = slice(1 + mj_model.nq, 1 + mj_model.nq + mj_model.nv)
        self._nsensor = mj_model.nsensordata

    def _call(self, state: jax.Array, ctrl: jax.Array, mocap: jax.Array, nstep: int, dyn=None):
        shapes = (
            jax.ShapeDtypeStruct(state.shape, jnp.float32),
            jax.ShapeDtypeStruct((*state.shape[:-1], self._nsensor), jnp.float32),
        )
        args = (state, ctrl, mocap) if dyn is None else (state, ctrl, mocap, dyn)

        def host(s, c, m, d=None):
            d = None if d is None else np.asarray(d)
            return self.stepper(np.asarray(s), np.asarray(c), np.asarray(m), nstep, d)

        return jax.pure_callback(host, shapes, *args, vmap_method="broadcast_all")

    def init(self, qpos: jax.Array, target_body: jax.Array, obj=None) -> CState:
        """State at rest at ``qpos (n,)`` with the target body at ``(3,)`` (and a gripper task's
        cube there, oriented as ``obj`` says, fingers open); sensors filled."""
        state = jnp.asarray(self._template, jnp.float32)
        state = state.at[self._qpos_slice.start + self.ids.qpos_adr].set(qpos)
        state = self._place_object(state, target_body, obj)
        ctrl = jnp.zeros(self.mj_model.nu, jnp.float32)
        _, sensors = self._call(state, ctrl, target_body.astype(jnp.float32), 0)
        return CState(state=state, mocap_pos=target_body.astype(jnp.float32), sensordata=sensors)

    def set_target(self, data: CState, target_body: jax.Array, obj=None) -> CState:
        """Move the target body (and a gripper task's cube, at rest; its sensors update at the
        next step)."""
        state = self._place_object(data.state, target_body, obj)
        return data.replace(state=state, mocap_pos=target_body.astype(jnp.float32))

    def _place_object(self, state: jax.Array, pos: jax.Array, obj) -> jax.Array:
        """``state`` with a gripper task's cube at ``pos (3,)`` in ``obj``'s orientation, at
        rest, and the fingers open."""
        if self.grip is None or obj is None:
            return state
        grip, q0, v0 = self.grip, self._qpos_slice.start, self._qvel_slice.start
        start, dof = q0 + grip.cube_qpos, v0 + grip.cube_dof
        state = state.at[start : start + 3].set(pos).at[start + 3 : start + 7].set(obj.quat)
        state = state.at[q0 + grip.fingers_qpos].set(grip.open_qpos)
        return state.at[dof : dof + 6].set(0.0)

    def step(
        self, data: CState, ctrl: jax.Array, dynamics: Dynamics | None = None, object_params=None
    ) -> CState:
        """One control step of ``n_substeps`` physics steps with ``ctrl (n,)``.

        ``dynamics``: per-env changes (domain randomisation), or None for the model.
        ``object_params``: a gripper task's cube mass (kg) and friction, ``(2,)``, else None.
        """
        full = jnp.zeros(self.mj_model.nu, jnp.float32).at[self._actuators].set(ctrl)
        gripper = self.grip is not None and object_params is not None
        dyn = None
        if dynamics is not None or gripper:
            dynamics = dynamics if dynamics is not None else Dynamics.nominal(len(self.ids.dof_adr))
            dyn = dynamics_row(dynamics, object_params if gripper else None).astype(jnp.float32)
        state, sensors = self._call(data.state, full, data.mocap_pos, self.n_substeps, dyn)
        return data.replace(state=state, sensordata=sensors)

    def overflow(self, data: CState) -> jax.Array:
        """Always False: C MuJoCo grows its buffers as needed."""
        return jnp.zeros((), bool)

    def check_overflow(self, flags: object) -> None:
        """Nothing to check: C MuJoCo never drops contacts (``flags`` are all False)."""

    def splits(self, path: tuple) -> bool:
        """Every leaf of a batched C-backend state has the batch axis first."""
        return True

    def where(self, done: jax.Array, new: CState, old: CState) -> CState:
        """Per env: ``new`` where ``done (B,)`` else ``old``."""
        return batched_where(done, new, old)

    def wait_precompiled(self) -> dict[str, float]:
        """Nothing compiles ahead here (the physics is C MuJoCo): ``{}``."""
        return {}

    def describe(self) -> dict:
        """Implementation facts, for run configs and benchmark JSON."""
        return {"impl": self.impl, "nthread": self.stepper.nthread}

    def read(self, data: CState) -> Reading:
        """The contract's read-out (see :class:`mjx_arm.envs.mjx_physics.Reading`)."""
        ids, s = self.ids, data.sensordata
        qpos_all = data.state[self._qpos_slice]
        target = sampling.target_point(jnp, data.mocap_pos, self.task)
        grip = jnp.zeros(0)
        if self.grip is not None:  # the target is the cube, wherever it is now
            grip = self.grip.read(jnp, qpos_all, s)
            target = grip[1:4]
        return Reading(
            ee_pos=s[ids.sensor_slices["ee_pos"]],
            ee_quat=s[ids.sensor_slices["ee_quat"]],
            qpos=qpos_all[ids.qpos_adr],
            qvel=data.state[self._qvel_slice][ids.dof_adr],
            target_pos=target,
            wrench=ids.wrench(jnp, s),
            grip=grip,
        )
