"""Checkpoints of a run: params (orbax), ``meta.json`` and transitions, saved atomically.

Layout, under ``RUN_DIR/checkpoints/``::

    step_000001234/params/           (normaliser, policy, value) in Brax's format, by orbax
    step_000001234/meta.json         the step and what the run adds (task, metrics, ...)
    step_000001234/transitions.npz   a short rollout of the policy (obs, action, reward, done)

Checkpoints hold params only: a resumed run starts the optimiser's moment estimates from zero
(google/brax#655) and may run on any number of devices.
"""

from __future__ import annotations

import functools
import json
import os
import shutil
from pathlib import Path
from typing import Any

import numpy as np

CHECKPOINT_PREFIX = "step_"


def checkpoint_dir(checkpoints: Path, step: int) -> Path:
    """Folder of the checkpoint at ``step`` under the ``checkpoints`` folder."""
    return checkpoints / f"{CHECKPOINT_PREFIX}{step:012d}"


def save_checkpoint(
    folder: Path,
    step: int,
    params: Any,
    meta: dict[str, Any],
    transitions: dict[str, np.ndarray] | None = None,
) -> Path:
    """Save params (normaliser, policy, value) with orbax, ``meta.json`` and transitions.

    Atomic: everything is written into a hidden folder that is then renamed to ``folder``, so a
    run killed mid-save never leaves a half-written checkpoint behind under a name
    :func:`latest_checkpoint` would take.
    """
    import orbax.checkpoint as ocp

    partial = folder.with_name(f".partial-{folder.name}")
    shutil.rmtree(partial, ignore_errors=True)
    partial.mkdir(parents=True)
    ocp.PyTreeCheckpointer().save((partial / "params").resolve(), params, force=True)
    if transitions is not None:
        save_transitions(partial, transitions)
    (partial / "meta.json").write_text(json.dumps({"step": step, **meta}, indent=2))
    _fsync_tree(partial)
    if folder.exists():  # the same step saved again (a resumed run's last checkpoint)
        shutil.rmtree(folder)
    os.replace(partial, folder)
    return folder


def latest_checkpoint(checkpoints: Path) -> Path | None:
    """The newest complete checkpoint folder under ``checkpoints``, or None."""
    if not checkpoints.exists():
        return None
    found = sorted(
        p
        for p in checkpoints.iterdir()
        if p.name.startswith(CHECKPOINT_PREFIX) and (p / "meta.json").exists()
    )
    return found[-1] if found else None


def load_meta(folder: Path) -> dict[str, Any]:
    """The ``meta.json`` of a checkpoint folder."""
    return json.loads((folder / "meta.json").read_text())


def load_params(folder: Path) -> Any:
    """The params saved in a checkpoint folder, as orbax reads them back (plain dicts)."""
    import orbax.checkpoint as ocp

    return ocp.PyTreeCheckpointer().restore((folder / "params").resolve())


def save_transitions(folder: Path, transitions: dict[str, np.ndarray]) -> Path:
    """Write ``transitions.npz`` (obs, action, reward, done, ...) into a checkpoint folder."""
    path = folder / "transitions.npz"
    np.savez_compressed(path, **transitions)
    return path


def restore_brax_params(raw: Any) -> tuple:
    """Brax's (normalizer, policy, value) from a checkpoint read back without a target.

    orbax returns plain dicts; Brax needs its running-statistics dataclass (with the UInt64
    sample count) for the normaliser. Policy and value params are plain dicts already.
    """
    import jax
    import jax.numpy as jnp
    from brax.training import types as brax_types
    from brax.training.acme import running_statistics

    norm, policy, value = raw
    count = norm["count"]
    if isinstance(count, dict):
        count = brax_types.UInt64(hi=jnp.asarray(count["hi"]), lo=jnp.asarray(count["lo"]))
    state = running_statistics.RunningStatisticsState(
        mean=jnp.asarray(norm["mean"]),
        std=jnp.asarray(norm["std"]),
        count=count,
        summed_variance=jnp.asarray(norm["summed_variance"]),
        std_eps=float(np.asarray(norm.get("std_eps", 0.0))),
    )
    to_jax = functools.partial(jax.tree.map, jnp.asarray)
    return state, to_jax(policy), to_jax(value)


def _fsync_tree(folder: Path) -> None:
    """Flush every file under ``folder`` to disk before it is renamed into place."""
    for path in folder.rglob("*"):
        if path.is_file():
            with path.open("rb") as f:
                os.fsync(f.fileno())
