"""What a checkpoint keeps so that a resumed run is the run it continues.

Brax's checkpoints hold params only (google/brax#655): a run resumed from them starts Adam's
moment estimates from zero, draws new keys and resets every env. A checkpoint here also holds

- ``resume.npz``: the whole training state (params, normaliser, optimiser state, env-step
  count) and the PRNG keys of the epochs and of the evaluations;
- ``env_state.npz`` (the newest checkpoint only; older ones drop it): every per-env array of
  the training envs' state (physics, targets, episode counters, their keys), gathered from
  every device.

Arrays are stored in the order of the state's tree, and read back into a template of the same
structure (the fresh state of the same config), so a file that does not fit the config is a
named error, never a wrong run. None of them is pickled.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jax
import numpy as np

from mjx_arm.inputs import InputFileError, MiB, OversizedInputError, read_npz_members

RESUME_FILE = "resume.npz"
ENV_STATE_FILE = "env_state.npz"
KEY_NAMES = ("epochs", "evaluation")


class ResumeStateError(InputFileError):
    """A checkpoint's resume files do not fit the run's config, or cannot be read."""


@dataclass
class ResumeState:
    """A training run's state between two epochs, on the host.

    Attributes:
        train_state: Brax's ``TrainingState`` (params, normaliser, optimiser, env steps).
        keys: ``epochs`` (the key the next epoch's key is split from) and ``evaluation``.
        env_leaves: the per-env arrays of the training envs' state, ``(num_envs, ...)`` each,
            in tree order (see :func:`env_leaf_paths`); None where not kept.
    """

    train_state: Any
    keys: dict[str, np.ndarray]
    env_leaves: list[np.ndarray] | None = None


def env_leaf_paths(env_state: Any, num_envs: int, splits=None) -> list[tuple]:
    """Tree paths of the per-env leaves of ``env_state``: a leading axis of ``num_envs`` that
    the physics cuts per env (not MuJoCo Warp's shared contact pool, counters or tables,
    which each step computes afresh)."""

    def per_env(path: tuple, leaf: Any) -> bool:
        names = [str(getattr(k, "name", getattr(k, "key", ""))) for k in path]
        if any(n.startswith("contact__") for n in names):
            return False
        if splits is not None and not splits(path):
            return False
        return getattr(leaf, "ndim", 0) >= 1 and leaf.shape[0] == num_envs

    flat, _ = jax.tree_util.tree_flatten_with_path(env_state)
    return [path for path, leaf in flat if per_env(path, leaf)]


def select_leaves(tree: Any, paths: list[tuple]) -> list[Any]:
    """The leaves of ``tree`` at ``paths``, in that order."""
    wanted = set(paths)
    found = {p: leaf for p, leaf in jax.tree_util.tree_flatten_with_path(tree)[0] if p in wanted}
    return [found[p] for p in paths]


def replace_leaves(tree: Any, paths: list[tuple], values: list[Any]) -> Any:
    """``tree`` with the leaves at ``paths`` replaced by ``values``."""
    new = dict(zip(paths, values, strict=True))
    return jax.tree_util.tree_map_with_path(lambda p, leaf: new.get(p, leaf), tree)


def resume_arrays(state: ResumeState) -> dict[str, dict[str, np.ndarray]]:
    """The files of ``state`` to write into a checkpoint folder: file name -> arrays."""
    leaves = jax.tree.leaves(state.train_state)
    arrays = {f"state_{i:04d}": np.asarray(x) for i, x in enumerate(leaves)}
    arrays.update({f"key_{name}": np.asarray(state.keys[name]) for name in KEY_NAMES})
    files = {RESUME_FILE: arrays}
    if state.env_leaves is not None:
        leaves = enumerate(state.env_leaves)
        files[ENV_STATE_FILE] = {f"env_{i:04d}": np.asarray(x) for i, x in leaves}
    return files


def has_resume_state(folder: Path) -> bool:
    """Whether a checkpoint folder holds the training state (not params only)."""
    return (folder / RESUME_FILE).is_file()


def newest_whole_state(checkpoints: Path) -> Path | None:
    """The newest usable checkpoint under ``checkpoints`` with the training state and the
    envs' state (None where none has both)."""
    from mjx_arm.train.checkpoints import usable_checkpoints

    found = [
        p
        for p in usable_checkpoints(checkpoints)
        if has_resume_state(p) and (p / ENV_STATE_FILE).is_file()
    ]
    return found[-1] if found else None


def load_resume_state(
    folder: Path, template: Any, key_template: np.ndarray, env_template: list[Any] | None
) -> ResumeState:
    """Read a checkpoint's resume files into the structure of ``template``.

    Args:
        folder: the checkpoint folder.
        template: a fresh training state of the same config (its structure, shapes, dtypes).
        key_template: a PRNG key of the run's kind (shape and dtype).
        env_template: the per-env leaves of a fresh env state (None: do not read the env
            state). An env state that is missing (an older checkpoint) or of another batch
            (another ``num_envs``) is dropped with a warning: the run resumes from reset envs.

    Raises:
        ResumeStateError: the training state is unreadable or does not fit ``template``.
    """
    leaves, treedef = jax.tree.flatten(template)
    arrays = _read_npz(folder / RESUME_FILE, _nbytes([*leaves, *[key_template] * len(KEY_NAMES)]))
    stored = [arrays.get(f"state_{i:04d}") for i in range(len(leaves))]
    problem = _mismatch(stored, leaves) or (
        f"{len(arrays)} arrays, expected {len(leaves) + len(KEY_NAMES)}"
        if len(arrays) != len(leaves) + len(KEY_NAMES)
        else ""
    )
    keys = {name: arrays.get(f"key_{name}") for name in KEY_NAMES}
    problem = problem or _mismatch(list(keys.values()), [key_template] * len(KEY_NAMES))
    if problem:
        raise ResumeStateError(
            f"{folder / RESUME_FILE} does not fit this run's config ({problem}); resume with the "
            "config the run was started with, or start a new run"
        )
    state = jax.tree.unflatten(treedef, stored)
    return ResumeState(state, keys, _env_leaves(folder, env_template))


def _env_leaves(folder: Path, template: list[Any] | None) -> list[np.ndarray] | None:
    """The stored env leaves where they fit ``template`` (else None, with a warning)."""
    if template is None:
        return None
    path = folder / ENV_STATE_FILE
    if not path.is_file():
        warnings.warn(
            f"{folder.name} keeps no env state (only the newest checkpoint does): the run "
            "resumes with every env reset",
            stacklevel=3,
        )
        return None
    arrays = _read_npz(path, _nbytes(template))
    stored = [arrays.get(f"env_{i:04d}") for i in range(len(template))]
    problem = _mismatch(stored, template) or (
        f"{len(arrays)} arrays, expected {len(template)}" if len(arrays) != len(template) else ""
    )
    if problem:
        warnings.warn(
            f"the env state of {folder.name} does not fit this run's envs ({problem}; another "
            "num_envs?): the run resumes with every env reset",
            stacklevel=3,
        )
        return None
    return stored


def _nbytes(template: list[Any]) -> int:
    """The bytes the arrays of ``template`` hold (what a file that fits them may declare)."""
    return sum(
        int(np.prod(np.shape(leaf))) * np.dtype(getattr(leaf, "dtype", np.float32)).itemsize
        for leaf in template
    )


def _read_npz(path: Path, expected_bytes: int) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` (no pickles), none larger, and all together no larger, than
    the ``expected_bytes`` its template holds (plus 1 MiB): sizes are checked before anything
    is allocated (:func:`~mjx_arm.inputs.read_npz_members`).

    Raises:
        ResumeStateError: missing, not a regular file inside the run directory, not an npz (a
            file cut short included), holding pickled objects, or declaring more bytes than
            its template holds.
    """
    limit = expected_bytes + MiB
    try:
        return read_npz_members(
            path, "resume state", max_member_bytes=limit, max_total_bytes=limit,
            error=ResumeStateError, within=path.absolute().parents[2],  # the run directory
        )  # fmt: skip
    except OversizedInputError as err:
        raise ResumeStateError(
            f"{path} declares more than this run's state holds ({str(err)[:160]}); delete the "
            "checkpoint to resume from the one before"
        ) from err
    except ResumeStateError as err:
        raise ResumeStateError(
            f"{path} cannot be read ({str(err)[:200]}); delete the checkpoint to resume from "
            "the one before"
        ) from err


def _mismatch(stored: list[Any], template: list[Any]) -> str:
    """The first array of ``stored`` that is missing or differs from ``template`` in shape or
    dtype, described ("" where all fit)."""
    for i, (got, want) in enumerate(zip(stored, template, strict=True)):
        if got is None:
            return f"array {i} is missing"
        shape, dtype = tuple(np.shape(want)), np.dtype(getattr(want, "dtype", np.float32))
        if got.shape != shape or got.dtype != dtype:
            return f"array {i} is {got.dtype}{list(got.shape)}, expected {dtype}{list(shape)}"
    return ""
