"""Special files where a file is expected: a FIFO, a character device (``/dev/zero``,
``/dev/urandom``, by path or through a link), a socket, a folder, and links (to a device, to a
file outside the folder, dangling, in a loop).

:func:`make_special` puts one at a path; :func:`special_input` makes an input slot of any kind
special, the file itself or a part of it: an arm file's URDF, a run directory's member
(``config.json``, ``metrics.csv``, a checkpoint's ``meta.json``, ``.lock``, ...). The meshes and
their side files are made special by :mod:`input_fuzz.hostile_mesh`. A reader that opens a FIFO
blocks until a writer comes (forever), one that reads a device never reaches its end; the harness
(:mod:`input_fuzz.harness`) counts either as a hang or running out of memory.
"""

from __future__ import annotations

import os
import re
import shutil
import socket
from pathlib import Path

import numpy as np

from input_fuzz.hostile_npz import pick

# How a path is made special; "device_path" is the device's own path (an argument, or a name
# written into the file that refers to it), the others are made at the path.
SPECIALS = (
    "fifo",
    "fifo",
    "zero_link",
    "urandom_link",
    "device_path",
    "socket",
    "folder",
    "outside_link",
    "dangling_link",
    "link_loop",
)
DEVICES = ("/dev/zero", "/dev/urandom")
OUTSIDE = ("/etc/passwd", "/etc/hostname", "/proc/self/status")
# Members of a run directory made special (relative to it; STEP: the newest checkpoint).
RUN_MEMBERS = (
    "config.json",
    "config.json",
    "metrics.csv",
    "metrics.csv",
    "STEP/meta.json",
    "STEP/meta.json",
    ".lock",
    ".mjx_arm_run",
    "STEP/transitions.npz",
    "STEP/params",
    "checkpoints",
    "",  # the run directory itself
)


def _socket(path: Path) -> None:
    """A Unix socket file at ``path`` (bound from its folder: the name limit is 107 bytes)."""
    here = os.getcwd()
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        os.chdir(path.parent)
        sock.bind(path.name)
    finally:
        os.chdir(here)
        sock.close()


def _remove(path: Path) -> None:
    if path.is_symlink() or path.is_file() or (path.exists() and not path.is_dir()):
        path.unlink()
    elif path.is_dir():
        shutil.rmtree(path)


def make_special(path: Path, how: str, rng: np.random.Generator, outside: Path | None = None):
    """Replace whatever is at ``path`` by a special file of kind ``how`` (:data:`SPECIALS`;
    "device_path" makes a link to a device here). ``outside``: a good file outside the folder
    that an outside link may point to (else a system file). Returns what it made, in words."""
    _remove(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if how == "fifo":
        os.mkfifo(path)
        return "a FIFO"
    if how in ("zero_link", "urandom_link", "device_path"):
        device = {"zero_link": "/dev/zero", "urandom_link": "/dev/urandom"}.get(how)
        device = device or pick(rng, DEVICES)
        path.symlink_to(device)
        return f"a link to {device}"
    if how == "socket":
        _socket(path)
        return "a socket"
    if how == "folder":
        path.mkdir()
        return "a folder"
    if how == "outside_link":
        target = outside if outside is not None and rng.random() < 0.5 else pick(rng, OUTSIDE)
        path.symlink_to(target)
        return f"a link to {'a good file outside' if target == outside else target}"
    if how == "dangling_link":
        path.symlink_to(path.with_name(path.name + ".gone"))
        return "a dangling link"
    other = path.with_name(path.name + ".loop")
    _remove(other)
    other.symlink_to(path.name)
    path.symlink_to(other.name)
    return "a link loop"


def special_file(good: Path, out: Path, rng: np.random.Generator) -> tuple[Path, str]:
    """The input path of a special file of ``good``'s kind: ``/dev/zero`` itself, or a special
    file made at ``out``; and ``kind`` for the label."""
    how = pick(rng, SPECIALS)
    if how == "device_path":
        device = pick(rng, DEVICES)
        return Path(device), f"path={device}"
    make_special(out, how, rng, outside=good)
    return out, f"self={how}"


def special_arm_urdf(good: Path, out: Path, rng: np.random.Generator) -> tuple[Path, str]:
    """An arm file (TOML or JSON, as ``good``) whose ``urdf`` names a special file."""
    how = pick(rng, SPECIALS)
    target = out.with_name(out.stem + "_urdf.urdf")
    if how == "device_path":
        target = Path(pick(rng, DEVICES))
    else:
        make_special(target, how, rng)
    text = good.read_text()
    quoted = f'"{target}"'
    text, count = re.subn(r'("?urdf"?\s*[=:]\s*)"[^"]*"', lambda m: m.group(1) + quoted, text)
    out.write_text(text)
    return out, f"urdf={how}" if count else "self=unchanged"


def special_run_dir(good: Path, out: Path, rng: np.random.Generator) -> tuple[Path, str]:
    """A copy of the run directory ``good`` with one member special (:data:`RUN_MEMBERS`), or
    the run directory itself special."""
    member = pick(rng, RUN_MEMBERS)
    how = pick(rng, SPECIALS)
    if member == "":
        path, label = special_file(good, out, rng)
        return path, f"run_dir:{label}"
    shutil.copytree(good, out)
    step = sorted((out / "checkpoints").glob("step_*"))[-1].name
    target = out / member.replace("STEP", f"checkpoints/{step}")
    outside = good / target.relative_to(out)
    make_special(target, how, rng, outside=outside if outside.exists() else None)
    return out, f"{member.replace('STEP/', '')}={how}"


def special_input(kind: str, good: Path, out: Path, rng: np.random.Generator):
    """The path of a special input of ``kind`` made from the good file ``good`` at ``out``
    (or a device path), and what is special, as ``part=how``."""
    if kind == "run_dir":
        return special_run_dir(good, out, rng)
    if kind in ("arm_file", "arm_json") and rng.random() < 0.3:
        return special_arm_urdf(good, out, rng)
    return special_file(good, out, rng)
