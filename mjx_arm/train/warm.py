"""What a warm trainer (``mjx-arm serve``) keeps from one run to the next in its process.

A run started in a process of its own spends its first seconds importing JAX, MuJoCo and Brax,
building the envs (MuJoCo Warp's model and kernels) and tracing and lowering its programs (the
reset, the training step's rollout and update, the evaluation); XLA's persistent cache spares
only the compiles. A process that trains run after run keeps all of it: the envs and the compiled
programs of the last config it trained, for the next run of the same config. Only the seed may
differ, and it enters the programs as data (the keys), so a run on kept programs trains exactly
as it would in a fresh process (``tests/test_server.py`` compares them metric by metric).

Nothing is kept unless :func:`enable` was called (the server calls it): an ordinary
``mjx-arm train`` process trains once and keeps nothing. One record is kept, the last config's:
the envs hold GPU buffers, and a server that trains many configs should not hold them all.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import itertools
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

# Files under an arm's folder (the first found) whose times and sizes key its envs: a mesh
# changed in place builds new envs.
MAX_ARM_FILES = 2000


@dataclass
class Programs:
    """A run's compiled programs, for the next run of its config.

    Attributes:
        learner: networks, loss and optimiser (its jitted init traced once).
        epoch: the compiled training epoch (``EpochPrograms``).
        reset: the compiled reset ``keys [num_envs, 2] -> env_state``.
        evaluator: the evaluator that holds the compiled evaluation (or its compile aside).
    """

    learner: Any
    epoch: Any
    reset: Callable
    evaluator: Any


@dataclass
class Record:
    """The envs of one config (all but its seed) and, once a run compiled them, its programs."""

    key: str
    env: Any
    eval_env: Any
    programs: Programs | None = None


_STATE: dict[str, Record | None] = {}  # "record": the one kept; no key at all: not enabled


def enable() -> None:
    """Keep envs and programs between runs in this process (a warm trainer)."""
    _STATE.setdefault("record", None)


def enabled() -> bool:
    """Whether this process keeps envs and programs between runs."""
    return "record" in _STATE


def disable() -> None:
    """Keep nothing from now on, and drop what is kept (its buffers go with it)."""
    _STATE.clear()


def config_key(config: Any, setup: Any) -> str:
    """A digest of everything a run's envs and programs are built from but its seed: the
    training config (``TrainConfig``), the resolved task and arm (``ArmTask``) and the arm's
    files (the URDF's text, the times and sizes of the files beside it)."""
    fields = {k: v for k, v in dataclasses.asdict(config).items() if k != "seed"}
    digest = hashlib.sha256(json.dumps(fields, sort_keys=True, default=str).encode())
    digest.update(repr(setup).encode())
    urdf = Path(getattr(setup.arm, "urdf", ""))
    if urdf.is_file():
        digest.update(urdf.read_bytes())
        for path in sorted(itertools.islice(urdf.parent.rglob("*"), MAX_ARM_FILES)):
            with contextlib.suppress(OSError):  # a dangling link
                stat = path.stat()
                digest.update(f"{path}:{stat.st_mtime_ns}:{stat.st_size}".encode())
    return digest.hexdigest()


def envs(config: Any, setup: Any, build: Callable[[], tuple[Any, Any]]) -> tuple[Any, Any, bool]:
    """The training and evaluation envs of ``config`` on ``setup``: the kept ones where the
    last run's config was the same but for its seed, else ``build()`` (kept where enabled).

    Returns:
        ``(env, eval_env, kept)``: ``kept`` True where they come from an earlier run.
    """
    if not enabled():
        return (*build(), False)
    key = config_key(config, setup)
    record = _STATE["record"]
    if record is not None and record.key == key:
        return record.env, record.eval_env, True
    _STATE["record"] = None  # the old envs go before the new ones take memory
    env, eval_env = build()
    _STATE["record"] = Record(key, env, eval_env)
    return env, eval_env, False


def keep_programs(env: Any, programs: Programs) -> None:
    """Keep ``programs`` with the kept envs whose training env is ``env`` (if any)."""
    record = _STATE.get("record")
    if record is not None and record.env is env:
        record.programs = programs


def programs_of(env: Any) -> Programs | None:
    """The kept programs of the config whose training env is ``env`` (None: none yet)."""
    record = _STATE.get("record")
    return record.programs if record is not None and record.env is env else None
