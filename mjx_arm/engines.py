"""The engine registry: one row per physics engine, naming what the engine provides.

A row (:class:`EngineSpec`) holds the engine's name (what a user types: ``--engine NAME``,
``gym.make(id, engine=NAME)``), a label for reports, and each thing the engine provides as an
import path string ``"package.module:attribute"``, loaded with :func:`load` only when used (the
registry sits at the bottom of the import layers, so it never imports an engine itself):

- ``env``: the Gymnasium env class, called ``cls(task, **kwargs)`` (a CPU engine);
- ``batch_physics``: per backend, the batch physics class of the batched JAX env (each one
  satisfies :class:`BatchPhysics`);
- ``position_env``: the position-controlled env of sim-to-real, ``cls(task, config=, **kwargs)``;
- ``parity``: the parity benchmark's engine factory, ``f(task, impl, batch_size, arm)``, with
  ``parity_goal`` (its divergence goal's setting) and ``grasp`` (its scripted pick);
- ``urdf_reader``: what its URDF loader reads (a ``mjx_arm.urdf.readers.UrdfReader``), for the
  validator's static checks; an engine with one is a choice of ``mjx-arm validate --engine``;
- ``urdf_check``: the URDF load check, ``f(tree, package_dirs, repair, findings, limits)``;
- ``parity_causes``: check prefix -> the stated cause of a missed parity goal of a pair (or
  engine) this engine's name is part of;
- ``impl_choice``: whether it runs under a choice of MJX implementation (``impl``).

Two engines have a standing role, named by :data:`CONVERTER_ENGINE` (its URDF loader is the
URDF-to-MJCF converter every MuJoCo model is built with) and :data:`REFERENCE_ENGINE` (the one
the others are compared with, recorded in and filmed).

Each is None (or empty) where the engine does not provide it. The built-in rows are below; an
engine that lives in its own top-level package (the PyBullet reference, ``pybullet_ref``)
registers its row from a module named in :data:`ENGINE_MODULES`, imported on first lookup.
"""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

from mjx_arm.inputs import InputError

__all__ = [
    "CONVERTER_ENGINE",
    "REFERENCE_ENGINE",
    "BatchPhysics",
    "EngineSpec",
    "EngineUnavailableError",
    "UnknownEngineError",
    "batch_engines",
    "check_installed",
    "engine",
    "engine_names",
    "eval_engines",
    "load",
    "register_engine",
    "unregister_engine",
]


class UnknownEngineError(InputError, ValueError):
    """An engine name that no row of the registry has."""


class EngineUnavailableError(InputError):
    """An engine whose optional package (its row's ``requires``) is not installed."""


@dataclass(frozen=True)
class EngineSpec:
    """One engine's row. Import paths are ``"module:attribute"`` strings (see the module doc).

    Attributes:
        name: what a user types.
        label: how reports and tables name it.
        env: the Gymnasium env class (a CPU engine), or None.
        env_options: keyword settings only this engine's env takes (``contact``), passed on
            when given and ignored by the other engines.
        batch_physics: backend name -> batch physics class; empty where there is no batch.
        position_env: the position-controlled env class of sim-to-real, or None.
        parity: the parity benchmark's engine factory, or None.
        parity_goal: the :class:`~mjx_arm.bench.parity_config.ParityConfig` field that holds
            the joint divergence goal of a pair this engine takes part in (None: MJX's goal).
        grasp: the grasp benchmark's scripted pick, ``f(model, arm, script, frames) -> dict``.
        parity_causes: check prefix (``"joint divergence"``) -> why a parity goal of this
            engine is missed; the first row (engines with a ``parity_goal`` first) whose name
            the goal's subject holds and whose prefix the check starts with gives the cause.
        impl_choice: it runs under a choice of MJX implementation (``impl``: ``jax``,
            ``warp``), so the parity benchmark runs it once per implementation asked for.
        urdf_reader: what its URDF loader reads (an ``UrdfReader``), or None.
        urdf_check: the URDF load check, or None.
        requires: the optional module the engine imports (None: always installed).
        install_hint: what to run when ``requires`` is missing.
    """

    name: str
    label: str
    env: str | None = None
    env_options: tuple[str, ...] = ()
    batch_physics: Mapping[str, str] = field(default_factory=dict)
    position_env: str | None = None
    parity: str | None = None
    parity_goal: str | None = None
    grasp: str | None = None
    parity_causes: Mapping[str, str] = field(default_factory=dict)
    impl_choice: bool = False
    urdf_reader: str | None = None
    urdf_check: str | None = None
    requires: str | None = None
    install_hint: str | None = None

    def provides(self, what: str) -> bool:
        """Whether the row fills the field ``what`` (``"env"``, ``"parity"``, ...)."""
        return bool(getattr(self, what))


@runtime_checkable
class BatchPhysics(Protocol):
    """What the batched JAX env asks of its physics (MJX, or C MuJoCo behind a host callback).

    ``data`` is one backend's state of a batch of B envs (a pytree); ``ctrl`` is ``(B, n)``
    (vmapped where the backend steps one env at a time), ``done`` is ``(B,)``.
    """

    def init(self, qpos: Any, target_body: Any, obj: Any = None) -> Any:
        """The state at joint positions ``qpos (n_q,)`` with the target at ``target_body``."""

    def set_target(self, data: Any, target_body: Any, obj: Any = None) -> Any:
        """``data`` with the target (and a gripper task's cube ``obj``) moved."""

    def step(self, data: Any, ctrl: Any, dynamics: Any = None, object_params: Any = None) -> Any:
        """One control step holding ``ctrl``."""

    def read(self, data: Any) -> Any:
        """The observation contract's read-out (a ``Reading``)."""

    def overflow(self, data: Any) -> Any:
        """Whether a buffer overflowed (a bool array)."""

    def check_overflow(self, flags: Any) -> None:
        """Raise a named error when ``flags`` say a buffer overflowed."""

    def where(self, done: Any, new: Any, old: Any) -> Any:
        """Per env: ``new`` where ``done`` else ``old``."""

    def splits(self, path: tuple) -> bool:
        """Whether the state leaf at ``path`` has the batch axis first."""

    def wait_precompiled(self) -> dict[str, float]:
        """Wait for kernels compiled ahead; their compile seconds by name."""

    def describe(self) -> dict:
        """Implementation facts, for run configs and benchmark JSON."""


_ROWS: dict[str, EngineSpec] = {}

# Modules that register an engine living outside mjx_arm, imported on first lookup.
ENGINE_MODULES = ("pybullet_ref.engine",)
_loaded = False


def register_engine(spec: EngineSpec) -> EngineSpec:
    """Add ``spec`` (replacing a row of the same name); returns it."""
    _ROWS[spec.name] = spec
    return spec


def unregister_engine(name: str) -> None:
    """Remove the row ``name`` (no error when there is none)."""
    _ROWS.pop(name, None)


def _rows() -> dict[str, EngineSpec]:
    global _loaded
    if not _loaded:
        _loaded = True
        for module in ENGINE_MODULES:
            importlib.import_module(module)
    return _ROWS


def engine_names(provides: str | None = None) -> tuple[str, ...]:
    """The registered names in registry order; with ``provides``, those that fill that field."""
    rows = _rows().values()
    return tuple(r.name for r in rows if provides is None or r.provides(provides))


def batch_engines() -> tuple[str, ...]:
    """Engines that are a batch and no Gymnasium env (``mjx``)."""
    return tuple(r.name for r in _rows().values() if r.batch_physics and not r.env)


def eval_engines() -> tuple[str, ...]:
    """Where a policy can be evaluated: the Gymnasium env engines, then the batch engines."""
    return (*engine_names("env"), *batch_engines())


def engine(name: str, provides: str | None = None) -> EngineSpec:
    """The row ``name``; with ``provides``, it must fill that field.

    Raises:
        UnknownEngineError: no such row (or none that provides ``provides``).
    """
    choices = engine_names(provides)
    if name not in choices:
        raise UnknownEngineError(f"unknown engine {name!r}; choose one of {choices}")
    return _ROWS[name]


def check_installed(name: str) -> None:
    """Raise :class:`EngineUnavailableError`, with the row's install hint, when the package
    the engine ``name`` requires cannot be imported."""
    spec = engine(name)
    if spec.requires and importlib.util.find_spec(spec.requires) is None:
        raise EngineUnavailableError(
            f"engine {name!r} needs the {spec.requires} package, which is not installed: "
            f"{spec.install_hint or 'install it'}"
        )


def load(path: str) -> Any:
    """The attribute that ``"package.module:attribute"`` names, importing its module."""
    module, _, attribute = path.partition(":")
    return getattr(importlib.import_module(module), attribute)


# The engine whose URDF loader is the converter to MJCF: an arm is validated for it wherever a
# MuJoCo model is built from the arm (the MuJoCo and MJX envs, training, the benchmarks).
CONVERTER_ENGINE = "mujoco"
# The engine the others are compared with where one reference is needed: parity records its
# press commands in it, and the demo films and plots its episodes.
REFERENCE_ENGINE = "mujoco"

register_engine(
    EngineSpec(
        name="mujoco",
        label="CPU MuJoCo (Gymnasium)",
        env="mjx_arm.envs.mujoco_env:MujocoArmEnv",
        position_env="mjx_arm.sim2real.position_env:MujocoPositionArmEnv",
        parity="mjx_arm.bench.engines:mujoco_engine",
        grasp="mjx_arm.bench.grasp:run_mujoco",
        urdf_reader="mjx_arm.urdf.readers:MUJOCO",
        urdf_check="mjx_arm.urdf.check_physics:check_mujoco_load",
    )
)
register_engine(
    EngineSpec(
        name="mjx",
        label="MJX",
        batch_physics={
            "mjx": "mjx_arm.envs.mjx_physics:MjxPhysics",
            "mujoco": "mjx_arm.envs.mujoco_batch:MujocoCallbackPhysics",
        },
        parity="mjx_arm.bench.engines:MjxEngine",
        grasp="mjx_arm.bench.grasp:run_mjx",
        impl_choice=True,
        parity_causes={
            "forward kinematics": (
                "MJX computes in float32: about 1e-7 relative rounding per transform, summed "
                "along the chain of bodies"
            ),
            "joint divergence": (
                "float32 against float64 (and, in sequences that touch the table, MJX's own "
                "collision routines and fixed solver iterations): differences grow along the "
                "trajectory"
            ),
        },
    )
)
