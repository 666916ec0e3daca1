"""A trajectory file read under bounds, and the run directory it belongs to.

:func:`mjx_arm.replay.load_trajectory` reads a trajectory ``.npz`` through
:func:`read_trajectory_members`: each member is refused before it is unpacked when it is over
its limit, the arrays by bytes and by elements (:data:`TRAJECTORY_MEMBER_ELEMENTS`: bytes alone
let a uint8 or bool array through that the plot widens eightfold; 10 M steps of them, 257 kB
packed, took 3.35 GB), the ``*_config`` JSON texts by bytes (:data:`TRAJECTORY_JSON_BYTES`);
then :func:`check_steps` bounds the steps. A trajectory names its task and arm itself, or takes
them from its run's ``config.json``, found only where training writes the file
(:func:`run_config_of`).
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from mjx_arm.inputs import InputError, MiB, read_npz_members

# Steps of one trajectory: twice the longest episode a task allows (TaskConfig.episode_steps,
# 100,000); elements of one array: as many steps of 64 numbers (an observation has at most 40).
TRAJECTORY_MAX_STEPS = 200_000
TRAJECTORY_MEMBER_ELEMENTS = 64 * TRAJECTORY_MAX_STEPS
# The ``*_config`` members: JSON texts of a few kB.
TRAJECTORY_JSON_BYTES = MiB


class TrajectoryError(InputError, ValueError):
    """A file that is not a usable trajectory (not an .npz, keys missing, bad shapes)."""


def read_trajectory_members(
    path: Path, keys: Iterable[str], member_bytes: int, total_bytes: int
) -> dict[str, Any]:
    """The members ``keys`` of a trajectory ``.npz``: arrays of at most ``member_bytes`` and
    :data:`TRAJECTORY_MEMBER_ELEMENTS` each, ``*_config`` texts of at most
    :data:`TRAJECTORY_JSON_BYTES`, each group at most ``total_bytes``; each refused before it is
    unpacked (:func:`~mjx_arm.inputs.read_npz_members`).

    Raises:
        OversizedInputError: a member or a group over its limit.
        TrajectoryError: not a readable ``.npz``.
    """
    keys = frozenset(keys)
    texts = {k for k in keys if k.endswith("_config")}
    groups = (
        (lambda k: k in keys and k not in texts, member_bytes),
        (texts.__contains__, TRAJECTORY_JSON_BYTES),
    )
    traj: dict[str, Any] = {}
    for wanted, limit in groups:
        traj |= read_npz_members(
            path,
            "trajectory",
            wanted,
            max_member_bytes=limit,
            max_total_bytes=total_bytes,
            error=TrajectoryError,
            max_member_elements=TRAJECTORY_MEMBER_ELEMENTS,
        )
    return traj


def check_steps(path: Path, traj: dict[str, Any]) -> None:
    """At most :data:`TRAJECTORY_MAX_STEPS` steps (first dimension) in every array of ``traj``.

    Raises:
        TrajectoryError: an array of more steps, named.
    """
    for key, value in traj.items():
        steps = value.shape[0] if getattr(value, "ndim", 0) else 0
        if steps > TRAJECTORY_MAX_STEPS:
            raise TrajectoryError(
                f"{path}: {key} holds {steps:,} steps, over the limit of "
                f"{TRAJECTORY_MAX_STEPS:,} for a trajectory (twice the longest episode)"
            )


def run_config_of(path: str | Path) -> Path | None:
    """The ``config.json`` of the run whose checkpoint holds the trajectory ``path``, where it
    lies as training writes it (``RUN/checkpoints/step_N/transitions.npz`` beside the
    checkpoint's ``meta.json``); None for a file anywhere else, whatever ``config.json`` lies
    in a folder above it."""
    path = Path(path).resolve()
    step, checkpoints = path.parent, path.parent.parent
    in_checkpoint = (
        path.name == "transitions.npz"
        and re.fullmatch(r"step_\d+", step.name) is not None
        and checkpoints.name == "checkpoints"
        and (step / "meta.json").is_file()
    )
    config = checkpoints.parent / "config.json"
    return config if in_checkpoint and config.is_file() else None
