"""Validation layer 3: masses and inertia tensors, then MuJoCo's own loader (through the
converter). Each engine's load check is named by its registry row (:mod:`mjx_arm.engines`);
PyBullet's lives with that engine (:mod:`pybullet_ref.urdf_check`) and names the element a
message concerns with :func:`native_element`.
"""

from __future__ import annotations

import re
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from mjx_arm.urdf.errors import one_line
from mjx_arm.urdf.findings import _Findings, _joint, _link, _number, _Tree
from mjx_arm.urdf.inertia import inertia_problem, inertia_tensor, is_frame
from mjx_arm.urdf.readers import UrdfReader
from mjx_arm.urdf.repair import INERTIA_FIX

# --------------------------------------------------------------------------- layer 3: physics


def _check_inertials(
    tree: _Tree, readers: tuple[UrdfReader, ...], repair: bool, out: _Findings
) -> None:
    """Masses and inertia tensors: every moving link has mass, every tensor one of ``readers``
    uses is physical."""
    moving = tree.moving_links()
    for name, elem in tree.links.items():
        inertial = elem.find("inertial")
        mass = _number(inertial.find("mass") if inertial is not None else None, "value")
        if isinstance(mass, str):
            out.error(3, _link(name), f"has a non-numeric mass {mass!r}", "give the mass in kg")
            continue
        if mass is not None and mass < 0:
            out.error(3, _link(name), f"has negative mass {mass:g}", "give the mass in kg, > 0")
            continue
        if name in moving:
            _check_moving_mass(name, elem, mass or 0.0, moving[name], readers, out)
        if inertial is None:
            continue
        if not moving.get(name) and is_frame(elem):
            continue  # a massless frame on a fixed joint: nothing to check, see is_frame
        # The converter checks every <inertia>; PyBullet uses those of massive or moving links.
        if (mass or 0.0) > 0 or name in moving or any(r.checks_every_inertia for r in readers):
            _check_tensor(name, inertial, repair, needed=(mass or 0.0) > 0, out=out)


def _check_moving_mass(
    name: str,
    elem: ET.Element,
    mass: float,
    direct: bool,
    readers: tuple[UrdfReader, ...],
    out: _Findings,
) -> None:
    """A moving link needs mass; a massless frame without collision geometry is allowed, and
    so is one with collision geometry on a fixed joint: both engines keep it welded to its
    parent, its shapes collide and add no mass. PyBullet needs the mass 0 written out: for a
    link without ``<inertial>`` it invents 1 kg (MuJoCo alone does not mind)."""
    if mass > 0 or not (direct or elem.find("collision") is not None):
        return
    written = elem.find("inertial") is not None
    if not direct and (written or not any(r.invents_mass for r in readers)):
        out.warning(
            3,
            _link(name),
            "is a massless frame on a fixed joint with collision geometry: it stays welded "
            "to its parent, its shapes collide and add no mass",
            "add <inertial> with the link's mass if its shapes stand for a real part",
        )
        return
    how = "is moved by a non-fixed joint" if direct else "moves and has collision geometry"
    if elem.find("inertial") is None:
        what = "has no <inertial> (PyBullet then invents 1 kg and unit inertia)"
    else:
        what = "has mass 0"
    out.error(
        3,
        _link(name),
        f"{how} but {what}",
        "add <inertial> with the link's mass (kg > 0), centre of mass and inertia tensor",
    )


def _check_tensor(
    name: str,
    inertial: ET.Element,
    repair: bool,
    needed: bool,
    out: _Findings,
) -> None:
    inertia = inertial.find("inertia")
    if inertia is None:
        if needed:
            out.error(
                3,
                _link(name),
                "has a mass but no <inertia>",
                "add <inertia ixx iyy izz ixy ixz iyz> about the centre of mass (kg m^2)",
            )
        return
    keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    values = {k: _number(inertia, k) for k in keys}
    bad = [k for k, v in values.items() if isinstance(v, str)]
    if bad:
        out.error(3, _link(name), f"has non-numeric inertia {', '.join(bad)}", "give numbers")
        return
    v = {k: float(values[k] or 0.0) for k in keys}  # type: ignore[arg-type]
    tensor = inertia_tensor(v)
    problem = inertia_problem(tensor)
    if problem is None:
        return
    if repair and np.all(np.isfinite(tensor)):
        out.warning(
            3,
            _link(name),
            f"inertia {problem}; the repair replaces it by the nearest valid tensor in every "
            "engine",
            "correct the <inertia> values to keep the link's real dynamics",
        )
    else:
        out.error(3, _link(name), f"inertia {problem}", INERTIA_FIX)


# --------------------------------------------------------------------------- layer 3: native


def native_element(tree: _Tree, text: str) -> str:
    """The link or joint an engine's message names, else ``robot``."""
    named = re.search(r"(link|joint) '([^']+)'", text)
    if named:
        return f"{named.group(1)} {named.group(2)!r}"
    element = re.search(r"Element name '([^']+)'", text)
    candidates = [element.group(1)] if element else []
    candidates += re.findall(r"[\w.-]+", text)
    for word in candidates:
        if word in tree.joints:
            return _joint(word)
        if word in tree.links:
            return _link(word)
        link = _link_of_mesh(tree, word)
        if link:
            return _link(link)
    return "robot"


def _link_of_mesh(tree: _Tree, stem: str) -> str | None:
    for name, elem in tree.links.items():
        for mesh in elem.iter("mesh"):
            filename = Path(mesh.get("filename", ""))
            if stem in (filename.stem, filename.name):
                return name
    return None


def check_mujoco_load(
    tree: _Tree,
    package_dirs: Mapping[str, str],
    repair: bool,
    out: _Findings,
    limits: Mapping[str, float] | None = None,
) -> None:
    """The MuJoCo row's URDF load check (:mod:`mjx_arm.engines`).

    Convert with :func:`mjx_arm.urdf.convert.build_checked_spec` (with the default effort and
    velocity ``limits`` the converter will use), compile and write the MJCF
    (:func:`~mjx_arm.urdf.convert.mjcf_text`); report any failure.

    MuJoCo's own warnings (e.g. an OBJ's texture coordinates discarded) are dropped: they concern
    rendering, and MuJoCo's asset cache prints them only on the first load in a process, which
    would make the report depend on what ran before.
    """
    from mjx_arm.urdf.convert_config import ConvertConfig
    from mjx_arm.urdf.mjcf import build_checked_spec, mjcf_text

    limits = limits or {}
    config = ConvertConfig(
        package_dirs=dict(package_dirs),
        repair_inertia=repair,
        default_effort=limits.get("effort", 0.0),
        default_velocity=limits.get("velocity", 0.0),
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            mjcf_text(build_checked_spec(tree.path, config), tree.path)
        except Exception as exc:
            text = one_line(exc)
            out.error(
                3,
                native_element(tree, text),
                f"MuJoCo cannot load the model: {text}",
                "correct the element MuJoCo names (see the message)",
            )
