"""URDF -> MJCF through MuJoCo's own URDF importer and ``mujoco.MjSpec`` edits.

The importer does the parsing (links, joints, inertials, geometry, limits, damping). What it leaves
out is added here on the spec: joint damping and armature, velocity actuators sized from the URDF
``<limit effort velocity>``, an ``ee`` site, wrist force/torque sensors with what is needed to tare
them, MJX-ready solver options, contact filtering and, optionally, the task scene.
"""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from mjx_arm.urdf.errors import ConversionError, one_line
from mjx_arm.urdf.inertia import inertia_problem, inertia_tensor, repair_inertia
from mjx_arm.urdf.meshes import resolve_mesh_filename
from mjx_arm.urdf.model import RobotModel, parse_urdf
from mjx_arm.urdf.safe_xml import read_xml
from mjx_arm.urdf.scene import SCENES, add_scene

# Collision bit masks. Scene geoms (table, target box) never collide with each other. Arm geoms
# collide with the scene, and with each other only when self_collision is on.
ARM_CONTYPE, ARM_CONAFFINITY = 1, 3
ARM_CONAFFINITY_NO_SELF = 2
SCENE_CONTYPE, SCENE_CONAFFINITY = 2, 1

# Names the converted model always carries (the task code looks them up by name).
EE_SITE = "ee"
FT_SITE = "ft"
TOOL_COM_SITE = "tool_com"
SENSORS = (
    "ft_force",
    "ft_torque",
    "tool_acc",
    "tool_gyro",
    "tool_angacc",
    "ft_quat",
    "ee_pos",
    "ee_quat",
)


@dataclass(frozen=True)
class ConvertConfig:
    """How a URDF becomes an MJCF model. Saved with every run that uses it.

    Attributes:
        default_damping: joint damping (N m s/rad) for joints whose URDF gives none or zero.
        armature_per_effort: reflected rotor inertia added to each actuated joint, per unit of
            its URDF effort (kg m^2 per N m). Geared industrial joints carry a rotor inertia
            times the gear ratio squared, which grows with the joint's size: 0.005 gives
            0.75 kg m^2 on a 150 N m joint and 0.14 kg m^2 on a 28 N m wrist.
        kv_factor: velocity gain of each actuator as a multiple of ``I_min / sim_dt``, where
            ``I_min`` is the smallest apparent inertia ``1 / (M^-1)_jj`` of that joint over the
            joint ranges (what the joint feels when the others move freely).
            At 1.0 a substep halves the velocity error, and a torque-capped actuator cannot
            chatter: MuJoCo drops the implicit derivative of a clamped actuator, and an
            explicit step stays inside the error band while ``kv * dt / I <= 1``.
        gravity_compensation: compensate the arm's weight through its actuators (inside the
            effort limit), as an industrial arm's joint controllers do.
        ee_link: link whose frame is the end-effector point; None picks ``ee_link`` if present,
            else the deepest link of the tree.
        ft_joint: fixed joint where the wrist force/torque reading is taken; None picks
            ``ft_sensor_joint`` if present, else the joint above the end-effector body.
        sim_dt: physics time step (s).
        solver_iterations: constraint solver iterations (few, for MJX speed). On an H200 the
            Touch scene steps 1.6M physics steps/s at 4 iterations (line search 8), 3.2M at
            2 (4) and 5.0M at 1 (2), 32k envs (benchmarks/results/sweep_touch_*.json).
        ls_iterations: line-search iterations of the Newton solver.
        scene: "none", "reach" or "touch": the task scene added around the arm.
        package_dirs: ``package://NAME`` -> directory; unnamed packages are searched for upwards
            from the URDF's folder.
        repair_inertia: replace inertia tensors that break the triangle inequality (or are not
            positive definite) by the nearest valid one instead of failing.
        self_collision: let non-neighbouring arm links collide with each other. The task
            models turn it off: the tasks keep the arm near its home pose, and dropping the
            self pairs cuts MJX's contact rows from 374 to about a quarter.
    """

    default_damping: float = 1.0
    armature_per_effort: float = 0.005
    kv_factor: float = 1.0
    gravity_compensation: bool = True
    ee_link: str | None = None
    ft_joint: str | None = None
    sim_dt: float = 1.0 / 240.0
    solver_iterations: int = 2
    ls_iterations: int = 4
    scene: str = "none"
    package_dirs: Mapping[str, str] = field(default_factory=dict)
    repair_inertia: bool = False
    self_collision: bool = True

    def replace(self, **changes) -> ConvertConfig:
        """Return a copy with some fields changed."""
        return dataclasses.replace(self, **changes)


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
        engine="mujoco",
        package_dirs=config.package_dirs,
        native=False,
        repair_inertia=config.repair_inertia,
    )
    if not report.ok:
        raise ConversionError(report.format())
    try:
        return build_checked_spec(path, config)
    except ConversionError:
        raise
    except Exception as exc:  # a bug: still a named error, never a bare traceback
        raise ConversionError(
            f"{path}: the converter failed unexpectedly: {type(exc).__name__}: {exc}; "
            "report this as a bug in mjx_arm.urdf.convert"
        ) from exc


def build_checked_spec(path: Path, config: ConvertConfig) -> mujoco.MjSpec:
    """:func:`build_spec` for a URDF that already passed the static checks (the validator's
    native layer calls it). Raises ``ConversionError`` as :func:`build_spec` does."""
    if config.scene not in SCENES:
        raise ConversionError(f"unknown scene {config.scene!r}; choose one of {sorted(SCENES)}")
    model = parse_urdf(path)
    xml_text = _prepare_urdf_text(path, config)
    try:
        spec = mujoco.MjSpec.from_string(xml_text)
    except Exception as exc:  # MuJoCo raises ValueError with its own text
        raise ConversionError(f"{path}: MuJoCo's URDF importer failed: {exc}") from exc
    try:
        _edit_spec(spec, model, config, path)
    except ConversionError:
        raise
    except (ValueError, mujoco.FatalError) as exc:
        # The edits compile copies of the spec (joint inertias, tool centre of mass, contacts at
        # rest); MuJoCo's compiler reports a zero joint axis or an unreadable mesh there. Its
        # message comes first, as the validator quotes it after "MuJoCo cannot load the model:".
        raise ConversionError(f"{str(exc).rstrip()}\n(MuJoCo compiling {path})") from exc
    return spec


def _edit_spec(spec: mujoco.MjSpec, model: RobotModel, config: ConvertConfig, path: Path) -> None:
    """Apply every edit of :func:`build_spec` to the imported ``spec``, in order."""
    _set_options(spec, config)
    actuated = _edit_joints(spec, model, config, path)
    _add_actuators(spec, actuated, model, config)
    ee_body, ft_body = _tool_bodies(spec, model, config, path)
    _add_sites_and_sensors(spec, model, ee_body, ft_body, config)
    _set_contact_bits(spec, config.self_collision)
    if config.gravity_compensation:
        for body in spec.bodies[1:]:
            body.gravcomp = 1.0
    add_scene(spec, config.scene)
    _exclude_neighbours(spec, model)


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
    """Convert a URDF and compile it into a ``mujoco.MjModel`` (errors as :func:`to_mjcf`)."""
    config = (config or ConvertConfig()).replace(**overrides)
    return compile_spec(build_spec(urdf, config), urdf)


def compile_spec(spec: mujoco.MjSpec, urdf: str | Path) -> mujoco.MjModel:
    """Compile a converted spec and check that the model's numbers are finite.

    Raises:
        ConversionError: the model does not compile or holds NaN or infinite values.
    """
    try:
        model = spec.compile()
    except Exception as exc:
        raise ConversionError(f"{urdf}: the converted model does not compile: {exc}") from exc
    _check_finite(model, urdf)
    return model


def mjcf_text(spec: mujoco.MjSpec, urdf: str | Path) -> str:
    """The MJCF text of a converted spec, checked to compile again as written.

    MuJoCo writes about 6 significant digits per vector, so extreme values that compile from
    the spec can fail from the text; that is a :class:`ConversionError` here, not a broken file.
    """
    compile_spec(spec, urdf)
    text = spec.to_xml()
    try:
        mujoco.MjModel.from_xml_string(text)
    except Exception as exc:
        raise ConversionError(
            f"{urdf}: the written MJCF does not compile again (MuJoCo keeps about 6 significant "
            f"digits per vector; check the URDF for extreme values): {one_line(exc)}"
        ) from exc
    return text


# Model arrays that must be finite, with the object each row belongs to.
_FINITE_FIELDS = {
    "body_pos": mujoco.mjtObj.mjOBJ_BODY,
    "body_quat": mujoco.mjtObj.mjOBJ_BODY,
    "body_ipos": mujoco.mjtObj.mjOBJ_BODY,
    "body_mass": mujoco.mjtObj.mjOBJ_BODY,
    "body_inertia": mujoco.mjtObj.mjOBJ_BODY,
    "geom_size": mujoco.mjtObj.mjOBJ_GEOM,
    "geom_pos": mujoco.mjtObj.mjOBJ_GEOM,
    "jnt_range": mujoco.mjtObj.mjOBJ_JOINT,
    "jnt_axis": mujoco.mjtObj.mjOBJ_JOINT,
    "dof_damping": mujoco.mjtObj.mjOBJ_DOF,
    "dof_armature": mujoco.mjtObj.mjOBJ_DOF,
    "dof_frictionloss": mujoco.mjtObj.mjOBJ_DOF,
    "actuator_gainprm": mujoco.mjtObj.mjOBJ_ACTUATOR,
    "actuator_biasprm": mujoco.mjtObj.mjOBJ_ACTUATOR,
    "actuator_ctrlrange": mujoco.mjtObj.mjOBJ_ACTUATOR,
    "actuator_forcerange": mujoco.mjtObj.mjOBJ_ACTUATOR,
}


def _check_finite(model: mujoco.MjModel, urdf: str | Path) -> None:
    """Raise a ConversionError naming the first model row that holds NaN or inf."""
    for name, objtype in _FINITE_FIELDS.items():
        values = np.asarray(getattr(model, name))
        if values.size == 0:
            continue
        bad = np.flatnonzero(~np.isfinite(values.reshape(len(values), -1)).all(axis=1))
        if bad.size:
            owner = mujoco.mj_id2name(model, objtype, int(bad[0])) or f"#{int(bad[0])}"
            raise ConversionError(
                f"{urdf}: the converted model has non-finite {name} for {owner!r} (the URDF's "
                "values are too large or too small to compute with)"
            )


# --------------------------------------------------------------------------- URDF text


def _prepare_urdf_text(path: Path, config: ConvertConfig) -> str:
    """Resolve mesh paths, check inertias and tell the importer to keep every link apart."""
    root = read_xml(path)
    for mesh in root.iter("mesh"):
        link = _enclosing_link_name(root, mesh)
        mesh.set(
            "filename",
            str(resolve_mesh_filename(mesh.get("filename", ""), path, link, config.package_dirs)),
        )
    for link in root.findall("link"):
        _check_or_repair_inertia(link, path, config.repair_inertia)
    for old in root.findall("mujoco"):
        root.remove(old)
    extension = ET.Element("mujoco")
    ET.SubElement(
        extension,
        "compiler",
        {
            "fusestatic": "false",
            "discardvisual": "false",
            "strippath": "false",
            "angle": "radian",
            "autolimits": "true",
        },
    )
    root.insert(0, extension)
    return ET.tostring(root, encoding="unicode")


def _enclosing_link_name(root: ET.Element, node: ET.Element) -> str:
    for link in root.findall("link"):
        if any(n is node for n in link.iter()):
            return link.get("name", "?")
    return "?"


def _check_or_repair_inertia(link: ET.Element, path: Path, repair: bool) -> None:
    inertia = link.find("inertial/inertia")
    if inertia is None:
        return
    keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    v = {k: float(inertia.get(k, "0")) for k in keys}
    tensor = inertia_tensor(v)
    problem = inertia_problem(tensor)
    if problem is None:
        return
    name = link.get("name", "?")
    if not repair:
        raise ConversionError(
            f"{path}: link {name!r}: inertia {problem}. Fix the <inertia> values, or convert "
            "with repair_inertia=True (CLI: --repair-inertia) to raise the smaller principal "
            "moments to the nearest valid tensor."
        )
    fixed = repair_inertia(tensor)
    for key, (i, j) in zip(keys, [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)], strict=True):
        inertia.set(key, repr(float(fixed[i, j])))


# --------------------------------------------------------------------------- spec edits


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
        if lim is None or lim.effort <= 0 or lim.velocity <= 0:
            raise ConversionError(
                f"{path}: joint {urdf_joint.name!r} needs <limit effort=... velocity=...> with "
                "positive values: the velocity actuator's torque cap and speed come from them"
            )
        if not (urdf_joint.damping and urdf_joint.damping > 0):
            joint.damping[0] = config.default_damping
        joint.armature = config.armature_per_effort * lim.effort
        if config.gravity_compensation:
            joint.actgravcomp = True
        actuated.append(joint)
    if not actuated:
        raise ConversionError(f"{path}: no movable joint to actuate")
    return actuated


def _add_actuators(spec: mujoco.MjSpec, joints, model: RobotModel, config: ConvertConfig) -> None:
    inertia = _min_joint_inertia(spec, [j.name for j in joints])
    for joint in joints:
        lim = model.joints[joint.name].limit
        assert lim is not None  # checked in _edit_joints
        act = spec.add_actuator()
        act.name = joint.name
        act.target = joint.name
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        kv = config.kv_factor * inertia[joint.name] / config.sim_dt
        act.set_to_velocity(
            kv=float(np.format_float_positional(kv, precision=4, unique=False, fractional=False))
        )
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.ctrlrange = [-lim.velocity, lim.velocity]
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-lim.effort, lim.effort]


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
    shapes already touch in the reference configuration; neither is a real collision.
    """
    pairs = {tuple(sorted((j.parent, j.child))) for j in model.joints.values()}
    root = model.root_link
    first = [j.child for j in model.joints.values() if j.parent == root]
    pairs |= {tuple(sorted((root, c))) for c in first}
    pairs |= _pairs_in_contact_at_rest(spec, set(model.links))
    for body1, body2 in sorted(pairs):
        if body1 == body2:
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
