"""What the warm trainer (``mjx-arm serve``) and ``mjx-arm train --server`` say to each other.

They talk over a Unix socket, one JSON object per line. The client sends one request::

    {"argv": [...], "cwd": "...", "env": {"MJX_ARM_...": "..."}, "code": "<digest>",
     "devices": "<CUDA_VISIBLE_DEVICES or null>", "tty": [false, true]}

(``{"ping": true}`` asks only whether a server listens). The server answers
``{"accepted": pid}`` or ``{"refused": "why"}``, then streams the command's output as
``{"out": "text"}`` and ``{"err": "text"}`` and ends with ``{"exit": code}``. A client that goes
away (Ctrl-C) stops its run as Ctrl-C stops a local one.

This module imports nothing heavy: the client is a short process.
"""

from __future__ import annotations

import hashlib
import json
import os
import socket
import tempfile
from pathlib import Path
from typing import Any

ENV_SOCKET = "MJX_ARM_SERVER"  # the socket's path, where not given on the command line
MAX_LINE = 1 << 20  # bytes of one message line at most (a request is a few kB)


def user_folder() -> Path:
    """The folder of this user's sockets: ``$XDG_RUNTIME_DIR/mjx-arm``, else
    ``TMPDIR/mjx-arm-UID`` (the server makes it, mode 0700, and refuses another user's)."""
    runtime = os.environ.get("XDG_RUNTIME_DIR")
    if runtime:
        return Path(runtime) / "mjx-arm"
    return Path(tempfile.gettempdir()) / f"mjx-arm-{os.getuid()}"


def default_socket() -> Path:
    """``$MJX_ARM_SERVER``, else ``trainer.sock`` in :func:`user_folder`."""
    if os.environ.get(ENV_SOCKET):
        return Path(os.environ[ENV_SOCKET])
    return user_folder() / "trainer.sock"


def code_digest() -> str:
    """A digest of this installation's mjx_arm sources (each .py file's path, time and size):
    a server started before the code changed is not used to train with the new code."""
    root = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        stat = path.stat()
        digest.update(f"{path.relative_to(root)}:{stat.st_mtime_ns}:{stat.st_size}".encode())
    return digest.hexdigest()[:16]


def send(sock: socket.socket, message: dict[str, Any]) -> None:
    """Send one message (a JSON line)."""
    sock.sendall(json.dumps(message).encode() + b"\n")


class Reader:
    """The messages arriving on a socket, one JSON line each."""

    def __init__(self, sock: socket.socket) -> None:
        self._file = sock.makefile("rb")

    def next(self) -> dict[str, Any] | None:
        """The next message; None where the other side closed the socket."""
        line = self._file.readline(MAX_LINE)
        if not line:
            return None
        return json.loads(line)
