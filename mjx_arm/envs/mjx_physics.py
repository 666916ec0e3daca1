"""MJX physics of the task model, on MJX's JAX implementation or on MuJoCo Warp.

:class:`MjxPhysics` is what the batched env steps: ``init``, ``step``, ``read``, plus ``where``
(per-env select of two batched states) and ``overflow`` (per-env flag of a dropped contact or
constraint). The implementation is a setting (:class:`~mjx_arm.envs.physics_config.
PhysicsConfig`); everything above this layer is the same for both.

What differs under Warp, and how this layer handles it:

- Contacts live in one pool that all envs of a batch share (``naconmax`` contacts in all);
  constraint rows are per env (``njmax``). Both are sized here from the model's own bound (every
  collision pair it allows, with its largest contact count, and all joint limits), times the
  batch for the pool, unless the config sets them; so is the row count of the convex
  collider's scratch arrays (``naccdmax``, :mod:`mjx_arm.envs.warp_buffers`).
- Pool fields carry no batch axis, so batched states are merged field by field with Warp's own
  table of which fields are per env (:meth:`MjxPhysics.where`).
- Warp counts an overflow per env in a bitmask. Dropped contacts or constraint rows raise
  :class:`PhysicsOverflowError` where the batch is read on the host (trainer, vector env,
  benchmarks); the solver's iteration limits are not errors here (the model runs a fixed, small
  number of iterations on purpose), and Warp's own per-env warning prints are switched off.
"""

from __future__ import annotations

import time
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from flax import struct
from mujoco import mjx

from mjx_arm.arm.info import ArmInfo
from mjx_arm.arm.model_io import GripReader, SensorReader
from mjx_arm.envs import warp_compile
from mjx_arm.envs.physics_config import PhysicsConfig, resolve_impl
from mjx_arm.envs.warp_buffers import (
    DROPPED_BITS,
    model_bounds,
    overflow_message,
    warp_compatible,
)
from mjx_arm.task import sampling
from mjx_arm.task.config import TaskConfig
from mjx_arm.urdf.scene import TARGET_BODY


class PhysicsOverflowError(RuntimeError):
    """Warp dropped contacts or constraint rows: its buffers are too small for the batch."""


@struct.dataclass
class Reading:
    """What the contract reads from the physics, one env (add a leading batch axis under vmap).

    Attributes:
        ee_pos: ``(3,)``.
        ee_quat: ``(4,)`` (w, x, y, z).
        qpos: ``(n,)``.
        qvel: ``(n,)``.
        target_pos: ``(3,)``.
        wrench: ``(6,)`` (tared, ee frame, unclipped).
        grip: ``(10,)`` for a gripper task (:data:`mjx_arm.task.grip.GRIP_LAYOUT`), else
            ``(0,)``.
    """

    ee_pos: jax.Array
    ee_quat: jax.Array
    qpos: jax.Array
    qvel: jax.Array
    target_pos: jax.Array
    wrench: jax.Array
    grip: jax.Array


@struct.dataclass
class Dynamics:
    """Per-env changes of the model's dynamics (domain randomisation); :meth:`nominal` is the
    model.

    Attributes:
        friction: multiplier of every geom's friction coefficients, ``()``.
        damping: multiplier of the n arm joints' damping, ``(n,)``.
        armature: multiplier of the n joints' rotor inertia, ``(n,)``.
        gain: multiplier of the n velocity servos' gain, ``(n,)``.
        frictionloss: dry friction added to the n joints (N m), ``(n,)``.
        payload: mass added at the flange body's centre of mass (kg), ``()``; the gravity
            compensation of the servos does not hold its weight.
        table: height offset of the table (m), ``()``.
        timestep: multiplier of the physics step (control-period jitter), ``()``.
    """

    friction: jax.Array
    damping: jax.Array
    armature: jax.Array
    gain: jax.Array
    frictionloss: jax.Array
    payload: jax.Array
    table: jax.Array
    timestep: jax.Array

    @staticmethod
    def nominal(n_joints: int = 6) -> Dynamics:
        """The model as built, for an arm of ``n_joints``."""
        one, zero, n = jnp.ones(()), jnp.zeros(()), n_joints
        return Dynamics(one, jnp.ones(n), jnp.ones(n), jnp.ones(n), jnp.zeros(n), zero, zero, one)


def own_device() -> jax.Device:
    """This process's first device. MJX puts a model and data on ``jax.devices()[0]`` unless
    told: where several processes train (one per GPU), that is process 0's GPU, which the
    others cannot address."""
    return jax.local_devices()[0]


class MjxPhysics:
    """MJX physics of the task model: ``n_substeps`` ``mjx.step`` per control step.

    Args:
        mj_model: the compiled task model (arm + scene).
        arm: the arm facts (joint names, tool mass properties).
        task: the task configuration (substeps, target geometry).
        config: implementation and buffer sizes (default: ``impl="auto"``).
        batch_size: the largest batch stepped at once (sizes Warp's shared contact pool).
        background_compile: compile MuJoCo Warp's kernels on a background thread (the caller
            calls :meth:`wait_precompiled` before the first step runs); default: before the
            constructor returns.
    """

    def __init__(
        self,
        mj_model: mujoco.MjModel,
        arm: ArmInfo,
        task: TaskConfig,
        config: PhysicsConfig | None = None,
        batch_size: int = 1,
        background_compile: bool = False,
    ) -> None:
        self.mj_model = mj_model
        self.config = config or PhysicsConfig()
        self.impl = resolve_impl(self.config.impl)
        self.ids = SensorReader(mj_model, arm)
        self.task = task
        self.mocap = int(mj_model.body_mocapid[mj_model.body(TARGET_BODY).id])
        self.n_substeps = task.n_substeps
        self.batch_size = max(int(batch_size), 1)
        self.buffers: dict[str, int] = {}
        self.build_stages: dict[str, float] = {}  # seconds of the build's parts (Warp's)
        self.precompile_seconds = 0.0
        self._precompile: Any = None  # MuJoCo Warp's kernels compiling in the background
        self._background = background_compile
        if self.impl == "warp":
            self.model, self._template = self._warp_model_and_data()
        else:
            self.model = mjx.put_model(mj_model, own_device(), impl="jax")
            self._template = mjx.make_data(self.model, own_device(), impl="jax")
        self._joint_dofs = jnp.asarray(self.ids.dof_adr)
        self.grip = GripReader(mj_model, arm) if task.spec.gripper else None
        acts = list(self.ids.actuators) + ([self.grip.finger_act] if self.grip else [])
        self._arm_actuators = jnp.asarray(self.ids.actuators)
        self._actuators = jnp.asarray(acts)  # the arm's, then the gripper's for a gripper task

    def _warp_model_and_data(self) -> tuple[Any, Any]:
        bounds = model_bounds(self.mj_model)
        per_env = self.config.naconmax_per_env or bounds.contacts
        ccd_per_env = min(self.config.naccdmax_per_env or max(bounds.convex_pairs, 1), per_env)
        self.buffers = {
            "naconmax_per_env": per_env,
            "naconmax": per_env * self.batch_size,
            "njmax": self.config.njmax or bounds.rows,
            "naccdmax_per_env": ccd_per_env,
            "naccdmax": ccd_per_env * self.batch_size,
            "model_contacts": bounds.contacts,
            "model_rows": bounds.rows,
            "model_convex_pairs": bounds.convex_pairs,
        }
        mj_model = warp_compatible(self.mj_model)
        start = time.monotonic()
        model = mjx.put_model(mj_model, own_device(), impl="warp")
        put = time.monotonic()
        # Warp prints a warning per env and substep on any overflow; this layer reads the bits.
        opt_impl = model.opt._impl.replace(warn_overflow=0)
        model = model.replace(opt=model.opt.replace(_impl=opt_impl))
        naconmax, njmax = self.buffers["naconmax"], self.buffers["njmax"]
        data = mjx.make_data(
            mj_model,
            own_device(),
            impl="warp",
            naconmax=naconmax,
            njmax=njmax,
            naccdmax=self.buffers["naccdmax"],
        )
        made = time.monotonic()
        threads = self.config.compile_threads
        devices = warp_compile.cuda_devices() if threads else []
        if devices:
            loads = warp_compile.try_step_loads(mj_model, naconmax, njmax, devices[0])
            if self._background:
                self._precompile = warp_compile.start_precompile(threads, loads, devices)
            else:
                self.precompile_seconds = warp_compile.precompile(threads, loads, devices)
        self.build_stages = {
            "Warp model": put - start,
            "Warp data": made - put,
            "Warp step loads": time.monotonic() - made,
        }
        return model, data

    def wait_precompiled(self) -> dict[str, float]:
        """Wait for MuJoCo Warp's kernel compiles started in the background (if any).

        Returns:
            ``warp_kernels``: seconds the compiles took, ``warp_kernels_wait``: seconds this
            call waited for them; only ``warp_kernels`` where they ran in the constructor.
        """
        if self._precompile is None:
            return {"warp_kernels": self.precompile_seconds} if self.precompile_seconds else {}
        start = time.monotonic()
        self.precompile_seconds = self._precompile.result()
        self._precompile = None
        waited = time.monotonic() - start
        return {"warp_kernels": self.precompile_seconds, "warp_kernels_wait": waited}

    def describe(self) -> dict[str, Any]:
        """Implementation and buffer sizes, for run configs and benchmark JSON."""
        return {"impl": self.impl, "batch_size": self.batch_size, **self.buffers}

    # ------------------------------------------------------------------ state

    def init(self, qpos: jax.Array, target_body: jax.Array, obj: Any = None) -> Any:
        """Data at rest at joint angles ``qpos (n,)`` with the target body at ``(3,)`` (and a
        gripper task's cube there, oriented as ``obj`` says: an ObjectStart)."""
        data = self._template
        data = data.replace(
            qpos=data.qpos.at[self.ids.qpos_adr].set(qpos),
            mocap_pos=data.mocap_pos.at[self.mocap].set(target_body),
        )
        data = self._place_object(data, target_body, obj)
        return mjx.forward(self.model, data)

    def set_target(self, data: Any, target_body: jax.Array, obj: Any = None) -> Any:
        """Move the target body (and a gripper task's cube, at rest); takes effect in the next
        step's collision detection."""
        data = data.replace(mocap_pos=data.mocap_pos.at[self.mocap].set(target_body))
        return self._place_object(data, target_body, obj)

    def _place_object(self, data: Any, pos: jax.Array, obj: Any) -> Any:
        """A gripper task's cube at ``pos (3,)`` with ``obj``'s orientation, at rest, and the
        fingers open."""
        if self.grip is None or obj is None:
            return data
        quat = obj.quat
        start, dof = self.grip.cube_qpos, self.grip.cube_dof
        qpos = data.qpos.at[start : start + 3].set(pos).at[start + 3 : start + 7].set(quat)
        return data.replace(qpos=self.grip.open(qpos), qvel=data.qvel.at[dof : dof + 6].set(0.0))

    def step(
        self, data: Any, ctrl: jax.Array, dynamics: Dynamics | None = None, object_params=None
    ) -> Any:
        """One control step: hold ``ctrl`` for ``n_substeps`` physics steps.

        Args:
            data: one env's state (vmap for a batch).
            ctrl: joint velocity targets (rad/s), ``(n,)``, then for a gripper task the
                finger's (m/s).
            dynamics: per-env multipliers of friction, damping, armature and servo gain;
                None steps the model as built.
            object_params: a gripper task's cube mass (kg) and friction, ``(2,)``, else None.
        """
        model = self.model if dynamics is None else self.randomized(dynamics)
        if self.grip is not None and object_params is not None:
            model = self.grip.dress(model, object_params[0], object_params[1])
        data = data.replace(ctrl=data.ctrl.at[self._actuators].set(ctrl))
        if dynamics is not None and self.impl == "warp":
            data = self._place_table(data, dynamics.table)

        def substep(d: Any, _: Any) -> tuple[Any, None]:
            return mjx.step(model, d), None

        data, _ = jax.lax.scan(substep, data, None, length=self.n_substeps)
        # kinematics and sensors stay those of the last substep's forward pass (1/240 s before
        # the integrated qpos/qvel), as in the CPU env: no extra forward per control step
        return data

    def _place_table(self, data: Any, offset: jax.Array) -> Any:
        """The table's geoms ``offset`` (m) up from where the model puts them, in the data.

        MuJoCo Warp computes the world positions of the world body's geoms once and does not
        read a changed ``geom_pos`` for them, so :meth:`randomized`'s table height reaches its
        collisions only through here (the table is a geom of the world body: its world
        position is its ``geom_pos``).
        """
        ids = self.ids.table_geoms
        if not len(ids):
            return data
        z = jnp.asarray(self.mj_model.geom_pos[ids, 2], jnp.float32) + offset
        return data.replace(geom_xpos=data.geom_xpos.at[ids, 2].set(z))

    def randomized(self, dyn: Dynamics) -> Any:
        """The model with ``dyn``'s changes applied (one env; batched under vmap)."""
        m, dofs, act, ids = self.model, self._joint_dofs, self._arm_actuators, self.ids
        gain = m.actuator_gainprm.at[act, 0].multiply(dyn.gain)
        bias = m.actuator_biasprm.at[act, 2].multiply(dyn.gain)  # velocity servo: -kv * qdot
        table_z = m.geom_pos.at[ids.table_geoms, 2].add(dyn.table)
        # the payload's weight is not in the servo's gravity compensation (a payload the
        # controller was not told of): the flange's compensated mass stays its own
        flange = ids.flange_body
        mass0 = m.body_mass[flange]
        return m.replace(
            geom_friction=m.geom_friction * dyn.friction,
            dof_damping=m.dof_damping.at[dofs].multiply(dyn.damping),
            dof_armature=m.dof_armature.at[dofs].multiply(dyn.armature),
            dof_frictionloss=m.dof_frictionloss.at[dofs].add(dyn.frictionloss),
            body_mass=m.body_mass.at[flange].add(dyn.payload),
            body_gravcomp=m.body_gravcomp.at[flange].multiply(mass0 / (mass0 + dyn.payload)),
            geom_pos=table_z,
            actuator_gainprm=gain,
            actuator_biasprm=bias,
            opt=m.opt.replace(timestep=m.opt.timestep * dyn.timestep),
        )

    def read(self, data: Any) -> Reading:
        """The contract's read-out of ``data``."""
        ids = self.ids
        target = sampling.target_point(jnp, data.mocap_pos[self.mocap], self.task)
        grip = jnp.zeros(0)
        if self.grip is not None:  # the target is the cube, wherever it is now
            grip = self.grip.read(jnp, data.qpos, data.sensordata)
            target = grip[1:4]
        return Reading(
            ee_pos=data.site_xpos[ids.ee_site],
            ee_quat=data.xquat[ids.ee_body],
            qpos=data.qpos[ids.qpos_adr],
            qvel=data.qvel[ids.dof_adr],
            target_pos=target,
            wrench=ids.wrench(jnp, data.sensordata),
            grip=grip,
        )

    # ------------------------------------------------------------------ batches

    def overflow(self, data: Any) -> jax.Array:
        """True where Warp dropped contacts or constraint rows (one env; vmap for a batch)."""
        if self.impl != "warp":
            return jnp.zeros((), bool)
        return (data._impl.overflow & DROPPED_BITS) != 0

    def where(self, done: jax.Array, new: Any, old: Any) -> Any:
        """Per env: ``new`` where ``done (B,)`` else ``old``, for batched states.

        Under Warp the contact pool has no batch axis and belongs to the stepped state: it is
        kept from ``old``.
        """
        if self.impl != "warp":
            return batched_where(done, new, old)
        from mujoco.mjx._src.types import tree_path_to_attr_str
        from mujoco.mjx.warp import types as warp_types

        per_env = warp_types._BATCH_DIM["Data"]

        def pick(path: Any, n: jax.Array, o: jax.Array) -> jax.Array:
            if not per_env.get(tree_path_to_attr_str(path), True):
                return o
            return _where_rows(done, n, o)

        return jax.tree_util.tree_map_with_path(pick, new, old)

    def splits(self, path: tuple) -> bool:
        """Whether the state leaf at ``path`` is cut into per-device slices by a device split.

        Every leaf of a batched state has the batch axis first, except MuJoCo Warp's shared
        buffers: its contact pool is cut too (each device keeps the pool of its own envs), its
        counters and index tables are whole on every device.
        """
        if self.impl != "warp":
            return True
        names = [getattr(key, "name", None) for key in path]
        if "_impl" not in names or names.index("_impl") + 1 >= len(names):
            return True
        field = names[names.index("_impl") + 1]
        from mujoco.mjx.warp import types as warp_types

        per_env = warp_types._BATCH_DIM["Data"]
        return field.startswith("contact__") or per_env.get(field, True)

    def check_overflow(self, flags: Any) -> None:
        """Raise :class:`PhysicsOverflowError` if any env of ``flags`` (host array) overflowed."""
        flags = np.asarray(flags)
        if flags.any():
            raise PhysicsOverflowError(overflow_message(int(flags.sum()), self.describe()))


def _where_rows(done: jax.Array, new: jax.Array, old: jax.Array) -> jax.Array:
    mask = jnp.reshape(done > 0, done.shape + (1,) * (old.ndim - done.ndim))
    return jnp.where(mask, new, old)


def batched_where(done: jax.Array, new: Any, old: Any) -> Any:
    """Per env: ``new`` where ``done (B,)`` else ``old`` (pytrees with a leading batch axis)."""
    return jax.tree.map(lambda n, o: _where_rows(done, n, o), new, old)
