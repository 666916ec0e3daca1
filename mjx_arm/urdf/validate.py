"""Three-layer URDF validation: XML and tree, engine compatibility, physics and native loads.

Layer 1 reads the XML leniently and checks the kinematic tree. Layer 2 checks what each engine's
URDF loader needs (MuJoCo's through :mod:`mjx_arm.urdf.convert`, PyBullet's): joint limits,
damping, readable meshes and collision shapes MJX can collide; what a loader reads is its
:class:`~mjx_arm.urdf.readers.UrdfReader`, named in the engine's registry row. Layer 3 checks
masses and inertia tensors, then loads the file into the engines' own loaders (skipped when an
earlier check already found an error: PyBullet crashes on some broken trees, for example a URDF
with two root links).

Every problem becomes a :class:`Finding` that names the file, the element, what is wrong and how to
fix it; nothing raises on bad input. ``mjx-arm validate`` prints the report; envs call
:func:`validated`, which caches the result per file version.

The checks live in :mod:`~mjx_arm.urdf.check_tree` (layer 1), :mod:`~mjx_arm.urdf.check_joints`
and :mod:`~mjx_arm.urdf.check_geometry` (layer 2) and :mod:`~mjx_arm.urdf.check_physics`
(layer 3); the report types in :mod:`~mjx_arm.urdf.findings`. This module runs them in order.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path

from mjx_arm.engines import engine, load
from mjx_arm.urdf.check_geometry import _check_geometry
from mjx_arm.urdf.check_joints import _check_joints
from mjx_arm.urdf.check_physics import _check_inertials
from mjx_arm.urdf.check_tree import _check_line_lengths, _check_tree, _read_xml
from mjx_arm.urdf.errors import UrdfError, one_line, report_error
from mjx_arm.urdf.findings import ENGINES, Finding, ValidationReport, _Findings, _Tree
from mjx_arm.urdf.readers import UrdfReader, readers_of

__all__ = ["ENGINES", "Finding", "ValidationReport", "require_valid", "validate", "validated"]

# --------------------------------------------------------------------------- entry points


def validate(
    path: str | Path,
    engine: str = "all",
    package_dirs: Mapping[str, str] | None = None,
    native: bool = True,
    repair_inertia: bool = False,
    min_damping_pybullet: float | None = None,
    default_limits: Mapping[str, float] | None = None,
    min_damping: float | None = None,
) -> ValidationReport:
    """Validate a URDF in three layers and return every finding; never raises on bad input.

    Args:
        path: the URDF file.
        engine: "mujoco", "pybullet" or "all": the engine(s) the file must work in.
        package_dirs: ``package://NAME`` -> directory, for meshes outside the URDF's folder tree.
        native: run the engines' own loaders (layer 3) when the static checks find no error.
        repair_inertia: report invalid inertia tensors as warnings: the repair
            (:mod:`mjx_arm.urdf.repair`) replaces them in MuJoCo's conversion and in the copy
            PyBullet loads, and the native loads check the repaired text.
        min_damping_pybullet: deprecated name of ``min_damping``.
        default_limits: ``effort``/``velocity`` values the repair gives joints that give none
            (``ConvertConfig.default_limits``), in every engine; a missing limit with a default
            is a warning.
        min_damping: joint damping below which an engine that jitters without damping (a
            reader with ``min_damping``: PyBullet, 0.01) is expected to jitter; None: each
            engine's own.

    Raises:
        ValueError: ``engine`` is not one of the names.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {sorted(ENGINES)}, got {engine!r}")
    engines, dirs = ENGINES[engine], dict(package_dirs or {})
    readers = readers_of(engines, _min_damping(min_damping, min_damping_pybullet))
    out = _Findings(str(path))
    tree = _guarded(out, 1, lambda: _layer1(Path(path), out))
    if tree is not None:
        _static(tree, readers, dirs, repair_inertia, out, default_limits)
        if native and not out.has_errors:
            _native(tree, engines, dirs, repair_inertia, out, default_limits or {})
    return ValidationReport(str(path), engine, tuple(out.items))


def _min_damping(min_damping: float | None, deprecated: float | None) -> float | None:
    """``min_damping``, or the value of its deprecated name ``min_damping_pybullet`` (with a
    :class:`DeprecationWarning`) where only that is given."""
    if deprecated is None:
        return min_damping
    warnings.warn(
        "validate(min_damping_pybullet=) is deprecated: use min_damping=",
        DeprecationWarning,
        stacklevel=3,
    )
    return deprecated if min_damping is None else min_damping


def _static(
    tree: _Tree,
    readers: tuple[UrdfReader, ...],
    dirs: Mapping[str, str],
    repair: bool,
    out: _Findings,
    limits: Mapping[str, float] | None,
) -> None:
    """Layers 2 and 3 without the native loads: what each of ``readers`` can read."""
    for reader in readers:
        if reader.max_line_bytes is not None:
            limit, label = reader.max_line_bytes, reader.label
            _guarded(out, 2, lambda a=limit, b=label: _check_line_lengths(tree.path, a, b, out))
    _guarded(out, 2, lambda: _check_joints(tree, readers, out, limits))
    _guarded(out, 2, lambda: _check_geometry(tree, readers, dirs, out))
    _guarded(out, 3, lambda: _check_inertials(tree, readers, repair, out))


def _layer1(path: Path, out: _Findings) -> _Tree | None:
    resolved = path.expanduser().resolve()
    root = _read_xml(resolved, out)
    return None if root is None else _check_tree(resolved, root, out)


def _native(
    tree: _Tree,
    engines: tuple[str, ...],
    dirs: Mapping[str, str],
    repair: bool,
    out: _Findings,
    limits: Mapping[str, float],
) -> None:
    for name in engines:  # registry order: MuJoCo first
        if engine(name).urdf_check:
            check = load(engine(name).urdf_check)
            _guarded(out, 3, lambda check=check: check(tree, dirs, repair, out, limits))


def _guarded(out: _Findings, layer: int, check: Callable[[], _Tree | None]) -> _Tree | None:
    """Run one check; an unexpected exception becomes an error finding instead of a traceback."""
    try:
        return check()
    except Exception as exc:
        out.error(
            layer,
            "robot",
            f"the validator failed unexpectedly: {type(exc).__name__}: {one_line(exc)}",
            "report this as a bug in mjx_arm.urdf.validate",
        )
        return None


def require_valid(path: str | Path, engine: str = "all", **kw) -> ValidationReport:
    """Validate and return the report; raise :class:`UrdfError` with the report when not ok."""
    report = validate(path, engine=engine, **kw)
    if not report.ok:
        raise report_error(UrdfError, report)
    return report


def validated(
    path: str | Path,
    engine: str = "all",
    package_dirs: Mapping[str, str] | None = None,
    repair_inertia: bool = False,
    default_limits: Mapping[str, float] | None = None,
) -> ValidationReport:
    """:func:`require_valid`, cached per (resolved path, modification time, engine, options).

    Envs call this whenever they are constructed; a file is validated again only after it
    changes.

    Raises:
        UrdfError: the URDF has errors (not cached: every call validates again).
    """
    resolved = Path(path).expanduser().resolve()
    try:
        mtime = resolved.stat().st_mtime_ns
    except OSError:
        mtime = -1
    dirs = tuple(sorted((package_dirs or {}).items()))
    limits = tuple(sorted((default_limits or {}).items()))
    return _validated_cached(str(resolved), mtime, engine, dirs, repair_inertia, limits)


@functools.lru_cache(maxsize=64)
def _validated_cached(
    path: str,
    mtime_ns: int,
    engine: str,
    package_dirs: tuple[tuple[str, str], ...],
    repair_inertia: bool,
    default_limits: tuple[tuple[str, float], ...],
) -> ValidationReport:
    del mtime_ns  # part of the cache key only
    return require_valid(
        path,
        engine,
        package_dirs=dict(package_dirs),
        repair_inertia=repair_inertia,
        default_limits=dict(default_limits) or None,
    )
