"""Checkpoints of a run: params (orbax), ``meta.json`` and transitions, saved atomically.

Layout, under ``RUN_DIR/checkpoints/``::

    step_000001234/params/           (normaliser, policy, value) in Brax's format, by orbax
    step_000001234/meta.json         the step and what the run adds (task, metrics, ...)
    step_000001234/transitions.npz   a short rollout of the policy (obs, action, reward, done)
    step_000001234/resume.npz        the training state (optimiser included) and PRNG keys
    step_000001234/env_state.npz     the training envs' state (the newest checkpoint only)

With ``resume.npz`` and ``env_state.npz`` (:mod:`mjx_arm.train.resume`) a resumed run goes on
as if it had never stopped, on any number of devices. Checkpoints written before them hold
params only (as Brax's do, google/brax#655): such a run resumes with fresh optimiser moments,
new keys and reset envs.

Nothing is lost: a save that fails (a full disk) or is killed leaves the checkpoints before it
whole and the newest of them the latest, and a checkpoint that cannot be read is a named
:class:`CheckpointError`. A checkpoint's files are read only as regular files inside its run
directory (``RUN_DIR``, two folders up), ``meta.json`` with a size bound; a folder under
``checkpoints/`` whose name is not ``step_`` and a number is not a checkpoint.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from mjx_arm.inputs import InputFileError, MiB, read_json_object

CHECKPOINT_PREFIX = "step_"
PARTIAL, OLD = ".partial-", ".old-"
PARAMS_FILES = "params_files"  # meta.json: each params file's size and hash, checked on load
MAX_META_BYTES = 4 * MiB  # a meta.json holds a few kB


class CheckpointError(InputFileError):
    """A checkpoint that cannot be read, or that could not be saved (a full disk)."""


def checkpoint_dir(checkpoints: Path, step: int) -> Path:
    """Folder of the checkpoint at ``step`` under the ``checkpoints`` folder."""
    return checkpoints / f"{CHECKPOINT_PREFIX}{step:012d}"


def save_checkpoint(
    folder: Path,
    step: int,
    params: Any,
    meta: dict[str, Any],
    transitions: dict[str, np.ndarray] | None = None,
    arrays: dict[str, dict[str, np.ndarray]] | None = None,
) -> Path:
    """Save params (normaliser, policy, value) with orbax, ``meta.json``, transitions and the
    ``arrays`` files (file name -> arrays, each written as an ``.npz``).

    Atomic: everything is written into a hidden folder that is then renamed to ``folder``, so a
    run killed mid-save never leaves a half-written checkpoint behind under a name
    :func:`latest_checkpoint` would take, and a checkpoint saved again at the same step
    replaces the old one only once the new one is complete.

    Raises:
        CheckpointError: the save failed (a full disk, no permission); the partial folder is
            removed and the earlier checkpoints are untouched.
    """
    partial = folder.with_name(f"{PARTIAL}{folder.name}")
    shutil.rmtree(partial, ignore_errors=True)
    try:
        _write_partial(partial, step, params, meta, transitions, arrays or {})
    except (OSError, ValueError) as err:  # orbax (tensorstore) reports a full disk as ValueError
        shutil.rmtree(partial, ignore_errors=True)
        kept = latest_checkpoint(folder.parent)
        raise CheckpointError(
            f"saving the checkpoint of step {step} in {folder.parent} failed ({_cause(err)}); the "
            f"last good checkpoint is kept ({kept.name if kept else 'none yet'}): free some "
            "space and resume the run"
        ) from err
    old = folder.with_name(f"{OLD}{folder.name}")
    if folder.exists():  # the same step saved again (a resumed run's last checkpoint)
        shutil.rmtree(old, ignore_errors=True)
        os.replace(folder, old)
    os.replace(partial, folder)
    shutil.rmtree(old, ignore_errors=True)
    return folder


def _write_partial(
    partial: Path,
    step: int,
    params: Any,
    meta: dict[str, Any],
    transitions: dict[str, np.ndarray] | None,
    arrays: dict[str, dict[str, np.ndarray]],
) -> None:
    """Write a whole checkpoint into ``partial`` and flush it to disk."""

    partial.mkdir(parents=True)
    checkpointer().save((partial / "params").resolve(), params, force=True)
    if transitions is not None:
        save_transitions(partial, transitions)
    for name, content in arrays.items():
        with (partial / name).open("wb") as f:
            np.savez(f, **content)
    files = {PARAMS_FILES: params_files(partial / "params")}
    (partial / "meta.json").write_text(json.dumps({"step": step, **meta, **files}, indent=2))
    _fsync_tree(partial)


def checkpointer() -> Any:
    """orbax's checkpointer for host params, for this process alone.

    Where several processes train, orbax waits for all of them at every save and restore;
    here only process 0 saves (host arrays), so that wait would never end.
    """
    import jax
    import orbax.checkpoint as ocp

    if jax.process_count() == 1:
        return ocp.PyTreeCheckpointer()
    me = jax.process_index()
    alone = ocp.options.MultiprocessingOptions(primary_host=me, active_processes={me})
    handler = ocp.PyTreeCheckpointHandler(multiprocessing_options=alone)
    return ocp.Checkpointer(handler, multiprocessing_options=alone)


def params_files(params: Path, sizes: dict[str, int] | None = None) -> dict[str, list]:
    """``{relative path: [bytes, sha256]}`` of every file orbax wrote under ``params``.

    Files are hashed in chunks (memory stays small whatever their size); with ``sizes``, a
    file whose size differs from its entry there is not hashed (its hash is "")."""
    found = {}
    for p in sorted(params.rglob("*")):
        if not p.is_file():
            continue
        name, size = str(p.relative_to(params)), p.stat().st_size
        if sizes is not None and sizes.get(name) != size:
            found[name] = [size, ""]
            continue
        with p.open("rb") as f:
            found[name] = [size, hashlib.file_digest(f, "sha256").hexdigest()]
    return found


def _damage(folder: Path) -> str:
    """What differs between a checkpoint's params files and the list its meta.json recorded
    when it was saved ("" where they agree, or for checkpoints saved before the list)."""
    recorded = load_meta(folder).get(PARAMS_FILES)
    if not isinstance(recorded, dict):
        return ""
    sizes = {n: e[0] for n, e in recorded.items() if isinstance(e, list) and e}
    found = params_files(folder / "params", sizes)
    for name, entry in recorded.items():
        if name not in found:
            return f"params/{name} is missing"
        if found[name] != entry:
            return f"params/{name} has changed since it was saved ({found[name][0]} bytes)"
    return ""


def checkpoint_step(folder: Path) -> int | None:
    """The step a checkpoint folder's name gives (``step_N``, or ``.old-step_N`` left by a
    killed save), or None for any other name (``step_abc``)."""
    digits = folder.name.removeprefix(OLD).removeprefix(CHECKPOINT_PREFIX)
    named = folder.name.removeprefix(OLD).startswith(CHECKPOINT_PREFIX)
    return int(digits) if named and digits.isascii() and digits.isdigit() else None


def usable(folder: Path) -> bool:
    """Whether a checkpoint folder is complete: a step in its name, ``meta.json`` with a step
    (:func:`load_meta`), and params."""
    if checkpoint_step(folder) is None:
        return False
    try:
        load_meta(folder)
    except CheckpointError:
        return False
    return (folder / "params").is_dir()


def latest_checkpoint(checkpoints: Path) -> Path | None:
    """The newest usable checkpoint folder under ``checkpoints`` (:func:`usable`), or None.

    A save killed between moving an old checkpoint of the same step aside and renaming the new
    one into place left the old one as ``.old-step_N``: it is moved back first, or, where the
    run directory cannot be written (read-only), read where it lies.
    """
    if not checkpoints.is_dir():
        return None
    stranded = []
    for old in checkpoints.glob(f"{OLD}{CHECKPOINT_PREFIX}*"):
        target = old.with_name(old.name.removeprefix(OLD))
        if not target.exists():
            try:
                os.replace(old, target)
            except OSError:  # a read-only run directory
                stranded.append(old)
    found = usable_checkpoints(checkpoints) + [p for p in stranded if usable(p)]
    return max(found, key=checkpoint_step) if found else None


def usable_checkpoints(checkpoints: Path) -> list[Path]:
    """Every usable checkpoint folder under ``checkpoints`` (:func:`usable`), oldest first."""
    if not checkpoints.is_dir():
        return []
    found = [p for p in checkpoints.iterdir() if p.name.startswith(CHECKPOINT_PREFIX)]
    return sorted((p for p in found if usable(p)), key=checkpoint_step)


def unusable_reason(checkpoints: Path) -> str:
    """Why the newest folder named as a checkpoint under ``checkpoints`` is not usable, as
    ``" (step_N: why)"`` for a message ("" where none is named so, or it is usable)."""
    folders = checkpoints.iterdir() if checkpoints.is_dir() else []
    named = [p for p in folders if checkpoint_step(p) is not None]
    if not named:
        return ""
    newest = max(named, key=checkpoint_step)
    try:
        load_meta(newest)
    except CheckpointError as err:
        return f" ({newest.name}: {err})"
    return "" if (newest / "params").is_dir() else f" ({newest.name} has no params/ folder)"


def load_meta(folder: Path) -> dict[str, Any]:
    """The ``meta.json`` of a checkpoint folder: a regular file inside the run directory, of
    at most :data:`MAX_META_BYTES`.

    Raises:
        CheckpointError: missing, not such a file, not JSON, or without a whole-number
            ``step``.
    """
    path = folder / "meta.json"
    try:
        meta = read_json_object(path, "checkpoint metadata", MAX_META_BYTES, within=run_of(folder))
    except InputFileError as err:
        raise CheckpointError(str(err)) from err
    step = meta.get("step")
    if not isinstance(step, int) or isinstance(step, bool) or step < 0:
        raise CheckpointError(f"{path}: 'step' must be a whole number >= 0")
    return meta


def run_of(folder: Path) -> Path:
    """The run directory of a checkpoint folder (``RUN_DIR/checkpoints/step_N``)."""
    return folder.absolute().parent.parent


def _foreign(params: Path) -> str:
    """The first entry under ``params`` that is neither a folder nor a regular file (a FIFO,
    a device) or that links out of the run directory, described ("" where there is none)."""
    root = os.path.realpath(run_of(params.parent))
    for path in params.rglob("*"):
        target = Path(os.path.realpath(path))
        if not target.is_relative_to(root):
            return f"params/{path.relative_to(params)} is a link to {target}, out of the run"
        if not (target.is_dir() or target.is_file()):
            return f"params/{path.relative_to(params)} is not a regular file"
    return ""


def load_params(folder: Path) -> Any:
    """The params saved in a checkpoint folder, as orbax reads them back (plain dicts).

    Raises:
        CheckpointError: the params are missing or cannot be read (a damaged checkpoint).
    """

    path = (folder / "params").resolve()
    if not path.is_dir():
        raise CheckpointError(f"checkpoint {folder} has no params/ folder; it is incomplete")
    damage = _foreign(folder / "params") or _damage(folder)  # before orbax reads a byte
    if damage:
        raise CheckpointError(
            f"checkpoint {folder} cannot be read: {damage}; delete it to use the one before"
        )
    try:
        return checkpointer().restore(path)
    except Exception as err:  # orbax and tensorstore raise many types for a damaged file
        raise CheckpointError(
            f"checkpoint {folder} cannot be read ({type(err).__name__}: {_cause(err)}); "
            "delete it to use the one before"
        ) from err


def _cause(err: Exception) -> str:
    """An OSError's reason, or the head of another error's message (tensorstore's messages
    carry a long spec in brackets)."""
    return getattr(err, "strerror", None) or str(err).split(" [", 1)[0][:300]


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
