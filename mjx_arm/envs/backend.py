"""Which physics steps the batched JAX env: MJX or C MuJoCo behind a host callback."""

from __future__ import annotations

import jax

from mjx_arm.task.config import TaskConfig

BACKENDS = ("auto", "mjx", "mujoco")


def resolve_backend(name: str) -> str:
    """``auto`` -> ``mjx`` when an accelerator is present, else ``mujoco`` (C MuJoCo)."""
    if name not in BACKENDS:
        raise ValueError(f"unknown backend {name!r}; choose one of {BACKENDS}")
    if name != "auto":
        return name
    return "mjx" if jax.default_backend() in ("gpu", "cuda", "rocm", "tpu") else "mujoco"


def make_batched_env(task: TaskConfig, backend: str = "auto"):
    """The single-env JAX env (``MjxArmEnv``) with the physics of ``backend``."""
    from mjx_arm.envs.mjx_env import MjxArmEnv

    if resolve_backend(backend) == "mujoco":
        from mjx_arm.envs.mujoco_batch import MujocoCallbackPhysics

        return MjxArmEnv(task, physics_factory=MujocoCallbackPhysics)
    return MjxArmEnv(task)
