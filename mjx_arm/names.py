"""The project's vocabulary: the names of tasks, engines, backends, MJX implementations and
presets, defined once and used by the configs, the envs and the command line's choices.

- engine: where one policy runs, one row each in :mod:`mjx_arm.engines` (the registry): the
  Gymnasium envs on a CPU (``engine_names("env")``: MuJoCo, the PyBullet reference), and ``mjx``,
  the batched JAX env, whatever steps its physics.
- backend: what steps the batched JAX env's physics (:data:`BACKENDS`): ``mjx`` (MuJoCo's MJX)
  or ``mujoco`` (C MuJoCo behind a host callback, the CPU path); ``auto`` picks by device.
  Only the ``mjx`` engine has a backend; reports name the two together with
  :func:`engine_label` (``mjx (backend mujoco)``), and JSON keeps them as ``engine`` and
  ``backend``.
- implementation: how MJX steps the model (:data:`IMPLS`): ``jax`` (XLA) or ``warp`` (MuJoCo
  Warp's CUDA kernels); ``auto`` picks Warp where a GPU and warp-lang are present.
"""

from __future__ import annotations

from mjx_arm import engines

# The built-in tasks, one file each (mjx_arm/task/NAME.py); mjx_arm.task.registry adds others.
TASKS = ("reach", "touch", "lift")


def env_id(task: str) -> str:
    """The Gymnasium id of a task: ``reach`` -> ``mjx_arm/Reach-v0``."""
    return f"mjx_arm/{task.capitalize()}-v0"


TASK_IDS = {task: env_id(task) for task in TASKS}

# The registry's lists (mjx_arm.engines) as this module loads them: the built-in engines, in the
# orders the commands show. The commands read the registry itself, so they also list an engine
# registered later.
CPU_ENGINES = engines.engine_names("env")
EVAL_ENGINES = engines.eval_engines()
PARITY_ENGINES = engines.engine_names("parity")

BACKENDS = ("auto", "mjx", "mujoco")

IMPLS = ("auto", "jax", "warp")
PRESET_NAMES = ("seed", "fast", "cpu", "robust")

# Exit codes of every command: success, and an invalid input or setting (a named error); a
# benchmark stopped by SIGTERM after writing what it had exits as a shell reports that signal.
EXIT_OK, EXIT_INVALID, EXIT_STOPPED = 0, 2, 143


def engine_label(engine: str, backend: str | None = None) -> str:
    """How output names where a policy ran: the engine, and for the ``mjx`` engine its backend.

    A CPU engine's label is its name; ``engine_label("mjx", "mujoco")`` ->
    ``mjx (backend mujoco)``. A backend given with an engine without backends (a CPU engine)
    is ignored.
    """
    if not backend or engine not in engines.batch_engines():
        return engine
    return f"{engine} (backend {backend})"
