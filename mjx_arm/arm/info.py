"""What every engine needs to know about the arm (:class:`~mjx_arm.arm.facts.ArmInfo`), read
once from its config and URDF; its working points come from :mod:`mjx_arm.arm.points`."""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import math
from pathlib import Path

import numpy as np

from mjx_arm.arm.config import (
    SHIPPED_HOME_QPOS,
    ArmConfig,
    ResolvedArm,
    is_shipped,
    load_arm,
    resolve_arm,
)
from mjx_arm.arm.facts import ArmInfo
from mjx_arm.arm.gripper import find_gripper
from mjx_arm.arm.points import MIN_EE_OFFSET as MIN_EE_OFFSET
from mjx_arm.arm.points import task_arm as task_arm
from mjx_arm.arm.points import tool_down_solver, with_points
from mjx_arm.task.wrench import tool_inertia

# Poses drawn to measure an arm's reach (seeded: the same arm always gets the same scale).
REACH_SAMPLES = 4096
REACH_QUANTILE = 0.99


def _info(resolved: ResolvedArm, reach: float, reference: float) -> ArmInfo:
    offset = np.asarray(resolved.config.ee_offset or (0.0, 0.0, 0.0), dtype=float)
    limits = [j.limit for j in resolved.joints]
    path = resolved.config.urdf_path
    return ArmInfo(
        config=resolved.config,
        urdf=path,
        joint_names=resolved.joint_names,
        lower=np.array([_range(j)[0] for j in resolved.joints]),
        upper=np.array([_range(j)[1] for j in resolved.joints]),
        v_max=np.array(
            [_limit(lim, "velocity") or resolved.config.default_velocity for lim in limits]
        ),
        effort=np.array(
            [_limit(lim, "effort") or resolved.config.default_effort for lim in limits]
        ),
        home_qpos=np.array(resolved.home_qpos),
        ee_link=resolved.ee_link,
        ft_joint=resolved.ft_joint,
        ft_link=resolved.ft_link,
        tool=tool_inertia(resolved.model, resolved.ft_link, resolved.ee_link, offset),
        reach_scale=reach / reference,
        gripper=find_gripper(resolved),
        full_turn=np.array([j.type == "continuous" for j in resolved.joints]),
        ee_offset=offset,
    )


def _limit(limit, name: str) -> float:
    """A ``<limit>``'s ``velocity`` or ``effort``; 0 where the joint has no ``<limit>`` (a
    continuous joint may leave it out: the config's default then applies)."""
    return 0.0 if limit is None else getattr(limit, name)


def _range(joint) -> tuple[float, float]:
    """A joint's position range (rad): its URDF limits, or +-2 pi for a continuous joint whose
    ``<limit>`` gives none (it turns freely in the physics either way)."""
    lim = joint.limit
    if joint.type == "continuous" and (lim is None or not lim.lower < lim.upper):
        return -2 * math.pi, 2 * math.pi
    return lim.lower, lim.upper


@functools.cache
def _arm_info_cached(arm: ArmConfig, mtime: float) -> ArmInfo:
    resolved = resolve_arm(arm)
    reference = _reference_reach()
    shipped = arm.urdf_path == ArmConfig().urdf_path and not (arm.ee_link or arm.joints)
    reach = reference if shipped else horizontal_reach(resolved)
    info = _info(resolved, reach, reference)
    if not arm.ee_offset and not is_shipped(arm):
        info = with_points(info)  # its tool point (Reach, Touch) and grip point (Lift)
    kv = arm.kv_factor or (1.0 if is_shipped(arm) else press_kv_factor(info))
    return dataclasses.replace(info, kv_factor=kv)


# The working height (m) of the ee point above the table at a home pose (mjx_arm.arm.setup).
HOME_HEIGHT = 0.20
KV_MIN = 0.25  # the lowest servo gain factor press_kv_factor gives


def press_force(arm: ArmInfo, q: np.ndarray | None = None) -> float:
    """The force (N) Touch's full downward action presses with, the tool held still, at the
    tool-down pose ``q (n,)`` (default: the best-conditioned one over the middle of Touch's
    area at :data:`HOME_HEIGHT`), with servo gain factor 1.

    A velocity servo held still pushes with its gain times the commanded speed: the wrist force
    is ``e_z . J+^T K J+ e_z * v`` for the least-norm joint motion ``J+ e_z`` that moves the
    tool down, ``K`` the servo gains and ``v`` the fastest such motion at Touch's joint speeds.
    """
    from mjx_arm.task.touch import touch_config

    solver = tool_down_solver(arm)
    task = touch_config()
    if q is None:
        low, high = task.replace(workspace_scale=arm.reach_scale).target_box()
        above = np.array([0.5 * (low[0] + high[0]), 0.5 * (low[1] + high[1]), HOME_HEIGHT])
        homes = solver.homes(above)
        if not homes:
            return float("nan")
        q = homes[0]
    model = solver.ik.model
    gains = np.array([model.actuator_gainprm[model.actuator(n).id, 0] for n in arm.joint_names])
    jp, _ = solver.ik.jacobian(np.asarray(q, float))
    pinv = np.linalg.pinv(jp)
    down = pinv @ np.array([0.0, 0.0, -1.0])
    speed = 1.0 / np.max(np.abs(down) / task.joint_speeds(arm.v_max))
    return float((pinv[:, 2] @ (gains * pinv[:, 2])) * speed)


@functools.cache
def _reference_press() -> float:
    """:func:`press_force` of the shipped arm at its home pose."""
    shipped = arm_info()
    return press_force(shipped, np.asarray(SHIPPED_HOME_QPOS))


def press_kv_factor(arm: ArmInfo) -> float:
    """The servo gain factor at which the arm presses like the shipped arm: the shipped arm's
    :func:`press_force` over this arm's, in [:data:`KV_MIN`, 1].

    Why: Touch's force band (1-50 N) is a band of the action along the pressing direction, and
    a stiffer arm squeezes it into actions finer than PPO's exploration noise (policies then
    rest on the box below 1 N, or strike it). On the H200 the arms that press at about the
    shipped arm's 250 N or less at a full action (shipped, Panda, xArm7) solved Touch on every
    seed tried; those at 360-430 N (UR3, UR5, UR10) on some (benchmarks/results/arms/).
    """
    force = press_force(arm)
    if not np.isfinite(force) or force <= 0:
        return 1.0
    return float(np.clip(_reference_press() / force, KV_MIN, 1.0))


@functools.cache
def _reference_reach() -> float:
    """The shipped arm's horizontal reach (m), the unit of ``reach_scale``."""
    return horizontal_reach(resolve_arm(ArmConfig()))


def arm_info(arm: str | Path | ArmConfig | None = None) -> ArmInfo:
    """Arm facts of ``arm`` (a URDF, an arm file or config; default: the shipped arm), cached
    per config and file version."""
    config = load_arm(arm)
    return _arm_info_cached(config, config.urdf_path.stat().st_mtime)


def validated_arm_info(arm: str | Path | ArmConfig | None, engine: str) -> ArmInfo:
    """Validate the arm's URDF for ``engine``, then read its arm facts.

    Validation comes first, so a broken file fails with the validator's report instead of a
    parse error.
    """
    config = load_arm(arm)
    validate_arm(config, engine)
    return arm_info(config)


def validate_arm(config: ArmConfig, engine: str) -> None:
    """Validate the arm's URDF for ``engine`` with the config's repairs (cached per file
    version and options), before anything reads it.

    Raises:
        UrdfError: the URDF has errors.
    """
    from mjx_arm.urdf.validate import validated

    validated(config.urdf_path, engine, None, config.repair_inertia, config.default_limits())


def horizontal_reach(resolved: ResolvedArm) -> float:
    """How far (m) the ee point gets from the base's vertical axis: the 99th percentile over
    seeded random poses inside the joint limits (full-turn joints within +-pi)."""
    import mujoco

    from mjx_arm.urdf.convert import EE_SITE, load_model

    config = resolved.config.convert_config(resolved.ee_link, resolved.ft_joint)
    model = load_model(resolved.config.urdf_path, config)
    data = mujoco.MjData(model)
    adr = np.array([model.joint(n).qposadr[0] for n in resolved.joint_names])
    low = np.maximum([_range(j)[0] for j in resolved.joints], -np.pi)
    high = np.minimum([_range(j)[1] for j in resolved.joints], np.pi)
    poses = np.random.default_rng(0).uniform(low, high, (REACH_SAMPLES, len(adr)))
    site = model.site(EE_SITE).id
    radii = np.empty(REACH_SAMPLES)
    for i, q in enumerate(poses):
        data.qpos[adr] = q
        mujoco.mj_kinematics(model, data)
        radii[i] = np.hypot(*data.site_xpos[site][:2])
    return float(np.quantile(radii, REACH_QUANTILE))


class ArmMismatchError(ValueError):
    """A policy trained on one arm run on another."""


# What the model hash covers: the kinematics, masses, joints and actuators of the converted arm.
_HASHED_FIELDS = (
    "body_pos",
    "body_quat",
    "body_mass",
    "body_inertia",
    "jnt_type",
    "jnt_axis",
    "jnt_range",
    "dof_damping",
    "dof_armature",
    "actuator_gainprm",
    "actuator_forcerange",
)


def model_hash(arm: ArmInfo) -> str:
    """SHA-256 of the arm's converted MuJoCo model (no scene): joint names, then kinematics,
    masses, joints and actuators rounded to 6 significant digits, so the same arm hashes the
    same wherever its files live."""
    return _model_hash_cached(arm.config, arm.urdf.stat().st_mtime)


@functools.cache
def _model_hash_cached(config: ArmConfig, mtime: float) -> str:
    from mjx_arm.urdf.convert import load_model

    arm = arm_info(config)
    model = load_model(arm.urdf, arm.convert_config())
    digest = hashlib.sha256(",".join(arm.joint_names).encode())
    if np.any(arm.ee_offset):  # (hashes of arms at the link's origin read as before)
        digest.update(np.char.mod("%.6g", np.asarray(arm.ee_offset)).tobytes())
    if arm.grip_offset is not None and np.any(arm.grip_offset):  # Lift's ee point
        digest.update(np.char.mod("%.6g", np.asarray(arm.grip_offset)).tobytes())
    for name in _HASHED_FIELDS:
        values = np.asarray(getattr(model, name), np.float64)
        digest.update(np.char.mod("%.6g", values.ravel()).tobytes())
    return digest.hexdigest()


def arm_record(arm: ArmInfo) -> dict:
    """What a run's config and a policy file record of the arm, JSON-ready."""
    return {
        "config": arm.config.to_dict(),
        "joint_names": list(arm.joint_names),
        "ee_link": arm.ee_link,
        "v_max": arm.v_max.tolist(),
        "reach_scale": arm.reach_scale,
        "model_hash": model_hash(arm),
    }


def check_same_arm(recorded: dict | None, arm: ArmInfo, what: str = "the policy") -> None:
    """Raise :class:`ArmMismatchError` unless ``arm`` is the arm of ``recorded``
    (:func:`arm_record`); a record without a model hash (older files) checks joint names only.
    """
    if not recorded:
        recorded = {"joint_names": list(arm_info().joint_names)}  # older files: shipped arm
    names = list(recorded.get("joint_names", []))
    where = recorded.get("config", {}).get("urdf") or "the shipped arm"
    if names != list(arm.joint_names):
        raise ArmMismatchError(
            f"{what} was trained on {where} with joints {names}; this env's arm ({arm.urdf}) "
            f"has {list(arm.joint_names)}. Pass the arm it was trained on (--arm)."
        )
    expected = recorded.get("model_hash")
    if expected and expected != model_hash(arm):
        raise ArmMismatchError(
            f"{what} was trained on {where}; this env's arm ({arm.urdf}) has the same joint "
            "names but a different converted model (kinematics, masses or actuators). Pass "
            "the arm it was trained on (--arm)."
        )
