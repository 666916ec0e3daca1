"""PyBullet's URDF load check, the one its registry row names (:mod:`pybullet_ref.engine`).

The URDF is written again with absolute mesh paths (PyBullet knows no ``package://`` folders)
and the repairs the PyBullet env applies, then loaded into a private DIRECT client in this
process with its C output captured: PyBullet can crash the process on some broken trees, so
the validator runs this only after the static checks passed. Its ``b3Warning`` messages
become warnings, a failed load an error, each placed on the link or joint it names.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import re
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Mapping
from pathlib import Path

from mjx_arm.urdf.check_physics import native_element
from mjx_arm.urdf.errors import one_line
from mjx_arm.urdf.findings import _Findings, _Tree
from mjx_arm.urdf.meshes import AssetPathError, resolve_asset
from mjx_arm.urdf.repair import UrdfRepairs, repair_tree

__all__ = ["check_pybullet_load"]


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
            native_element(tree, detail),
            f"PyBullet cannot load the file: {detail}",
            "correct the element PyBullet names (see the message)",
        )
        return
    for message in messages:
        out.warning(
            3,
            native_element(tree, message),
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
