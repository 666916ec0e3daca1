"""Checkpoints written beside training: one at a time, on a thread of their own.

What a checkpoint needs from the GPU (the params, the training and env state) is copied to the
host before training goes on, since the next epoch reuses those buffers; what is left (the
recorded episode in CPU MuJoCo, the params, state and transitions files: a few tenths of a
second, about a second where the envs' state is written) runs while the next epoch trains.

- A save starts only after the one before it is on disk, so checkpoints appear in step order
  and the newest is always whole (each is still written into a hidden folder and renamed).
- A save's error (a full disk, a policy that acted NaN in the recorded episode) is raised in
  the training thread at the next save or at :meth:`CheckpointSaver.wait`; the run ends on
  it as before, at most one epoch later.
- The run's last checkpoint is waited for before the run reports that it is done.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import jax
import numpy as np


class CheckpointSaver:
    """Runs save jobs one after another on one background thread."""

    def __init__(self) -> None:
        self._pool: ThreadPoolExecutor | None = None
        self._pending: Future | None = None

    def submit(self, job: Callable[[], None]) -> None:
        """Start ``job`` once the previous job has finished (its error is raised here)."""
        self.wait()
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="checkpoint")
        self._pending = self._pool.submit(job)

    def wait(self) -> None:
        """Block until the pending job is done; raise its error, if it failed."""
        pending, self._pending = self._pending, None
        if pending is not None:
            pending.result()

    def close(self) -> None:
        """Let the pending job finish and stop the thread (an error of that job is dropped:
        close is for a run that is already ending on an error of its own; call :meth:`wait`
        first to see it)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
        self._pending = None


def host_copy(tree: Any) -> Any:
    """Every leaf of ``tree`` as a numpy array that owns its memory: a JAX array's host view
    (zero-copy on a CPU device) would follow a buffer that the next epoch reuses."""

    def own(x: Any) -> np.ndarray:
        x = np.asarray(x)
        return x if x.flags.owndata and x.flags.writeable else np.array(x, copy=True)

    return jax.tree.map(own, tree)
