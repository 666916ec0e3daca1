"""A checked URDF into an edited ``MjSpec``, a compiled model and MJCF text (no validation:
:mod:`mjx_arm.urdf.convert` validates first).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np

from mjx_arm.urdf.collision_fit import fit_collision_primitives, fit_pads
from mjx_arm.urdf.convert_config import ConvertConfig
from mjx_arm.urdf.errors import ConversionError, one_line
from mjx_arm.urdf.inertia import inertia_problem
from mjx_arm.urdf.mesh_convert import CONVERTIBLE_FORMATS, MeshConvertError, convert_mesh
from mjx_arm.urdf.meshes import (
    MUJOCO_MESH_FORMATS,
    existing_mesh,
    resolve_mesh_filename,
)
from mjx_arm.urdf.model import RobotModel, parse_urdf
from mjx_arm.urdf.repair import INERTIA_FIX, UrdfRepairs, inertial_links, link_tensor, repair_tree
from mjx_arm.urdf.safe_xml import read_xml
from mjx_arm.urdf.scene import add_scene
from mjx_arm.urdf.scene_shapes import SCENES, SceneSpec
from mjx_arm.urdf.spec_edits import (
    _add_actuators,
    _add_pad_sensors,
    _add_sites_and_sensors,
    _edit_joints,
    _exclude_neighbours,
    _set_contact_bits,
    _set_options,
    _tool_bodies,
)


def build_checked_spec(path: Path, config: ConvertConfig) -> mujoco.MjSpec:
    """``mjx_arm.urdf.convert.build_spec`` for a URDF that already passed the static checks
    (the validator's native layer calls it). Raises ``ConversionError`` as that does."""
    if not isinstance(config.scene, SceneSpec):
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
    """Apply every converter edit to the imported ``spec``, in order."""
    _set_options(spec, config)
    actuated = _edit_joints(spec, model, config, path)
    _add_actuators(spec, actuated, model, config)
    ee_body, ft_body = _tool_bodies(spec, model, config, path)
    _add_sites_and_sensors(spec, model, ee_body, ft_body, config)
    fit_pads(spec, config.pads)
    fit_collision_primitives(spec, config.collision)
    _set_contact_bits(spec, config.self_collision)
    if config.gravity_compensation:
        for body in spec.bodies[1:]:
            body.gravcomp = 1.0
    add_scene(spec, config.scene)
    _add_pad_sensors(spec, config, path)
    _exclude_neighbours(spec, model)


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
        message = one_line(exc)
        raise ConversionError(
            f"{urdf}: the written MJCF does not compile again: {message}; {_reread_fix(message)}"
        ) from exc
    return text


def _reread_fix(message: str) -> str:
    """How to fix a URDF whose written MJCF MuJoCo refuses, from MuJoCo's ``message``."""
    if "DEPTH_EXCEEDED" in message or "nesting is too deep" in message:
        return "the kinematic chain is too deep for MuJoCo's XML reader: shorten it"
    return (
        "MuJoCo keeps about 6 significant digits per vector: check the URDF for extreme values "
        "(an inertia on the edge of the triangle inequality is moved inside it by "
        "--repair-inertia)"
    )


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
    """Resolve mesh paths (converting collision meshes MuJoCo cannot read), check inertias and
    tell the importer to keep every link apart."""
    root = read_xml(path)
    _drop_unreadable_visuals(root)
    repair_tree(root, UrdfRepairs.of(config))  # the same edits PyBullet's copy gets
    for mesh in root.iter("mesh"):
        link = _enclosing_link_name(root, mesh)
        mesh.set("filename", str(_mesh_path(mesh.get("filename", ""), path, link, config)))
    for link in inertial_links(root):  # massless frames welded to a parent are left out
        _check_inertia(link, path)
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


def _drop_unreadable_visuals(root: ET.Element) -> None:
    """Remove ``<visual>`` elements whose mesh MuJoCo cannot read (Collada, ...): they only
    draw, and the validator reports each as a warning. Collision meshes in such a format are
    converted to STL instead (:func:`_mesh_path`)."""
    for link in root.findall("link"):
        for visual in link.findall("visual"):
            mesh = visual.find("geometry/mesh")
            suffix = Path(mesh.get("filename", "")).suffix.lower() if mesh is not None else ""
            if mesh is not None and suffix not in MUJOCO_MESH_FORMATS:
                link.remove(visual)


def _mesh_path(filename: str, path: Path, link: str, config: ConvertConfig) -> Path:
    """The mesh file MuJoCo reads for ``filename``: the file itself, or, for a format MuJoCo
    cannot read and trimesh can, its STL conversion in the mesh cache.

    Raises:
        ConversionError: the mesh is missing, outside its folders, unreadable for MuJoCo
            (with ``convert_meshes`` off or a format trimesh does not read), or cannot be
            converted.
    """
    suffix = Path(filename).suffix.lower()
    convert = suffix not in MUJOCO_MESH_FORMATS and suffix in CONVERTIBLE_FORMATS
    if not (config.convert_meshes and convert):
        return resolve_mesh_filename(filename, path, link, config.package_dirs)
    source = existing_mesh(filename, path, link, config.package_dirs)
    try:
        return convert_mesh(source, config.mesh_cache_dir)
    except MeshConvertError as exc:
        raise ConversionError(f"{path}: link {link!r}: mesh {exc}") from exc


def _enclosing_link_name(root: ET.Element, node: ET.Element) -> str:
    for link in root.findall("link"):
        if any(n is node for n in link.iter()):
            return link.get("name", "?")
    return "?"


def _check_inertia(link: ET.Element, path: Path) -> None:
    """Raise a ConversionError for a link whose (repaired, where asked) inertia is not valid."""
    problem = inertia_problem(link_tensor(link))
    if problem is not None:
        raise ConversionError(
            f"{path}: link {link.get('name', '?')!r}: inertia {problem}. Fix: {INERTIA_FIX}."
        )
