"""Validation layer 2, joints: types, axes, limits and damping each engine needs."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping

import numpy as np

from mjx_arm.urdf.findings import (
    _AXIS_EPS,
    LIMITED_TYPES,
    MOVABLE_TYPES,
    _Findings,
    _Joint,
    _joint,
    _number,
    _numbers,
    _Tree,
)
from mjx_arm.urdf.readers import UrdfReader
from mjx_arm.urdf.repair import limit_fix

# --------------------------------------------------------------------------- layer 2: joints


def _check_joints(
    tree: _Tree,
    readers: tuple[UrdfReader, ...],
    out: _Findings,
    default_limits: Mapping[str, float] | None = None,
) -> None:
    """Joint checks for the engines whose URDF ``readers`` are given; ``default_limits``
    (``effort``/``velocity`` -> value) are what the repair puts where a joint gives none, in
    every engine (:mod:`mjx_arm.urdf.repair`)."""
    defaults = dict(default_limits or {})
    for j in tree.joints.values():
        if j.type in ("floating", "planar"):
            _check_free_joint(j, readers, out)
        if j.type not in MOVABLE_TYPES:
            continue
        _check_axis(j, out)
        if j.type in LIMITED_TYPES:
            _check_limit(j, out, defaults)
        elif any(r.sizes_actuators_from_limits for r in readers):
            _check_effort_velocity(j, j.elem.find("limit"), out, True, defaults)
        _check_damping(j, readers, out)


def _check_free_joint(j: _Joint, readers: tuple[UrdfReader, ...], out: _Findings) -> None:
    """Floating and planar joints: MuJoCo rejects a free joint below the root; none is actuated."""
    fix = "use revolute, continuous, prismatic or fixed joints for an arm"
    if j.type == "floating" and any(r.free_joint_root_only for r in readers):
        out.error(
            2,
            _joint(j.name),
            "is floating: MuJoCo allows a free joint only on a body attached to the world",
            fix,
        )
    else:
        out.warning(2, _joint(j.name), f"is {j.type}: the converter gives it no actuator", fix)


def _check_axis(j: _Joint, out: _Findings) -> None:
    axis_elem = j.elem.find("axis")
    if axis_elem is None:
        return  # URDF default (1, 0, 0)
    axis = _numbers(axis_elem.get("xyz"), 3)
    if axis is None:
        out.error(
            2,
            _joint(j.name),
            f"has a malformed <axis xyz={axis_elem.get('xyz')!r}>",
            'give three numbers, e.g. xyz="0 0 1"',
        )
    elif float(np.linalg.norm(axis)) < _AXIS_EPS:
        out.error(
            2,
            _joint(j.name),
            "has a zero <axis> (MuJoCo refuses it: axis too small)",
            'give the unit vector of the joint axis, e.g. xyz="0 0 1"',
        )


def _check_limit(j: _Joint, out: _Findings, defaults: Mapping[str, float]) -> None:
    """Revolute and prismatic joints: <limit> with lower < upper, effort > 0, velocity > 0."""
    limit = j.elem.find("limit")
    if limit is None:
        out.error(
            2,
            _joint(j.name),
            f"is {j.type} but has no <limit> (MuJoCo silently makes it "
            "unlimited and has no velocity limit of its own)",
            "add <limit lower=... upper=... effort=... velocity=.../>",
        )
        return
    lower, upper = _number(limit, "lower"), _number(limit, "upper")
    if isinstance(lower, str) or isinstance(upper, str):
        out.error(
            2,
            _joint(j.name),
            f"has a non-numeric <limit> bound ({lower!r}, {upper!r})",
            "give numbers in rad (revolute) or m (prismatic)",
        )
    elif lower is None or upper is None:
        out.error(
            2,
            _joint(j.name),
            "has a <limit> without lower and upper (URDF reads them as 0)",
            "give both lower and upper, with lower < upper",
        )
    elif not lower < upper:
        out.error(
            2,
            _joint(j.name),
            f"has limit lower={lower:g} >= upper={upper:g}",
            "set lower < upper (swap them if they are reversed)",
        )
    _check_effort_velocity(j, limit, out, False, defaults)


def _check_effort_velocity(
    j: _Joint,
    limit: ET.Element | None,
    out: _Findings,
    for_converter: bool,
    defaults: Mapping[str, float],
) -> None:
    why = " (the converter sizes the joint's velocity actuator from them)" if for_converter else ""
    for attr, unit in (("effort", "N m or N"), ("velocity", "rad/s or m/s")):
        value = None if limit is None else _number(limit, attr)
        if not (value is None or isinstance(value, str) or value <= 0):
            continue
        shown = "missing" if value is None else f"{value}"
        if defaults.get(attr, 0.0) > 0:
            out.warning(
                2,
                _joint(j.name),
                f"has <limit {attr}> {shown}: the repair gives it {defaults[attr]:g} in every "
                f"engine (--default-{attr})",
                f"set {attr} to the joint's positive maximum ({unit})",
            )
            continue
        out.error(
            2,
            _joint(j.name),
            f"has <limit {attr}> {shown}, not > 0{why}",
            limit_fix(attr, unit),
        )


def _check_damping(j: _Joint, readers: tuple[UrdfReader, ...], out: _Findings) -> None:
    """A damping >= 0; a warning where it is missing (each reader's ``undamped_note``) or
    below a reader's ``min_damping``."""
    value = _number(j.elem.find("dynamics"), "damping")
    if isinstance(value, str) or (value is not None and value < 0):
        out.error(
            2,
            _joint(j.name),
            f"has invalid <dynamics damping={value!r}>",
            "give a damping >= 0 (N m s/rad or N s/m)",
        )
        return
    notes = [r.undamped_note for r in readers if r.undamped_note]
    if not value and notes:
        out.warning(
            2,
            _joint(j.name),
            "has no <dynamics damping>: " + "; ".join(notes),
            'add <dynamics damping="..."/> with the joint\'s real damping',
        )
        return
    for reader in readers:
        if value and value < reader.min_damping:
            out.warning(
                2,
                _joint(j.name),
                f"has damping {value:g} < {reader.min_damping:g}: {reader.label} jitters with "
                "so little damping",
                f"raise <dynamics damping> to at least {reader.min_damping:g}",
            )
