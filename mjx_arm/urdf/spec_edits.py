"""What the converter adds on MuJoCo's imported ``MjSpec``: solver options, joint damping and
armature, velocity actuators, the ee and F/T sites and sensors, contact filtering.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

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
from mjx_arm.urdf.errors import ConversionError
from mjx_arm.urdf.model import RobotModel
from mjx_arm.urdf.pad_fit import PAD_GEOM_SUFFIX


def _set_options(spec: mujoco.MjSpec, config: ConvertConfig) -> None:
    spec.option.timestep = config.sim_dt
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_EULERDAMP
    # A diverging simulation must show as a non-finite state that the envs flag: MuJoCo's
    # automatic reset would silently put the arm back at qpos0 (all joints at 0) instead.
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_AUTORESET
    spec.option.iterations = config.solver_iterations
    spec.option.ls_iterations = config.ls_iterations
    spec.compiler.autolimits = True


def _edit_joints(spec: mujoco.MjSpec, model: RobotModel, config: ConvertConfig, path: Path):
    """Inject damping and armature; return the actuated spec joints in URDF tree order.

    A ``<mimic>`` joint gets damping (and armature when it has an effort limit) but no actuator:
    MuJoCo's importer already ties it to the joint it copies with a joint equality.
    """
    actuated = []
    for urdf_joint in model.actuated_joints:
        joint = spec.joint(urdf_joint.name)
        if joint is None:
            raise ConversionError(f"{path}: joint {urdf_joint.name!r} missing after import")
        lim = urdf_joint.limit
        if urdf_joint.mimic is not None:
            if not (urdf_joint.damping and urdf_joint.damping > 0):
                joint.damping[0] = config.default_damping
            if lim is not None and lim.effort > 0:
                joint.armature = config.armature_per_effort * lim.effort
            continue
        effort, velocity = effort_velocity(urdf_joint, config)
        if effort <= 0 or velocity <= 0:
            raise ConversionError(
                f"{path}: joint {urdf_joint.name!r} needs <limit effort=... velocity=...> with "
                "positive values: the velocity actuator's torque cap and speed come from them"
            )
        if not (urdf_joint.damping and urdf_joint.damping > 0):
            joint.damping[0] = config.default_damping
        joint.armature = config.armature_per_effort * effort
        if config.gravity_compensation:
            joint.actgravcomp = True
        actuated.append(joint)
    if not actuated:
        raise ConversionError(f"{path}: no movable joint to actuate")
    return actuated


def effort_velocity(urdf_joint, config: ConvertConfig) -> tuple[float, float]:
    """A joint's effort and velocity limits, the configured defaults where it gives none."""
    lim = urdf_joint.limit
    effort = lim.effort if lim is not None and lim.effort > 0 else config.default_effort
    velocity = lim.velocity if lim is not None and lim.velocity > 0 else config.default_velocity
    return effort, velocity


def _add_actuators(spec: mujoco.MjSpec, joints, model: RobotModel, config: ConvertConfig) -> None:
    inertia = _min_joint_inertia(spec, [j.name for j in joints])
    caps = dict(config.effort_caps)
    for joint in joints:
        effort, velocity = effort_velocity(model.joints[joint.name], config)
        effort = min(effort, caps.get(joint.name, effort))
        act = spec.add_actuator()
        act.name = joint.name
        act.target = joint.name
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        kv = config.kv_factor * inertia[joint.name] / (config.servo_dt or config.sim_dt)
        act.set_to_velocity(
            kv=float(np.format_float_positional(kv, precision=4, unique=False, fractional=False))
        )
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.ctrlrange = [-velocity, velocity]
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-effort, effort]


def _min_joint_inertia(spec: mujoco.MjSpec, names: list[str], samples: int = 256) -> dict:
    """Smallest apparent inertia ``1 / (M^-1)_jj`` per joint (kg m^2) over random poses.

    Poses are drawn with a fixed seed inside the joint ranges (within +-pi), so the result, and
    the converted file, is the same on every run.
    """
    model = spec.copy().compile()
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    low = np.maximum(model.jnt_range[:, 0], -np.pi)
    high = np.minimum(model.jnt_range[:, 1], np.pi)
    unlimited = ~model.jnt_limited.astype(bool)
    low[unlimited], high[unlimited] = -np.pi, np.pi
    dofs = {n: model.jnt_dofadr[model.joint(n).id] for n in names}
    best = {n: np.inf for n in names}
    full = np.zeros((model.nv, model.nv))
    for _ in range(samples):
        data.qpos[:] = model.qpos0
        for j in range(model.njnt):
            if int(model.jnt_type[j]) in (
                int(mujoco.mjtJoint.mjJNT_HINGE),
                int(mujoco.mjtJoint.mjJNT_SLIDE),
            ):
                data.qpos[model.jnt_qposadr[j]] = rng.uniform(low[j], high[j])
        mujoco.mj_forward(model, data)
        mujoco.mj_fullM(model, data, full)
        apparent = 1.0 / np.diag(np.linalg.inv(full))  # inertia felt with the other joints free
        for n, dof in dofs.items():
            best[n] = min(best[n], float(apparent[dof]))
    return best


def _tool_bodies(spec: mujoco.MjSpec, model: RobotModel, config: ConvertConfig, path: Path):
    """Return (end-effector body, force/torque body) of the spec."""
    ee_link = config.ee_link or ("ee_link" if "ee_link" in model.links else _deepest_link(model))
    if ee_link not in model.links:
        raise ConversionError(f"{path}: ee_link {ee_link!r} is not a link of this URDF")
    ft_joint = config.ft_joint or ("ft_sensor_joint" if "ft_sensor_joint" in model.joints else None)
    if ft_joint is not None:
        if ft_joint not in model.joints:
            raise ConversionError(f"{path}: ft_joint {ft_joint!r} is not a joint of this URDF")
        ft_link = model.joints[ft_joint].child
    else:
        # the child of the last movable joint above the end-effector
        chain = [j for j in model.chain_to(ee_link) if j.movable]
        ft_link = chain[-1].child if chain else ee_link
    return spec.body(ee_link), spec.body(ft_link)


def _deepest_link(model: RobotModel) -> str:
    return max(model.links, key=lambda name: (len(model.chain_to(name)), name))


def _add_sites_and_sensors(spec, model: RobotModel, ee_body, ft_body, config) -> None:
    """The ``ee`` site, the F/T site at the wrist and the sensors that tare the reading.

    ``ee_pos`` and ``ee_quat`` give the end-effector pose (a batched C backend reads only
    sensors). The force and torque sensors measure what the arm exerts on the tool subtree at
    the ``ft`` site. The accelerometer at the subtree's centre of mass, the gyro and the angular
    acceleration sensor give what the tool's own weight and inertia contribute, so the task code
    can remove it (see :mod:`mjx_arm.task.wrench`). ``tool_angacc`` (a frame sensor) is in the
    world frame; ``ft_quat`` rotates it into the sensor frame.
    """
    ee = ee_body.add_site()
    ee.name = EE_SITE
    ee.pos = list(config.ee_offset)
    ee.size = [0.008, 0, 0]
    ee.rgba = [0.1, 0.8, 0.1, 0.6]
    ee.group = 4
    ft = ft_body.add_site()
    ft.name = FT_SITE
    ft.size = [0.01, 0, 0]
    ft.group = 4
    com = ft_body.add_site()
    com.name = TOOL_COM_SITE
    com.pos = _subtree_com_in_body(spec, ft_body.name)
    com.size = [0.005, 0, 0]
    com.group = 4
    sensor_table = {  # name: (type, site)
        "ft_force": (mujoco.mjtSensor.mjSENS_FORCE, FT_SITE),
        "ft_torque": (mujoco.mjtSensor.mjSENS_TORQUE, FT_SITE),
        "tool_acc": (mujoco.mjtSensor.mjSENS_ACCELEROMETER, TOOL_COM_SITE),
        "tool_gyro": (mujoco.mjtSensor.mjSENS_GYRO, FT_SITE),
        "tool_angacc": (mujoco.mjtSensor.mjSENS_FRAMEANGACC, FT_SITE),
        "ee_pos": (mujoco.mjtSensor.mjSENS_FRAMEPOS, EE_SITE),
        "ft_quat": (mujoco.mjtSensor.mjSENS_FRAMEQUAT, FT_SITE),
        "ee_quat": (mujoco.mjtSensor.mjSENS_FRAMEQUAT, EE_SITE),
    }
    for name in SENSORS:
        sensor = spec.add_sensor()
        sensor.name = name
        sensor.type, sensor.objname = sensor_table[name]
        sensor.objtype = mujoco.mjtObj.mjOBJ_SITE


PAD_MARGIN = 0.002  # m: the touch zone reaches this far past a pad's collision box


def pad_sensor(link: str) -> str:
    """Name of the touch sensor of pad link ``link``."""
    return f"{link}_touch"


def _add_pad_sensors(spec: mujoco.MjSpec, config: ConvertConfig, path: Path) -> None:
    """A touch sensor on each of ``config.pad_links``: a box site :data:`PAD_MARGIN` larger
    than the link's collision primitives (one box around them all, in the link's frame: boxes,
    and the boxes around spheres, capsules and cylinders), so every
    contact on the pad counts (MuJoCo's touch sensor sums the normal forces of the body's
    contacts inside its site). A link with a fitted pad box (:mod:`mjx_arm.urdf.pad_fit`) gets
    that box, turned as it is, as its site: a one-jaw gripper's hand carries its palm beside
    it."""
    for link in config.pad_links:
        body = spec.body(link)
        geoms = body.geoms if body is not None else []
        boxes = [g for g in geoms if int(g.type) in _PAD_SHAPES and g.contype]
        fitted = [g for g in boxes if g.name == f"{link}{PAD_GEOM_SUFFIX}"]
        if not boxes:
            raise ConversionError(
                f"{path}: pad link {link!r} needs a collision shape (a box, sphere, capsule or "
                "cylinder, or a mesh the gripper's pads are fitted to)"
            )
        site = body.add_site()
        site.name = f"{link}_pad"
        site.type = mujoco.mjtGeom.mjGEOM_BOX
        if fitted:  # the fitted box itself, turned as it is (PyBullet counts the same zone)
            site.pos, site.quat = list(fitted[0].pos), list(fitted[0].quat)
            site.size = list(np.asarray(fitted[0].size, float) + PAD_MARGIN)
        else:
            low, high = _boxes_extent(boxes)
            site.pos = list(0.5 * (low + high))
            site.size = list(0.5 * (high - low) + PAD_MARGIN)
        site.group = 4
        sensor = spec.add_sensor()
        sensor.name = pad_sensor(link)
        sensor.type = mujoco.mjtSensor.mjSENS_TOUCH
        sensor.objtype, sensor.objname = mujoco.mjtObj.mjOBJ_SITE, site.name


# The pad shapes a touch site can be put around (a cylinder pad is a capsule by then).
_PAD_SHAPES = {
    int(mujoco.mjtGeom.mjGEOM_BOX),
    int(mujoco.mjtGeom.mjGEOM_SPHERE),
    int(mujoco.mjtGeom.mjGEOM_CAPSULE),
    int(mujoco.mjtGeom.mjGEOM_CYLINDER),
}


def _half_extent(geom) -> np.ndarray:
    """Half sizes ``(3,)`` of the box around a spec geom in its own frame: a box's size, a
    sphere's radius, a capsule's or cylinder's radius across and half length (and radius)
    along its z."""
    size = np.asarray(geom.size, float)
    if int(geom.type) == int(mujoco.mjtGeom.mjGEOM_BOX):
        return size
    if int(geom.type) == int(mujoco.mjtGeom.mjGEOM_SPHERE):
        return np.full(3, size[0])
    cap = size[0] if int(geom.type) == int(mujoco.mjtGeom.mjGEOM_CAPSULE) else 0.0
    return np.array([size[0], size[0], size[1] + cap])


def _boxes_extent(boxes) -> tuple[np.ndarray, np.ndarray]:
    """Corners ``(3,)`` low and high of the axis-aligned box (in the body's frame) around
    spec geoms (:data:`_PAD_SHAPES`), each placed by its ``pos`` and ``quat``."""
    signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
    corners = []
    for box in boxes:
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, np.asarray(box.quat, float))
        local = signs * _half_extent(box)
        corners.append(np.asarray(box.pos, float) + local @ rot.reshape(3, 3).T)
    points = np.concatenate(corners)
    return points.min(axis=0), points.max(axis=0)


def _subtree_com_in_body(spec: mujoco.MjSpec, body_name: str) -> list[float]:
    """Centre of mass of a body's subtree, in that body's frame (m), from a compiled copy."""
    model = spec.copy().compile()
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    body = model.body(body_name).id
    world = data.subtree_com[body] - data.xpos[body]
    local = data.xmat[body].reshape(3, 3).T @ world
    return [float(v) for v in np.round(local, 12)]


def _set_contact_bits(spec: mujoco.MjSpec, self_collision: bool) -> None:
    """Arm collision geoms get the arm's bit masks and are hidden in renders (group 3)."""
    for geom in spec.geoms:
        if geom.contype or geom.conaffinity:
            geom.contype = ARM_CONTYPE
            geom.conaffinity = ARM_CONAFFINITY if self_collision else ARM_CONAFFINITY_NO_SELF
            geom.group = 3


def _exclude_neighbours(spec: mujoco.MjSpec, model: RobotModel) -> None:
    """Exclude contacts between links joined by a joint and between links touching at rest.

    Neighbouring links overlap at their joint by construction, and so do links whose collision
    shapes already touch in the reference configuration; neither is a real collision. A pair
    with MuJoCo's world body is never excluded, even where the URDF names its root link
    ``world``: the scene (table, box) lives in that body, so such a pair would let a link pass
    through the table (the xArm6's fingers, which reach below the table top at all-zero
    angles, did). Links welded to the world never collide with it anyway.
    """
    world = spec.worldbody.name
    pairs = {tuple(sorted((j.parent, j.child))) for j in model.joints.values()}
    root = model.root_link
    first = [j.child for j in model.joints.values() if j.parent == root]
    pairs |= {tuple(sorted((root, c))) for c in first}
    pairs |= _pairs_in_contact_at_rest(spec, set(model.links))
    for body1, body2 in sorted(pairs):
        if body1 == body2 or world in (body1, body2):
            continue
        exclude = spec.add_exclude()
        exclude.bodyname1 = body1
        exclude.bodyname2 = body2


def _pairs_in_contact_at_rest(spec: mujoco.MjSpec, arm_links: set[str]) -> set[tuple[str, str]]:
    model = spec.copy().compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    found = set()
    for contact in data.contact[: data.ncon]:
        b1 = model.body(model.geom_bodyid[contact.geom1]).name
        b2 = model.body(model.geom_bodyid[contact.geom2]).name
        if b1 in arm_links and b2 in arm_links:
            found.add(tuple(sorted((b1, b2))))
    return found
