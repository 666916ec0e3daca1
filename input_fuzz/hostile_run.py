"""Damaged files of a run directory, for ``mjx-arm export RUN``, ``eval RUN``, ``train --resume
RUN`` and ``train --run-dir DIR``:

- ``config.json`` with strings where numbers belong (``"num_envs": "64"``), or bytes that are
  not UTF-8;
- ``metrics.csv`` with a 200,000-character field, bytes that are not UTF-8, no ``step`` column,
  or a folder in its place;
- ``checkpoints/`` holding folders named ``step_abc``, ``step_-1``, ``step_٣`` (a digit that is
  not ASCII) or a step of 30 digits, beside the good checkpoint or alone;
- a read-only run directory whose checkpoint was left as ``.old-step_N`` (a save killed while
  it replaced the checkpoint of the same step).

The folder a user keeps their own ``config.json`` and ``metrics.csv`` in (given as ``--run-dir``)
is made by :func:`user_folder`. Each mutation is ``(good run directory, output path, rng) ->
description`` (:mod:`input_fuzz.mutate`).
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np

from input_fuzz.hostile_npz import pick

# (table, key) of config.json given a string; the value is the number as text.
NUMBER_KEYS = (
    ("train", "num_envs"),
    ("train", "num_timesteps"),
    ("train", "learning_rate"),
    ("train", "batch_size"),
    ("train", "num_evals"),
    ("task", "ctrl_dt"),
    ("task", "episode_steps"),
    ("task", "action_scale"),
    ("task", "sim_dt"),
    ("arm", "reach_scale"),
)
BAD_STEPS = ("step_abc", "step_-1", "step_\u0663", "step_" + "9" * 30, "step_", "step_1e3")
NON_UTF8 = b"\xff\xfe\xc3\x28\xa0\xa1\xe2\x28\xa1"


def _checkpoint(out: Path) -> Path:
    return sorted((out / "checkpoints").glob("step_*"))[-1]


def config_strings(out: Path, rng: np.random.Generator) -> str:
    """Up to three numbers of config.json written as strings."""
    path = out / "config.json"
    config = json.loads(path.read_text())
    picked = [NUMBER_KEYS[int(i)] for i in rng.choice(len(NUMBER_KEYS), 3, replace=False)]
    count = int(rng.integers(1, 4))
    for table, key in picked[:count]:
        value = config[table].get(key, 1)
        config[table][key] = pick(rng, (str(value), f" {value}", "1e3", "many", ""))
    path.write_text(json.dumps(config))
    return "config_strings: " + ", ".join(f"{t}.{k}" for t, k in picked[:count])


def config_bytes(out: Path, rng: np.random.Generator) -> str:
    """config.json with bytes that are not UTF-8 inside a string, or in place of it all."""
    path = out / "config.json"
    data = path.read_bytes()
    if rng.random() < 0.5:
        path.write_bytes(data.replace(b'"reach"', b'"re' + NON_UTF8 + b'ach"', 1))
        return "config_non_utf8: inside a string"
    path.write_bytes(NON_UTF8 * 100)
    return "config_non_utf8: the whole file"


def metrics_long(out: Path, rng: np.random.Generator) -> str:
    """metrics.csv with a field of 200,000 characters (a value, a header or a quoted one)."""
    path = out / "metrics.csv"
    header, *rows = path.read_text().splitlines()
    field = "7" * 200_000
    op = pick(rng, ("value", "header", "quoted"))
    if op == "value":
        rows.append(f"{20480},{field},0.5")
    elif op == "header":
        header += "," + "h" * 200_000
    else:
        rows.append(f'20480,1.0,"{"x" * 200_000}"')
    path.write_text("\n".join([header, *rows]) + "\n")
    return f"metrics_long: a 200,000-character {op}"


def metrics_bytes(out: Path, rng: np.random.Generator) -> str:
    """metrics.csv with bytes that are not UTF-8 (in a row, or its header)."""
    path = out / "metrics.csv"
    data = path.read_bytes()
    if rng.random() < 0.5:
        path.write_bytes(data + b"20480," + NON_UTF8 + b",0.5\n")
        return "metrics_non_utf8: in a row"
    path.write_bytes(NON_UTF8 + data)
    return "metrics_non_utf8: in the header"


def metrics_no_step(out: Path, rng: np.random.Generator) -> str:
    """metrics.csv without a ``step`` column (renamed, or only other columns)."""
    path = out / "metrics.csv"
    header, *rows = path.read_text().splitlines()
    if rng.random() < 0.5:
        path.write_text("\n".join([header.replace("step", "steps", 1), *rows]) + "\n")
        return "metrics_no_step: the column renamed"
    path.write_text("a,b\n1,2\n")
    return "metrics_no_step: other columns only"


def metrics_folder(out: Path, rng: np.random.Generator) -> str:
    """A folder named metrics.csv (holding a file)."""
    path = out / "metrics.csv"
    path.unlink()
    path.mkdir()
    (path / "inside.csv").write_text("step\n1\n")
    return "metrics_folder: metrics.csv is a folder"


def bad_step_names(out: Path, rng: np.random.Generator) -> str:
    """Checkpoint folders whose names are not ``step_`` and a number, beside the good one (a
    copy of it) or in its place."""
    good = _checkpoint(out)
    name = pick(rng, BAD_STEPS)
    shutil.copytree(good, good.with_name(name))
    if rng.random() < 0.5:
        shutil.rmtree(good)
        return f"step_names: only {name!r}"
    return f"step_names: {name!r} beside the checkpoint"


def read_only_old(out: Path, rng: np.random.Generator) -> str:
    """The checkpoint left as ``.old-step_N`` in a read-only run directory (or a writable one),
    with or without a new ``step_N`` beside it."""
    good = _checkpoint(out)
    old = good.with_name(".old-" + good.name)
    good.rename(old)
    both = rng.random() < 0.3
    if both:
        shutil.copytree(old, good)
    locked = rng.random() < 0.7
    if locked:
        for folder in (out / "checkpoints", out):
            os.chmod(folder, 0o555)
    return f"old_step: {'read-only' if locked else 'writable'}{', both' if both else ''}"


RUN_FILE_EDITS = (
    config_strings,
    config_strings,
    config_bytes,
    metrics_long,
    metrics_bytes,
    metrics_no_step,
    metrics_folder,
    bad_step_names,
    bad_step_names,
    read_only_old,
    read_only_old,
)


def hostile_run_files(good: Path, out: Path, rng: np.random.Generator) -> str:
    """A copy of the run directory ``good`` with one damaged file or folder."""
    shutil.copytree(good, out)
    return pick(rng, RUN_FILE_EDITS)(out, rng)


USER_FILES = {
    "config.json": b'{"my_setting": 3, "notes": "mine"}\n',
    "metrics.csv": b"day,weight\n1,70.5\n2,70.1\n",
    "notes.txt": b"my own notes\n",
}


def user_folder(path: Path) -> None:
    """A folder of the user's holding their own config.json, metrics.csv and notes (not a run
    directory: nothing in it may be replaced)."""
    path.mkdir(parents=True, exist_ok=True)
    for name, data in USER_FILES.items():
        (path / name).write_bytes(data)
