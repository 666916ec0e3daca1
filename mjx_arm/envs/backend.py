"""Which physics steps the batched JAX env (MJX, JAX or Warp, or C MuJoCo behind a host callback),
and the host memory a batch of it needs, estimated before the batch is allocated."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import jax
import numpy as np

from mjx_arm.envs.physics_config import PhysicsConfig
from mjx_arm.inputs import ConfigError
from mjx_arm.names import BACKENDS
from mjx_arm.task.config import TaskConfig

if TYPE_CHECKING:
    from mjx_arm.arm.resolve import ArmTask


def resolve_backend(name: str) -> str:
    """``auto`` -> ``mjx`` when an accelerator is present, else ``mujoco`` (C MuJoCo)."""
    if name not in BACKENDS:
        raise ValueError(f"unknown backend {name!r}; choose one of {BACKENDS}")
    if name != "auto":
        return name
    return "mjx" if jax.default_backend() in ("gpu", "cuda", "rocm", "tpu") else "mujoco"


def make_batched_env(
    task: TaskConfig | ArmTask,
    backend: str = "auto",
    physics: PhysicsConfig | None = None,
    batch_size: int = 1,
    randomization=None,
    arm=None,
    background_compile: bool = False,
):
    """The single-env JAX env (``MjxArmEnv``) with the physics of ``backend``.

    Args:
        task: the task on its arm (:class:`~mjx_arm.arm.resolve.ArmTask`), or a task
            configuration resolved with ``arm``.
        backend: "auto", "mjx" or "mujoco" (C MuJoCo through a host callback).
        physics: the MJX implementation and buffers (``mjx`` only; default ``impl="auto"``).
        batch_size: the largest batch stepped at once (sizes Warp's shared contact pool).
        randomization: domain randomisation
            (:class:`mjx_arm.envs.randomization.RandomizationConfig`; default off).
        arm: with a task configuration, the arm (a URDF, an arm file or an ArmConfig; default:
            the shipped arm); None with an ArmTask.
        background_compile: compile MuJoCo Warp's kernels on a background thread; the caller
            waits with ``env.physics.wait_precompiled()`` before the first step runs.
    """
    from mjx_arm.envs.mjx_env import MjxArmEnv

    if resolve_backend(backend) == "mujoco":
        from mjx_arm.envs.mujoco_batch import MujocoCallbackPhysics

        return MjxArmEnv(
            task, arm, physics_factory=MujocoCallbackPhysics, randomization=randomization
        )
    return MjxArmEnv(
        task,
        arm,
        physics=physics,
        batch_size=batch_size,
        randomization=randomization,
        background_compile=background_compile,
    )


# ------------------------------------------------------------------ host memory of a batch

# Copies of the batch's JAX state alive at once while a batch steps: the state held, the state
# stepped, the fresh reset of finished envs and their merge (ArmVectorEnv.step), besides XLA's
# buffers; the rest of the estimate is the C rollout's float64 arrays.
STATE_COPIES = 4


class InsufficientMemoryError(ConfigError):
    """A batch of envs (and its training buffers) would not fit in the host's available memory."""


@dataclass(frozen=True)
class MemoryEstimate:
    """Host bytes of a batch of envs: ``fixed + per_env * num_envs``.

    Attributes:
        fixed: bytes that do not grow with the batch (the rollout threads' MjData).
        per_env: bytes per env: its JAX state times :data:`STATE_COPIES`, the rollout's float64
            states and sensors of a control step, and a randomised model copy where it has one.
    """

    fixed: int
    per_env: int

    def total(self, num_envs: int) -> int:
        """Bytes of ``num_envs`` envs."""
        return self.fixed + self.per_env * num_envs

    def largest(self, available: int) -> int:
        """The largest batch that fits in ``available`` bytes (0: none)."""
        return max(0, (available - self.fixed) // max(self.per_env, 1))


def available_memory() -> int:
    """The host's available memory in bytes: ``MemAvailable`` of /proc/meminfo, else the free
    physical pages (``os.sysconf``)."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


def _tree_bytes(tree) -> int:
    return sum(int(np.prod(x.shape)) * np.dtype(x.dtype).itemsize for x in jax.tree.leaves(tree))


def estimate_env_memory(env, randomized: bool = False) -> MemoryEstimate:
    """The host memory of a batch of the single-env JAX ``env`` (``MjxArmEnv``), from the shapes
    of its state (``jax.eval_shape``: nothing runs) and, on the C MuJoCo backend, from MuJoCo's
    sizes (``mj_stateSize``, ``nsensordata``, ``mj_sizeModel``, the MjData per thread).

    Args:
        env: the env.
        randomized: each env steps its own randomised model copy (C MuJoCo backend).
    """
    state = jax.eval_shape(env.reset, jax.random.PRNGKey(0))
    per_env, fixed = STATE_COPIES * _tree_bytes(state), 0
    physics = env.physics
    if getattr(physics, "impl", "") == "c":
        import mujoco

        from mjx_arm.envs.mujoco_batch import STATE_SPEC

        model = physics.mj_model
        nstate = mujoco.mj_stateSize(model, STATE_SPEC)
        steps = max(physics.n_substeps, 1)
        per_env += 8 * (steps * (nstate + model.nsensordata) + 2 * nstate + model.nu + 3)
        if randomized:
            per_env += mujoco.mj_sizeModel(model)
        data = mujoco.MjData(model)
        fixed = physics.stepper.nthread * (data.nbuffer + data.narena)
    return MemoryEstimate(fixed, per_env)


def state_on_host(env) -> bool:
    """Whether a batch of ``env`` keeps its state in host memory: the C MuJoCo backend, or any
    backend where JAX runs on the CPU (on an accelerator the state is in device memory, whose
    allocations XLA checks itself)."""
    return getattr(env.physics, "impl", "") == "c" or jax.default_backend() == "cpu"


def check_memory(
    estimate: MemoryEstimate, num_envs: int, what: str, available: int | None = None
) -> None:
    """Refuse a batch whose estimate exceeds the available memory.

    Args:
        estimate: the batch's bytes.
        num_envs: the batch size asked for.
        what: the setting that sizes the batch, as the message names it ("num_envs").
        available: bytes available (default: :func:`available_memory`).

    Raises:
        InsufficientMemoryError: the estimate, the available figure and the largest batch that fits.
    """
    available = available_memory() if available is None else available
    need = estimate.total(num_envs)
    if need <= available:
        return
    raise InsufficientMemoryError(
        f"{what}={num_envs} needs about {need / 2**30:.1f} GiB of host memory "
        f"({estimate.per_env} bytes per env), but {available / 2**30:.1f} GiB is available: "
        f"the largest {what} that fits is about {estimate.largest(available)}"
    )
