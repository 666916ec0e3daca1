"""Keep PyBullet's native start-up prints off the user's terminal.

PyBullet writes ``pybullet build time: ...`` to stderr when its module loads and ``argv[0]=`` to
stdout when a client connects, from C code straight to the file descriptors, where
``contextlib.redirect_stdout`` cannot reach. :func:`native_output_silenced` points descriptors
at the null device for the length of a block.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
from collections.abc import Iterator

STDOUT, STDERR = 1, 2


def _flush() -> None:
    """Flush Python's and C's buffers, so nothing written before (or inside) the block lands on
    the wrong side of the swap."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    with contextlib.suppress(Exception):
        ctypes.CDLL(None).fflush(None)


@contextlib.contextmanager
def native_output_silenced(fds: tuple[int, ...] = (STDOUT,)) -> Iterator[None]:
    """Send everything written to the file descriptors ``fds`` inside the block to the null
    device (Python's own writes to them too).

    Exceptions raised inside the block still propagate and print after it. It swaps
    process-wide descriptors: not for use from two threads at once.
    """
    _flush()
    saved = [os.dup(fd) for fd in fds]
    try:
        with open(os.devnull, "wb") as null:
            for fd in fds:
                os.dup2(null.fileno(), fd)
            try:
                yield
            finally:
                _flush()
                for fd, copy in zip(fds, saved, strict=True):
                    os.dup2(copy, fd)
    finally:
        for copy in saved:
            os.close(copy)
