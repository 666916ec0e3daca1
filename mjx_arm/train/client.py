"""``mjx-arm train --server``: hand the command to the warm trainer that ``mjx-arm serve`` runs.

The command goes over the server's socket (:mod:`mjx_arm.train.server_protocol`) with the
working folder and the ``MJX_ARM_*`` environment, and its output comes back as it is written.
Where no server answers, or the server cannot take the command (other code, other GPUs, several
devices), a note says why and the command trains in this process as without ``--server``.
"""

from __future__ import annotations

import os
import socket
import sys
from pathlib import Path

from mjx_arm.train.server_protocol import Reader, code_digest, default_socket, send

EXIT_INTERRUPTED = 130  # as a shell reports a process stopped by Ctrl-C


def request_for(argv: list[str]) -> dict:
    """The request that runs ``argv`` (``train ...``, without ``--server``) in the server."""
    return {
        "argv": [a for a in argv if a != "--server"],
        "cwd": os.getcwd(),
        "env": {k: v for k, v in os.environ.items() if k.startswith("MJX_ARM_")},
        "code": code_digest(),
        "devices": os.environ.get("CUDA_VISIBLE_DEVICES"),
        "tty": [sys.stdout.isatty(), sys.stderr.isatty()],
    }


def train_through_server(argv: list[str], path: Path | None = None) -> int | None:
    """Run ``argv`` in the warm trainer at ``path`` (default: :func:`default_socket`), its
    output written here; the command's exit code, or None where it should run in this process
    (no server answered, or the server refused it: a note on stderr says which)."""
    path = path or default_socket()
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        sock.connect(str(path))
        send(sock, request_for(argv))
        reader = Reader(sock)
        answer = reader.next() or {"refused": "it closed the connection"}
    except OSError as err:
        _note(f"no warm trainer answers at {path} ({err.strerror or err})")
        sock.close()
        return None
    if "refused" in answer:
        _note(f"the warm trainer at {path} cannot take this command: {answer['refused']}")
        sock.close()
        return None
    try:
        return _relay(reader)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED  # closing the socket stops the run in the server
    finally:
        sock.close()


def _relay(reader: Reader) -> int:
    """Write the server's output here until its exit code comes; returns it."""
    streams = {"out": sys.stdout, "err": sys.stderr}
    while (message := reader.next()) is not None:
        if "exit" in message:
            return int(message["exit"])
        for name, stream in streams.items():
            if name in message:
                stream.write(message[name])
                stream.flush()
    print("error: the warm trainer stopped before the run ended", file=sys.stderr)
    return 1


def _note(text: str) -> None:
    print(f"note: {text}; training in this process", file=sys.stderr)


def ping(path: Path | None = None, timeout: float = 2.0) -> dict | None:
    """The server's answer to a ping (``{"pong": pid, "code": ...}``), or None where none
    answers at ``path`` within ``timeout`` seconds."""
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.settimeout(timeout)
    try:
        sock.connect(str(path or default_socket()))
        send(sock, {"ping": True})
        return Reader(sock).next()
    except (OSError, ValueError):
        return None
    finally:
        sock.close()
