"""URDF -> MJCF through MuJoCo's own URDF importer and ``mujoco.MjSpec`` edits.

The importer does the parsing (links, joints, inertials, geometry, limits, damping). What it leaves
out is added here on the spec: joint damping and armature, velocity actuators sized from the URDF
``<limit effort velocity>``, an ``ee`` site, wrist force/torque sensors with what is needed to tare
them, MJX-ready solver options, contact filtering and, optionally, the task scene.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from mjx_arm.engines import CONVERTER_ENGINE
from mjx_arm.urdf.convert_config import (
    ARM_CONAFFINITY,
    ARM_CONAFFINITY_NO_SELF,
    ARM_CONTYPE,
    EE_SITE,
    FT_SITE,
    SENSORS,
    TOOL_COM_SITE,
    ConvertConfig,
)
from mjx_arm.urdf.errors import ConversionError, report_error
from mjx_arm.urdf.mjcf import build_checked_spec, compile_spec, mjcf_text

__all__ = [
    "ARM_CONAFFINITY",
    "ARM_CONAFFINITY_NO_SELF",
    "ARM_CONTYPE",
    "EE_SITE",
    "FT_SITE",
    "SENSORS",
    "TOOL_COM_SITE",
    "ConversionError",
    "ConvertConfig",
    "build_checked_spec",
    "build_spec",
    "compile_spec",
    "load_model",
    "mjcf_text",
    "to_mjcf",
]


def build_spec(urdf: str | Path, config: ConvertConfig | None = None) -> mujoco.MjSpec:
    """Check a URDF statically, import it and return the edited ``mujoco.MjSpec``.

    The URDF first goes through the validator's static layers for MuJoCo
    (:func:`mjx_arm.urdf.validate.validate` with ``native=False``), so a broken or hostile file
    fails with the validator's named findings before MuJoCo's importer sees it.

    Args:
        urdf: path of the URDF file.
        config: conversion settings; defaults to :class:`ConvertConfig()`.

    Raises:
        ConversionError: the validator's errors; a mesh that cannot be found or read, an
            invalid inertia (without ``repair_inertia``), a joint without effort or velocity
            limits, or an error of MuJoCo's importer or compiler (a zero joint axis, an
            unreadable mesh), always naming the file and quoting MuJoCo's message.
    """
    from mjx_arm.urdf.validate import validate

    config = config or ConvertConfig()
    path = Path(urdf).resolve()
    report = validate(
        path,
        engine=CONVERTER_ENGINE,
        package_dirs=config.package_dirs,
        native=False,
        repair_inertia=config.repair_inertia,
        default_limits=config.default_limits(),
    )
    if not report.ok:
        raise report_error(ConversionError, report)
    try:
        return build_checked_spec(path, config)
    except ConversionError:
        raise
    except Exception as exc:  # a bug: still a named error, never a bare traceback
        raise ConversionError(
            f"{path}: the converter failed unexpectedly: {type(exc).__name__}: {exc}; "
            "report this as a bug in mjx_arm.urdf.convert"
        ) from exc


def to_mjcf(urdf: str | Path, config: ConvertConfig | None = None, **overrides) -> str:
    """Convert a URDF to MJCF XML text.

    Args:
        urdf: path of the URDF file.
        config: conversion settings; keyword ``overrides`` replace single fields of it.

    Returns:
        The MJCF document. The same input gives the same bytes.

    Raises:
        ConversionError: as :func:`build_spec`, or the model does not compile, has non-finite
            values, or its MJCF text does not compile again.
    """
    config = (config or ConvertConfig()).replace(**overrides)
    return mjcf_text(build_spec(urdf, config), urdf)


def load_model(
    urdf: str | Path, config: ConvertConfig | None = None, **overrides
) -> mujoco.MjModel:
    """Convert a URDF and compile it into a ``mujoco.MjModel`` (errors as :func:`to_mjcf`),
    starting at ``config.rest_qpos``."""
    config = (config or ConvertConfig()).replace(**overrides)
    model = compile_spec(build_spec(urdf, config), urdf)
    if config.rest_qpos:
        set_rest_qpos(model, dict(config.rest_qpos))
    return model


def set_rest_qpos(model: mujoco.MjModel, rest: dict[str, float]) -> None:
    """Start ``model`` (in place) with hinge or slide joints ``rest`` (name -> rad or m) at
    those positions, as a joint's ``ref`` would: each joint's body is turned (or moved) by its
    value and its ``qpos0`` set to it, so a position means what it meant before and a reset
    puts the joint there; MuJoCo's constants at ``qpos0`` are derived again.

    A joint equality holds ``q1 - q1_0 = c0 + c1 (q2 - q2_0)`` about ``qpos0``: its ``c0`` is
    moved so that an equality between two moved joints keeps ``q1 = c0 + c1 q2`` as imported.
    """
    before = model.qpos0.copy()
    for name, value in rest.items():
        joint = model.joint(name)
        body, adr = int(joint.bodyid[0]), int(joint.qposadr[0])
        _move_body(model, body, joint, float(value) - float(model.qpos0[adr]))
        model.qpos0[adr] = value
    for i in range(model.neq):
        if model.eq_type[i] != mujoco.mjtEq.mjEQ_JOINT or model.eq_obj2id[i] < 0:
            continue
        one, two = (model.jnt_qposadr[model.eq_obj1id[i]], model.jnt_qposadr[model.eq_obj2id[i]])
        shift = (model.qpos0[one] - before[one]) - model.eq_data[i][1] * (
            model.qpos0[two] - before[two]
        )
        model.eq_data[i][0] -= shift
    mujoco.mj_setConst(model, mujoco.MjData(model))


def _move_body(model: mujoco.MjModel, body: int, joint, value: float) -> None:
    """Turn ``body`` by ``value`` (rad) about its hinge ``joint`` (axis through the joint's
    position, both in the body's frame), or move it by ``value`` (m) along its slide."""
    axis, quat = np.asarray(joint.axis, float), model.body_quat[body].copy()
    rotation = np.zeros(9)
    mujoco.mju_quat2Mat(rotation, quat)
    rotation = rotation.reshape(3, 3)
    if int(joint.type[0]) == mujoco.mjtJoint.mjJNT_SLIDE:
        model.body_pos[body] += rotation @ (axis * value)
        return
    turn = np.zeros(4)
    mujoco.mju_axisAngle2Quat(turn, axis, value)
    turned = np.zeros(9)
    mujoco.mju_quat2Mat(turned, turn)
    pivot = np.asarray(joint.pos, float)
    model.body_pos[body] += rotation @ (pivot - turned.reshape(3, 3) @ pivot)
    mujoco.mju_mulQuat(model.body_quat[body], quat, turn)
