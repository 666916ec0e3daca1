"""Mutations of good input files: byte damage, and edits that keep the file's format but break
its content (a deleted key, a value of the wrong type, NaN weights, a shape that does not fit).

Each mutation is a function ``(good file, output path, rng) -> description`` of one file kind
(:data:`MUTATIONS`); :func:`mutate` picks and applies one. The rng (NumPy's) comes from the case,
so a case replays exactly.
"""

from __future__ import annotations

import io
import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

# Values a mutated field takes: wrong types, out of range, non-finite, hostile paths.
VALUES: tuple[Any, ...] = (
    None,
    True,
    False,
    0,
    -1,
    1,
    7,
    10**30,
    -(2**63),
    0.5,
    -0.5,
    1e308,
    float("nan"),
    float("inf"),
    -float("inf"),
    "",
    "x",
    "nan",
    "2",
    "/dev/zero",
    "../../../etc/passwd",
    [],
    [1, 2],
    [0.1] * 6,
    ["a", "b"],
    [[1, 2], [3]],
    {},
    {"a": 1},
)

Mutation = Callable[[Path, Path, np.random.Generator], str]


def pick(rng: np.random.Generator, items):
    """One of ``items`` (a sequence), uniformly."""
    return items[int(rng.integers(len(items)))]


# --------------------------------------------------------------------------- bytes


def truncate(good: Path, out: Path, rng: np.random.Generator) -> str:
    data = good.read_bytes()
    cut = int(rng.integers(0, max(len(data), 1)))
    out.write_bytes(data[:cut])
    return f"truncated to {cut} of {len(data)} bytes"


def flip_bytes(good: Path, out: Path, rng: np.random.Generator) -> str:
    data = bytearray(good.read_bytes())
    count = int(rng.integers(1, 9))
    for i in rng.integers(0, max(len(data), 1), count):
        if data:
            data[int(i)] ^= int(rng.integers(1, 256))
    out.write_bytes(bytes(data))
    return f"{count} bytes flipped"


def garbage(good: Path, out: Path, rng: np.random.Generator) -> str:
    size = int(pick(rng, (0, 1, 16, 4096)))
    out.write_bytes(rng.integers(0, 256, size, dtype=np.uint8).tobytes())
    return f"{size} random bytes"


def as_folder(good: Path, out: Path, rng: np.random.Generator) -> str:
    out.mkdir(parents=True, exist_ok=True)
    return "a folder instead of a file"


BYTE_MUTATIONS: tuple[Mutation, ...] = (truncate, flip_bytes, garbage, as_folder)


# --------------------------------------------------------------------------- tables (JSON, TOML)


def edit_table(data: Any, rng: np.random.Generator) -> tuple[Any, str]:
    """``data`` (a loaded JSON/TOML table) with one edit: a key deleted, a value replaced (at
    any depth), an unknown key added, or the whole table replaced."""
    op = pick(rng, ("delete", "replace", "replace", "unknown", "root"))
    if op == "root" or not isinstance(data, dict) or not data:
        value = pick(rng, VALUES)
        return value, f"the table replaced by {value!r}"
    path, parent = _random_path(data, rng)
    key = path[-1]
    if op == "delete":
        del parent[key]
        return data, f"deleted {'.'.join(path)}"
    if op == "unknown":
        parent["no_such_key"] = pick(rng, VALUES)
        return data, f"unknown key {'.'.join([*path[:-1], 'no_such_key'])}"
    parent[key] = pick(rng, VALUES)
    return data, f"{'.'.join(path)} = {parent[key]!r}"


def _random_path(data: dict, rng: np.random.Generator) -> tuple[list[str], dict]:
    """A random key path into nested dicts and the dict holding its last key."""
    path, parent = [], data
    while True:
        key = str(pick(rng, list(parent)))
        path.append(key)
        child = parent[key]
        if not (isinstance(child, dict) and child and rng.random() < 0.6):
            return path, parent
        parent = child


def mutate_json(good: Path, out: Path, rng: np.random.Generator) -> str:
    data, what = edit_table(json.loads(good.read_text()), rng)
    out.write_text(json.dumps(data))
    return what


def toml_text(data: Any) -> str:
    """A table as TOML, one ``key = JSON value`` line each (what an edited value allows)."""
    if not isinstance(data, dict):
        return json.dumps(data)
    return "".join(f"{k} = {json.dumps(v)}\n" for k, v in data.items())


def mutate_toml(good: Path, out: Path, rng: np.random.Generator) -> str:
    import tomllib

    data, what = edit_table(tomllib.loads(good.read_text()), rng)
    out.write_text(toml_text(data))
    return what


# --------------------------------------------------------------------------- npz files


def _load_npz(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as data:
        return {k: data[k] for k in data.files}


def _save_npz(arrays: dict[str, Any], out: Path) -> None:
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    out.write_bytes(buffer.getvalue())


def edit_array(value: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, str]:
    """``value`` with NaN/inf entries, another shape, another type, or emptied."""
    op = pick(rng, ("nan", "inf", "shape", "transpose", "text", "empty", "scalar"))
    if op in ("nan", "inf") and value.size and value.dtype.kind == "f":
        value = value.copy()
        value.flat[int(rng.integers(value.size))] = np.nan if op == "nan" else np.inf
        return value, f"an entry set to {op}"
    if op == "shape" and value.ndim:
        cut = int(rng.integers(0, value.shape[-1] + 1))
        return value[..., :cut], f"last axis cut to {cut}"
    if op == "transpose" and value.ndim == 2:
        return value.T, "transposed"
    if op == "text":
        return np.array(["a"] * max(value.size, 1)), "text instead of numbers"
    if op == "empty":
        return np.zeros((0,), np.float32), "emptied"
    return np.array(7.0), "a scalar"


def mutate_npz_arrays(good: Path, out: Path, rng: np.random.Generator) -> str:
    """An array of a policy or trajectory file edited, deleted, or an extra one added."""
    arrays = _load_npz(good)
    key = str(pick(rng, sorted(k for k in arrays if k not in ("metadata", "task_config"))))
    op = pick(rng, ("edit", "edit", "edit", "delete", "extra"))
    if op == "delete":
        del arrays[key]
        what = f"{key} deleted"
    elif op == "extra":
        arrays["kernel_9"] = np.ones((3, 3), np.float32)
        what = "an extra layer kernel_9"
    else:
        arrays[key], change = edit_array(arrays[key], rng)
        what = f"{key}: {change}"
    _save_npz(arrays, out)
    return what


def mutate_npz_metadata(good: Path, out: Path, rng: np.random.Generator) -> str:
    """The JSON metadata of a policy (or a trajectory's task_config) edited or broken."""
    arrays = _load_npz(good)
    key = "metadata" if "metadata" in arrays else "task_config"
    data = json.loads(str(arrays[key]))
    op = pick(rng, ("edit", "edit", "edit", "version", "not_json", "delete"))
    if op == "delete":
        del arrays[key]
        what = f"{key} deleted"
    elif op == "not_json":
        arrays[key] = np.array("{not json")
        what = f"{key} not JSON"
    elif op == "version" and key == "metadata":
        data["contract_version"] = pick(rng, ("0", "2", "99", 2, None))
        arrays[key] = np.array(json.dumps(data))
        what = f"contract_version {data['contract_version']!r}"
    else:
        data, what = edit_table(data, rng)
        arrays[key] = np.array(json.dumps(data))
        what = f"{key}: {what}"
    _save_npz(arrays, out)
    return what


def mutate_onnx(good: Path, out: Path, rng: np.random.Generator) -> str:
    """An ONNX policy whose metadata property is edited (the graph stays valid)."""
    import onnx

    model = onnx.load(str(good))
    prop = next(p for p in model.metadata_props if p.key == "mjx_arm")
    data, what = edit_table(json.loads(prop.value), rng)
    prop.value = json.dumps(data)
    out.write_bytes(model.SerializeToString())
    return f"metadata: {what}"


# --------------------------------------------------------------------------- run directories


def mutate_run_dir(good: Path, out: Path, rng: np.random.Generator) -> str:
    """A copy of a run directory with its checkpoint, config or metrics damaged."""
    shutil.copytree(good, out)
    checkpoint = sorted((out / "checkpoints").glob("step_*"))[-1]
    op = pick(rng, tuple(_RUN_EDITS))
    return _RUN_EDITS[op](out, checkpoint, rng)


def _delete(path: Path) -> None:
    if path.is_dir():
        shutil.rmtree(path)
    elif path.exists():
        path.unlink()


def _damage_params(out: Path, checkpoint: Path, rng: np.random.Generator) -> str:
    files = sorted(p for p in (checkpoint / "params").rglob("*") if p.is_file())
    target = pick(rng, files)
    data = target.read_bytes()
    target.write_bytes(data[: int(rng.integers(0, max(len(data), 1)))])
    return f"params file {target.relative_to(out)} truncated"


def _delete_part(out: Path, checkpoint: Path, rng: np.random.Generator) -> str:
    part = pick(
        rng,
        (checkpoint / "params", checkpoint / "meta.json", out / "config.json", out / "checkpoints"),
    )
    _delete(part)
    return f"{part.relative_to(out)} deleted"


def _edit_meta(out: Path, checkpoint: Path, rng: np.random.Generator) -> str:
    return "meta.json: " + mutate_json(checkpoint / "meta.json", checkpoint / "meta.json", rng)


def _edit_config(out: Path, checkpoint: Path, rng: np.random.Generator) -> str:
    return "config.json: " + mutate_json(out / "config.json", out / "config.json", rng)


def _cut_metrics(out: Path, checkpoint: Path, rng: np.random.Generator) -> str:
    return "metrics.csv " + truncate(out / "metrics.csv", out / "metrics.csv", rng)


_RUN_EDITS: dict[str, Callable[[Path, Path, np.random.Generator], str]] = {
    "delete": _delete_part,
    "meta": _edit_meta,
    "config": _edit_config,
    "config_again": _edit_config,
    "params": _damage_params,
    "metrics": _cut_metrics,
}


# --------------------------------------------------------------------------- dispatch

MUTATIONS: dict[str, tuple[Mutation, ...]] = {
    "urdf": BYTE_MUTATIONS,
    "arm_file": (*BYTE_MUTATIONS, mutate_toml, mutate_toml, mutate_toml),
    "config": (*BYTE_MUTATIONS, mutate_json, mutate_json, mutate_json),
    "policy": (*BYTE_MUTATIONS, mutate_npz_arrays, mutate_npz_metadata, mutate_npz_metadata),
    "onnx": (*BYTE_MUTATIONS, mutate_onnx, mutate_onnx),
    "trajectory": (*BYTE_MUTATIONS, mutate_npz_arrays, mutate_npz_arrays, mutate_npz_metadata),
    "run_dir": (mutate_run_dir,),
}
MUTATIONS["arm_json"] = (*BYTE_MUTATIONS, mutate_json, mutate_json, mutate_json)


def mutated_mesh(good: Path, out: Path, rng: np.random.Generator) -> str:
    """A URDF with a mesh, one of whose files is damaged (:mod:`input_fuzz.hostile_mesh`)."""
    from input_fuzz import hostile_mesh

    return hostile_mesh.mutated_mesh(good, out, rng)


MUTATIONS["mesh"] = (mutated_mesh,)


def _hostile() -> dict[str, tuple[Mutation, ...]]:
    """The structure-aware mutations of each kind (:mod:`input_fuzz.hostile` and the modules
    it names); ONNX ones need the onnx package."""
    from input_fuzz import hostile
    from input_fuzz.hostile_mesh import MESH_MUTATIONS
    from input_fuzz.hostile_npz import NPZ_MUTATIONS
    from input_fuzz.hostile_run import hostile_run_files

    found = {
        "urdf": (hostile.hostile_urdf,),
        "arm_file": (hostile.hostile_toml,),
        "arm_json": (hostile.hostile_json,),
        "config": (hostile.hostile_json,),
        "policy": NPZ_MUTATIONS,
        "trajectory": NPZ_MUTATIONS,
        "run_dir": (hostile.hostile_run_dir, hostile_run_files, hostile_run_files),
        "mesh": MESH_MUTATIONS,
    }
    try:
        from input_fuzz.hostile_onnx import ONNX_MUTATIONS
    except ImportError:  # pragma: no cover - onnx is a test dependency
        return found
    return {**found, "onnx": (*ONNX_MUTATIONS, truncate, flip_bytes)}


def mutate(
    kind: str, good: Path, out: Path, rng: np.random.Generator, hostile: bool = False
) -> str:
    """Write a mutation of the good ``kind`` file ``good`` to ``out``: a generic one, or with
    ``hostile`` a structure-aware one (:mod:`input_fuzz.hostile`); ``name: what was changed``."""
    mutation = pick(rng, _hostile()[kind] if hostile else MUTATIONS[kind])
    return f"{mutation.__name__}: {mutation(good, out, rng)}"
