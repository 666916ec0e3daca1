"""The physics of every engine behind one interface, for side-by-side runs on the same inputs.

An engine takes a batch of :class:`Inputs` (start poses, target bodies, one action per physics
step of ``sim_dt``, a multiplier of the joint damping) and returns a :class:`Trace` of what the
contract reads after every physics step. Reading every physics step, not every control step,
shows chatter at the substep rate; :meth:`Trace.every` gives the control-step reads.

- ``mujoco``: the CPU MuJoCo env's model, stepped by C MuJoCo (float64).
- ``mjx``: the same model on MJX (float32), JAX or Warp implementation, one jitted and vmapped
  scan over the batch.
- ``pybullet``: the PyBullet reference env, its URDF loaded directly.

The CPU engines run through the envs' physics hooks, so they step exactly what the Gymnasium
envs step.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import mujoco
import numpy as np

from mjx_arm import engines
from mjx_arm.arm.info import ArmInfo, arm_info
from mjx_arm.arm.model_io import arm_model
from mjx_arm.arm.resolve import ArmTask
from mjx_arm.bench.parity_config import ENGINES
from mjx_arm.envs.base import BaseRobotEnv, PhysicsReading
from mjx_arm.task.config import TaskConfig
from mjx_arm.urdf.convert import EE_SITE

if TYPE_CHECKING:
    from mjx_arm.envs.mujoco_env import MujocoArmEnv

# Target body used where the target does not matter (forward kinematics): on the table, clear
# of the arm.
FK_TARGET = (0.5, 0.0, 0.2)


@dataclass
class Inputs:
    """A batch of open-loop runs.

    Attributes:
        qpos0: start joint angles (rad), the arm at rest, ``(B, 6)``.
        targets: target body positions (m), ``(B, 3)``.
        actions: one action in [-1, 1] per physics step, ``(B, T, 6)``.
        damping: multiplier of the six joints' damping per run (1: as converted), ``(B,)``.
    """

    qpos0: np.ndarray
    targets: np.ndarray
    actions: np.ndarray
    damping: np.ndarray

    def __len__(self) -> int:
        return len(self.qpos0)

    @staticmethod
    def concat(parts: list[Inputs]) -> Inputs:
        """The runs of ``parts`` in one batch (all with the same ``T``)."""
        fields = [f.name for f in dataclasses.fields(Inputs)]
        return Inputs(*(np.concatenate([getattr(p, k) for p in parts]) for k in fields))


@dataclass
class Trace:
    """What the contract reads after every physics step of a batch of runs.

    Attributes:
        qpos, qvel: joint angles (rad) and velocities (rad/s), ``(B, T, 6)``.
        ee_pos: ee point (m), ``(B, T, 3)``.
        wrench: tared F/T reading (N, N m) in the ee frame, unclipped, ``(B, T, 6)``.
    """

    qpos: np.ndarray
    qvel: np.ndarray
    ee_pos: np.ndarray
    wrench: np.ndarray

    def _map(self, fn) -> Trace:
        return Trace(*(fn(getattr(self, f.name)) for f in dataclasses.fields(self)))

    def runs(self, index: slice | np.ndarray) -> Trace:
        """The runs ``index`` of the batch."""
        return self._map(lambda x: x[index])

    def every(self, n: int) -> Trace:
        """The reads after every ``n``-th physics step (``n`` = substeps: control steps)."""
        return self._map(lambda x: x[:, n - 1 :: n])

    def force(self) -> np.ndarray:
        """Norm of the tared force (N), ``(B, T)``."""
        return np.linalg.norm(self.wrench[..., :3], axis=-1)

    @staticmethod
    def from_readings(runs: list[list[PhysicsReading]]) -> Trace:
        """A trace from per-run lists of env readings."""

        def stack(name: str) -> np.ndarray:
            return np.array([[getattr(r, name) for r in run] for run in runs], np.float64)

        return Trace(*(stack(f.name) for f in dataclasses.fields(Trace)))


class Engine(Protocol):
    """What every engine offers (see the module docstring)."""

    name: str

    def fk(self, qpos: np.ndarray) -> np.ndarray:
        """ee point (m) at joint angles ``qpos (B, 6)``, ``(B, 3)``."""

    def rollout(self, inputs: Inputs) -> Trace:
        """Play ``inputs`` open loop; the reads after every physics step."""

    def close(self) -> None:
        """Free the engine's resources."""


class EnvEngine:
    """A CPU engine stepped through a Gymnasium env's physics hooks, one run after another.

    Args:
        env: the env (its task decides the scene and the time step).
    """

    def __init__(self, env: BaseRobotEnv) -> None:
        self.env, self.name = env, env.engine
        self.scale = env.task.joint_speeds(env.arm.v_max)

    def fk(self, qpos: np.ndarray) -> np.ndarray:
        """ee point (m) at joint angles ``qpos (B, 6)``, ``(B, 3)``."""
        out = []
        for q in qpos:
            self.env._physics_reset(q, np.asarray(FK_TARGET))
            out.append(self.env._physics_read().ee_pos)
        return np.array(out)

    def rollout(self, inputs: Inputs) -> Trace:
        """Play ``inputs`` open loop; the reads after every physics step."""
        runs = []
        try:
            for q, target, actions, damping in zip(
                inputs.qpos0, inputs.targets, inputs.actions, inputs.damping, strict=True
            ):
                self.scale_damping(float(damping))
                runs.append(self._run(q, target, actions))
        finally:
            self.scale_damping(1.0)
        return Trace.from_readings(runs)

    def _run(self, qpos0: np.ndarray, target: np.ndarray, actions: np.ndarray) -> list:
        env = self.env
        env._physics_reset(qpos0, target)
        reads = []
        for action in actions:
            env._physics_set_velocity_targets(np.clip(action, -1.0, 1.0) * self.scale)
            env._physics_step(1)
            reads.append(env._physics_read())
        return reads

    def scale_damping(self, factor: float) -> None:
        """Set the six joints' damping to ``factor`` times the converted model's."""
        raise NotImplementedError

    def close(self) -> None:
        """Close the env."""
        self.env.close()


class MujocoEngine(EnvEngine):
    """C MuJoCo through :class:`~mjx_arm.envs.mujoco_env.MujocoArmEnv`."""

    def __init__(self, env: MujocoArmEnv) -> None:
        super().__init__(env)
        self.model, self.dofs = env.model, env.ids.dof_adr
        self._damping = self.model.dof_damping[self.dofs].copy()
        self._scratch = mujoco.MjData(self.model)
        self._site = self.model.site(EE_SITE).id

    def scale_damping(self, factor: float) -> None:
        """Set the six joints' damping to ``factor`` times the converted model's."""
        self.model.dof_damping[self.dofs] = factor * self._damping

    def jacobian(self, qpos: np.ndarray) -> np.ndarray:
        """``(3, 6)`` position Jacobian of the ee site w.r.t. the six joints at ``qpos``."""
        data, model = self._scratch, self.model
        data.qpos[self.env.ids.qpos_adr] = qpos
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        jacp = np.zeros((3, model.nv))
        mujoco.mj_jacSite(model, data, jacp, None, self._site)
        return jacp[:, self.dofs]


class BulletEngine(EnvEngine):
    """PyBullet through :class:`pybullet_ref.PybulletArmEnv` (its servo carries the damping)."""

    def __init__(self, env: BaseRobotEnv) -> None:
        super().__init__(env)
        self._servo = env.servo

    def scale_damping(self, factor: float) -> None:
        """Set the six joints' damping to ``factor`` times the converted model's."""
        from pybullet_ref.drive import DriveGains

        damping = tuple(factor * d for d in self._servo.damping)
        self.env.servo = dataclasses.replace(self._servo, damping=damping)
        self.env._drive.gains = DriveGains.of_servo(self.env.servo)  # the drive's copy


class MjxEngine:
    """MJX (float32) on the task model: one jitted, vmapped scan of physics steps per batch.

    Compiled ahead of each call (minutes on a CPU for the Touch scene; JAX's persistent
    cache, where enabled, keeps the result); :attr:`compile_seconds` sums the compilation.

    Args:
        task: the task (scene and time step).
        impl: MJX implementation: "auto", "jax" or "warp".
        batch_size: the largest batch (sizes Warp's contact pool).
        arm: the arm (default: the shipped one).
    """

    def __init__(
        self, task: TaskConfig, impl: str = "auto", batch_size: int = 1, arm: ArmInfo | None = None
    ) -> None:
        import jax

        from mjx_arm.envs.mjx_physics import MjxPhysics
        from mjx_arm.envs.physics_config import PhysicsConfig

        arm = self.arm = arm or arm_info()
        one_step = task.replace(ctrl_dt=task.sim_dt)  # a control step of one physics step
        model = arm_model(arm, task)
        self.physics = MjxPhysics(model, arm, one_step, PhysicsConfig(impl=impl), batch_size)
        self.name = f"mjx-{self.physics.impl}"
        self.scale = np.asarray(task.joint_speeds(arm.v_max), np.float32)
        self._rollout = jax.jit(jax.vmap(self._run))
        self._fk = jax.jit(jax.vmap(self._ee))
        self.compile_seconds = 0.0

    def _ee(self, qpos):
        import jax.numpy as jnp

        data = self.physics.init(qpos, jnp.asarray(FK_TARGET, jnp.float32))
        return self.physics.read(data).ee_pos

    def _run(self, qpos0, target, actions, damping):
        import jax
        import jax.numpy as jnp

        from mjx_arm.envs.mjx_physics import Dynamics

        n = self.arm.n_joints
        dynamics = Dynamics.nominal(n).replace(damping=jnp.full(n, damping))

        def body(data, action):
            data = self.physics.step(data, jnp.clip(action, -1.0, 1.0) * self.scale, dynamics)
            r = self.physics.read(data)
            return data, (r.qpos, r.qvel, r.ee_pos, r.wrench)

        _, out = jax.lax.scan(body, self.physics.init(qpos0, target), actions)
        return out

    def fk(self, qpos: np.ndarray) -> np.ndarray:
        """ee point (m) at joint angles ``qpos (B, 6)`` by MJX's forward pass, ``(B, 3)``."""
        ee = self._call("forward kinematics", self._fk, np.asarray(qpos, np.float32))
        return np.asarray(ee, np.float64)

    def rollout(self, inputs: Inputs) -> Trace:
        """Play ``inputs`` open loop; the reads after every physics step."""
        fields = [f.name for f in dataclasses.fields(Inputs)]
        args = [np.asarray(getattr(inputs, k), np.float32) for k in fields]
        out = self._call(f"{len(args[0])} rollouts", self._rollout, *args)
        return Trace(*(np.asarray(x, np.float64) for x in out))

    def _call(self, what: str, fn, *args):
        """Compile ``fn`` for ``args`` (timed, its progress said on stderr: a
        :class:`~mjx_arm.jax_cache.CompileClock`), then run it."""
        import jax

        from mjx_arm.jax_cache import CompileClock

        slow = jax.default_backend() == "cpu"
        clock = CompileClock(f"{self.name}'s {what}", "MJX on a CPU: minutes" if slow else "")
        try:
            compiled = fn.lower(*args).compile()
        finally:
            self.compile_seconds += clock.stop()
        return compiled(*args)

    def close(self) -> None:
        """Nothing to free."""


def make_engine(
    name: str,
    task: TaskConfig,
    impl: str = "auto",
    batch_size: int = 1,
    arm: ArmInfo | None = None,
) -> Engine:
    """The engine ``name`` (see :data:`ENGINES`) on ``task``'s scene: its registry row's
    ``parity`` factory (:mod:`mjx_arm.engines`).

    Args:
        name: an engine with parity hooks: "mujoco", "mjx" or "pybullet".
        task: the task (scene and time step).
        impl: MJX implementation ("auto", "jax", "warp"); ignored by the CPU engines.
        batch_size: the largest batch (MJX on Warp sizes its contact pool with it).
        arm: the arm (default: the shipped one).
    """
    if name not in ENGINES:
        raise ValueError(f"engine must be one of {ENGINES}, got {name!r}")
    engines.check_installed(name)
    return engines.load(engines.engine(name).parity)(task, impl, batch_size, arm)


def mujoco_engine(task: TaskConfig, impl: str, batch_size: int, arm: ArmInfo | None) -> Engine:
    """The MuJoCo row's parity hook: CPU MuJoCo's env on ``task`` (``impl`` and ``batch_size``
    concern MJX only)."""
    from mjx_arm.envs.mujoco_env import MujocoArmEnv

    return MujocoEngine(MujocoArmEnv(_on_arm(task, arm)))


def bullet_engine(task: TaskConfig, impl: str, batch_size: int, arm: ArmInfo | None) -> Engine:
    """The PyBullet row's parity hook: the reference env on ``task`` (``impl`` and
    ``batch_size`` concern MJX only)."""
    from pybullet_ref import PybulletArmEnv

    return BulletEngine(PybulletArmEnv(_on_arm(task, arm)))


def _on_arm(task: TaskConfig, arm: ArmInfo | None) -> TaskConfig | ArmTask:
    """``task`` on ``arm`` as the caller resolved them (:func:`mjx_arm.arm.resolve.task_for_arm`
    filled the task in), for an env to take as they are; without an arm, the task alone (the
    env resolves it on the shipped arm)."""
    return ArmTask(arm, task) if arm is not None else task
