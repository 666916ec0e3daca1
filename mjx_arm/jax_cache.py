"""JAX's persistent compilation cache, shared by every command that compiles, and the lines a
command prints while it compiles (:class:`CompileClock`)."""

from __future__ import annotations

import os
import sys
import threading
import time
from pathlib import Path
from typing import Any

DEFAULT_FOLDER = Path.home() / ".cache" / "mjx_arm" / "jax"


def enable_compilation_cache() -> None:
    """Turn on JAX's persistent compilation cache under ``~/.cache/mjx_arm/jax``
    (``MJX_ARM_JAX_CACHE`` overrides the folder).

    Every compiled program is kept, however small: JAX's default keeps only those that took
    1 s or more, and a new process then compiles dozens of small programs again (a few
    tenths of a second each on a GPU). Programs with host callbacks (the C MuJoCo backend's
    physics) are never kept: JAX cannot store them.
    """
    import jax

    jax.config.update("jax_compilation_cache_dir", str(cache_folder()))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)


def cache_folder() -> Path:
    """Where JAX's compilation cache lives: ``MJX_ARM_JAX_CACHE``, else
    ``~/.cache/mjx_arm/jax``."""
    return Path(os.environ.get("MJX_ARM_JAX_CACHE", str(DEFAULT_FOLDER)))


class CompileClock:
    """Lines on stderr while a program compiles, so that a long compile is not silence: one
    when it starts, one every ``every`` seconds with the time so far, and the total when
    :meth:`stop` is called (lines, not a redrawn bar: they read the same in a log file).

    Args:
        what: what compiles ("the batched env (MJX on the CPU)").
        hint: said on the first line (how long it may take, what is faster); "" for none.
        every: seconds between lines.
        stream: where the lines go (default: stderr).
    """

    def __init__(self, what: str, hint: str = "", every: float = 15.0, stream: Any = None):
        self.what, self.every = what, every
        self.stream = stream if stream is not None else sys.stderr
        self.start = time.monotonic()
        self._done = threading.Event()
        self._say(f"compiling {what}" + (f" ({hint})" if hint else "") + " ...")
        self._thread = threading.Thread(target=self._tick, name="compile-clock", daemon=True)
        self._thread.start()

    def _say(self, line: str) -> None:
        print(line, file=self.stream, flush=True)

    def _tick(self) -> None:
        while not self._done.wait(self.every):
            self._say(f"  still compiling {self.what}: {time.monotonic() - self.start:.0f} s")

    def stop(self) -> float:
        """End the lines with the total (only the first call says it); returns the seconds."""
        seconds = time.monotonic() - self.start
        if not self._done.is_set():
            self._done.set()
            self._thread.join()
            self._say(f"compiled {self.what} in {seconds:.0f} s")
        return seconds
