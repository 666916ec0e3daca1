"""Validation layer 3: masses and inertia tensors, then the engines' own loaders (MuJoCo through
the converter, PyBullet in this process, after the static checks that keep it from crashing).
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import re
import sys
import tempfile
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np

from mjx_arm.urdf.errors import one_line
from mjx_arm.urdf.findings import _Findings, _joint, _link, _number, _Tree
from mjx_arm.urdf.inertia import inertia_problem, inertia_tensor, is_frame
from mjx_arm.urdf.meshes import (
    AssetPathError,
    resolve_asset,
)
from mjx_arm.urdf.readers import UrdfReader
from mjx_arm.urdf.repair import INERTIA_FIX, UrdfRepairs, repair_tree

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


def _native_element(tree: _Tree, text: str) -> str:
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
                _native_element(tree, text),
                f"MuJoCo cannot load the model: {text}",
                "correct the element MuJoCo names (see the message)",
            )


@contextlib.contextmanager
def _captured_fds() -> Iterator[list[str]]:
    """Send C-level stdout and stderr to a temporary file; the yielded list gets the text.

    This swaps the process's file descriptors 1 and 2, so it is not safe to use from two threads
    at once.
    """
    captured: list[str] = []
    _flush_all()
    with tempfile.TemporaryFile() as tmp:
        saved = os.dup(1), os.dup(2)
        try:
            os.dup2(tmp.fileno(), 1)
            os.dup2(tmp.fileno(), 2)
            yield captured
        finally:
            _flush_all()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
            tmp.seek(0)
            captured.append(tmp.read().decode("utf-8", errors="replace"))


def _flush_all() -> None:
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    with contextlib.suppress(Exception):
        ctypes.CDLL(None).fflush(None)


def _absolute_mesh_copy(
    tree: _Tree, package_dirs: Mapping[str, str], folder: str, repairs: UrdfRepairs
) -> Path:
    """Write the URDF with absolute mesh and texture paths (PyBullet knows no package_dirs) and
    ``repairs`` applied (:mod:`mjx_arm.urdf.repair`: what the PyBullet env loads).

    A filename that does not resolve inside its folder loses its ``filename`` (PyBullet then
    opens nothing for it); the static checks report such meshes and textures before this runs.
    """
    root = ET.fromstring(ET.tostring(tree.root))
    repair_tree(root, repairs)
    for elem in [*root.iter("mesh"), *root.iter("texture")]:
        filename = elem.get("filename")
        if filename is None:
            continue
        try:
            elem.set("filename", str(resolve_asset(filename, tree.path, package_dirs)))
        except AssetPathError:
            del elem.attrib["filename"]
    copy = Path(folder) / tree.path.name
    copy.write_bytes(ET.tostring(root, encoding="utf-8"))
    return copy


def check_pybullet_load(
    tree: _Tree,
    package_dirs: Mapping[str, str],
    repair: bool,
    out: _Findings,
    limits: Mapping[str, float] | None = None,
) -> None:
    """The PyBullet row's URDF load check (:mod:`mjx_arm.engines`): :func:`_load_pybullet` of
    the URDF with the repairs of ``repair`` and ``limits`` (the default effort and velocity),
    as the PyBullet env loads it."""
    _load_pybullet(tree, package_dirs, out, UrdfRepairs.from_limits(repair, limits))


def _load_pybullet(
    tree: _Tree, package_dirs: Mapping[str, str], out: _Findings, repairs: UrdfRepairs
) -> None:
    """Load into a private DIRECT PyBullet client with its C output captured; report problems.

    PyBullet runs in this process (it segfaults on some broken trees, which is why this layer only
    runs after the static checks passed). Its ``b3Warning`` messages become warnings.
    """
    with tempfile.TemporaryDirectory() as folder:
        copy = _absolute_mesh_copy(tree, package_dirs, folder, repairs)
        failure = None
        with _captured_fds() as captured:
            failure = _pybullet_load_file(str(copy))
        text = captured[0].replace(str(copy), str(tree.path)).replace(folder, str(tree.path.parent))
    messages = _attach_names(_bullet_messages(text), tree)
    if failure is not None:
        detail = one_line(" ".join([failure, *messages]))
        out.error(
            3,
            _native_element(tree, detail),
            f"PyBullet cannot load the file: {detail}",
            "correct the element PyBullet names (see the message)",
        )
        return
    for message in messages:
        out.warning(
            3,
            _native_element(tree, message),
            f"PyBullet warns: {message}",
            "check the element PyBullet names",
        )


def _pybullet_load_file(path: str) -> str | None:
    """Load ``path`` in a fresh DIRECT client (always disconnected); return error text or None."""
    client = None
    try:
        import pybullet
        from pybullet_utils import bullet_client

        client = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
        client.loadURDF(path, flags=pybullet.URDF_USE_INERTIA_FROM_FILE)
        return None
    except Exception as exc:
        return str(exc) or type(exc).__name__
    finally:
        if client is not None:
            with contextlib.suppress(Exception):
                client.disconnect()


def _bullet_messages(text: str) -> list[str]:
    """The b3Warning / b3Error messages of PyBullet's output, deduplicated, in order."""
    parts = re.findall(
        r"b3(?:Warning|Error)\[[^\]]*\]:\s*(.*?)(?=b3\w+\[|pybullet build time|"
        r"argv\[0\]|\Z)",
        text,
        flags=re.DOTALL,
    )
    messages: list[str] = []
    for part in parts:
        message = " ".join(part.split())
        if message and message not in messages:
            messages.append(message)
    return messages


def _attach_names(messages: list[str], tree: _Tree) -> list[str]:
    """PyBullet prints some link names as a message of their own: join them to the one before."""
    out: list[str] = []
    for message in messages:
        if out and (message in tree.links or message in tree.joints):
            out[-1] = f"{out[-1]}: {message!r}"
        else:
            out.append(message)
    return out
