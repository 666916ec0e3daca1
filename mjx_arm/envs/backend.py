"""Which physics steps the batched JAX env: MJX (JAX or Warp) or C MuJoCo behind a host callback."""

from __future__ import annotations

import jax

from mjx_arm.envs.physics_config import PhysicsConfig
from mjx_arm.names import BACKENDS
from mjx_arm.task.config import TaskConfig


def resolve_backend(name: str) -> str:
    """``auto`` -> ``mjx`` when an accelerator is present, else ``mujoco`` (C MuJoCo)."""
    if name not in BACKENDS:
        raise ValueError(f"unknown backend {name!r}; choose one of {BACKENDS}")
    if name != "auto":
        return name
    return "mjx" if jax.default_backend() in ("gpu", "cuda", "rocm", "tpu") else "mujoco"


def make_batched_env(
    task: TaskConfig,
    backend: str = "auto",
    physics: PhysicsConfig | None = None,
    batch_size: int = 1,
    randomization=None,
    arm=None,
    background_compile: bool = False,
):
    """The single-env JAX env (``MjxArmEnv``) with the physics of ``backend``.

    Args:
        task: the task configuration.
        backend: "auto", "mjx" or "mujoco" (C MuJoCo through a host callback).
        physics: the MJX implementation and buffers (``mjx`` only; default ``impl="auto"``).
        batch_size: the largest batch stepped at once (sizes Warp's shared contact pool).
        randomization: domain randomisation
            (:class:`mjx_arm.envs.randomization.RandomizationConfig`; default off).
        arm: the arm (a URDF, an arm file or an ArmConfig; default: the shipped arm).
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
