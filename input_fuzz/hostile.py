"""Structure-aware hostile mutations of the text inputs and run directories; the ``.npz`` and
ONNX ones are in :mod:`input_fuzz.hostile_npz` and :mod:`input_fuzz.hostile_onnx`.

- arm files (``.toml``, ``.json``) and config files (a training config, a run's
  ``config.json``, a checkpoint's ``meta.json``): a value of the wrong type, unknown keys, a huge
  number, deep nesting, a 100,000-character string, thousands of keys (:func:`hostile_table`);
- URDFs: names at, just under and over :data:`MAX_NAME_CHARS` up to 100,000 characters,
  non-ASCII names, a chain of 500+ links and joints, huge mesh references (:data:`URDF_EDITS`);
- run directories: a damaged ``resume.npz``/``env_state.npz``/``transitions.npz``, a damaged
  orbax params folder, a hostile ``config.json`` or ``meta.json`` (:func:`hostile_run_dir`).

Each public mutation is ``(good file, output path, rng) -> description``.
"""

from __future__ import annotations

import json
import re
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np

from input_fuzz.hostile_npz import NPZ_MUTATIONS, pick
from mjx_arm.urdf.findings import MAX_NAME_CHARS  # the limit the lengths probe, either side

NAME_LENGTHS = (MAX_NAME_CHARS - 1, MAX_NAME_CHARS, MAX_NAME_CHARS + 1, 1000, 100_000)
CHAIN_LENGTHS = (500, 511, 512, 513, 600, 2000)
NESTING = (100, 1000, 5000, 100_000)

# --------------------------------------------------------------------------- tables


def _value_text(fmt: str, rng: np.random.Generator) -> tuple[str, str]:
    """(a hostile value as JSON or TOML text, ``kind: what it is``)."""
    op = pick(rng, ("type", "type", "huge", "nesting", "long", "inline"))
    if op == "huge":
        text = pick(rng, ("9" * 400, "1e308", "-1e308", "1e400", str(2**64), "-" + "9" * 50))
        if fmt == "toml" and "e400" in text:
            text = "inf"
        return text, f"huge: {text[:12]}"
    if op == "nesting":
        depth = int(pick(rng, NESTING))
        return "[" * depth + "]" * depth, f"nesting: {depth} deep"
    if op == "long":
        return json.dumps("x" * 100_000), "long: a 100,000-character string"
    if op == "inline":
        text = '{"a": {"b": [1, 2]}}' if fmt == "json" else "{a = {b = [1, 2]}}"
        return text, "type: a table"
    text = pick(rng, ("true", '"1.0"', "[]", "[1, 2]", '["a"]', "0", "-1", '""', '"../../etc"'))
    return text, f"type: {text}"


def hostile_table_text(data: dict, fmt: str, rng: np.random.Generator) -> tuple[str, str]:
    """``data`` (a loaded table) as ``fmt`` ("json"/"toml") text with one hostile edit: a
    real or unknown key given a hostile value, or thousands of unknown keys; and what it is
    (``kind: ...``, the kind one of type, huge, nesting, long, unknown_keys)."""
    value, what = _value_text(fmt, rng)
    keys = list(data) or ["x"]
    op = pick(rng, ("real", "real", "real", "unknown", "many"))
    lines = {k: json.dumps(v) for k, v in data.items() if not isinstance(v, dict)}
    if op == "many":
        lines.update({f"no_such_key_{i}": "1" for i in range(20_000)})
        what = "unknown_keys: 20,000 of them"
    else:
        key = str(pick(rng, keys)) if op == "real" else "no_such_key"
        lines[key] = value
        kind, _, detail = what.partition(": ")
        what = f"{kind}: {key} = {detail}"
    if fmt == "json":
        nested = {k: json.dumps(v) for k, v in data.items() if isinstance(v, dict)}
        body = ", ".join(f"{json.dumps(k)}: {v}" for k, v in {**nested, **lines}.items())
        return "{" + body + "}", what
    return "".join(f"{json.dumps(k)} = {v}\n" for k, v in lines.items()), what


def hostile_json(good: Path, out: Path, rng: np.random.Generator) -> str:
    text, what = hostile_table_text(json.loads(good.read_text()), "json", rng)
    out.write_text(text)
    return what


def hostile_toml(good: Path, out: Path, rng: np.random.Generator) -> str:
    import tomllib

    text, what = hostile_table_text(tomllib.loads(good.read_text()), "toml", rng)
    out.write_text(text)
    return what


# --------------------------------------------------------------------------- URDFs


def _names(text: str, tag: str) -> list[str]:
    return re.findall(rf'<{tag}\s+name="([^"]+)"', text)


def long_name(text: str, rng: np.random.Generator) -> tuple[str, str]:
    """A link or joint renamed (everywhere it is named) to 255 to 100,000 characters."""
    old = str(pick(rng, _names(text, "link") + _names(text, "joint")))
    length = int(pick(rng, NAME_LENGTHS))
    new = (old + "_" + "n" * length)[:length]
    return text.replace(f'"{old}"', f'"{new}"'), f"{old} renamed to {length} characters"


NON_ASCII = ("bras_épaule", "плечо", "肩关节", "joint_\u202e_rtl", "emoji_\U0001f916", "tab\tname")


def non_ascii_name(text: str, rng: np.random.Generator) -> tuple[str, str]:
    """A link or joint renamed (everywhere) to a non-ASCII name."""
    old = str(pick(rng, _names(text, "link") + _names(text, "joint")))
    new = pick(rng, NON_ASCII)
    return text.replace(f'"{old}"', f'"{new}"'), f"{old} renamed to {new!r}"


def deep_chain(text: str, rng: np.random.Generator) -> tuple[str, str]:
    """A chain of 500 to 2,000 revolute joints and links hung from the last link."""
    count = int(pick(rng, CHAIN_LENGTHS))
    parent = _names(text, "link")[-1]
    parts = []
    for i in range(count):
        child = f"chain_{i}"
        parts.append(
            f'<link name="{child}"><inertial><mass value="0.01"/><inertia ixx="1e-5" ixy="0" '
            f'ixz="0" iyy="1e-5" iyz="0" izz="1e-5"/></inertial></link>'
            f'<joint name="chain_joint_{i}" type="revolute"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="0 0 0.001"/><axis xyz="0 0 1"/>'
            f'<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
        )
        parent = child
    return text.replace("</robot>", "".join(parts) + "</robot>"), f"a chain of {count} links"


def huge_mesh(text: str, rng: np.random.Generator) -> tuple[str, str]:
    """A link given a mesh of a 100,000-character name, a scale of 1e30, or 5,000 mesh
    visuals."""
    link = str(pick(rng, _names(text, "link")))
    op = pick(rng, ("name", "scale", "many"))
    if op == "name":
        shape, what = f'<mesh filename="{"m" * 100_000}.stl"/>', "a 100,000-character mesh name"
    elif op == "scale":
        shape, what = '<mesh filename="part.stl" scale="1e30 1e30 1e30"/>', "mesh scale 1e30"
    else:
        shape, what = '<mesh filename="part.stl"/>', "5,000 mesh visuals"
    visuals = f"<visual><geometry>{shape}</geometry></visual>" * (5000 if op == "many" else 1)
    marker = f'<link name="{link}">'
    return text.replace(marker, marker + visuals, 1), f"{link}: {what}"


URDF_EDITS: tuple[Callable, ...] = (long_name, long_name, non_ascii_name, deep_chain, huge_mesh)


def hostile_urdf(good: Path, out: Path, rng: np.random.Generator) -> str:
    edit = pick(rng, URDF_EDITS)
    text, what = edit(good.read_text(), rng)
    out.write_text(text, encoding="utf-8")
    return f"{edit.__name__}: {what}"


# --------------------------------------------------------------------------- run directories


def _npz_file(out: Path, checkpoint: Path, rng: np.random.Generator) -> str:
    """A hostile ``resume.npz``, ``env_state.npz`` or ``transitions.npz`` (made from the
    checkpoint's transitions)."""
    name = pick(rng, ("resume.npz", "env_state.npz", "transitions.npz"))
    good = checkpoint / "transitions.npz"
    mutation = pick(rng, NPZ_MUTATIONS)
    target = checkpoint / name
    if target == good:
        source = checkpoint / "good_transitions.npz"
        shutil.move(good, source)
        what = mutation(source, target, rng)
        source.unlink()
    else:
        what = mutation(good, target, rng)
        if name == "resume.npz" and rng.random() < 0.5:
            mutation(good, checkpoint / "env_state.npz", rng)
    return f"{name} {mutation.__name__}: {what}"


def _orbax(out: Path, checkpoint: Path, rng: np.random.Generator) -> str:
    """The orbax params folder damaged: a file emptied, made a 3 GiB sparse file, replaced by
    a folder or a link to /dev/zero, or an unknown file added."""
    params = checkpoint / "params"
    files = sorted(p for p in params.rglob("*") if p.is_file())
    target = pick(rng, files)
    op = pick(rng, ("empty", "sparse", "folder", "zero_link", "extra"))
    if op == "empty":
        target.write_bytes(b"")
    elif op == "sparse":
        with target.open("r+b") as f:
            f.truncate(3 * 2**30)
    elif op == "folder":
        target.unlink()
        target.mkdir()
    elif op == "zero_link":
        target.unlink()
        target.symlink_to("/dev/zero")
    else:
        (params / "extra.bin").write_bytes(b"\0" * 64)
        return "orbax extra: an unknown file in params"
    return f"orbax {op}: {target.relative_to(out)}"


def _config(out: Path, checkpoint: Path, rng: np.random.Generator) -> str:
    path = pick(rng, (out / "config.json", checkpoint / "meta.json"))
    return f"{path.name} {hostile_json(path, path, rng)}"


RUN_EDITS = (_npz_file, _npz_file, _orbax, _config, _config)


def hostile_run_dir(good: Path, out: Path, rng: np.random.Generator) -> str:
    """A copy of the run directory ``good`` with one hostile part."""
    shutil.copytree(good, out)
    checkpoint = sorted((out / "checkpoints").glob("step_*"))[-1]
    return pick(rng, RUN_EDITS)(out, checkpoint, rng)
