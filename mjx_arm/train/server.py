"""``mjx-arm serve``: a warm trainer that runs ``mjx-arm train --server`` commands one at a time.

A training command started in a new process spends seconds before its first epoch: importing
JAX, MuJoCo and Brax, building the envs and tracing its programs (docs/training.md, "A warm
trainer"). The server pays them once. Each command it runs trains in its process as
``mjx-arm train`` would, into the run directory the command names, and keeps the envs and
compiled programs of its config (:mod:`mjx_arm.train.warm`) for the next command of the same
config: a new seed starts training at once.

The server takes ``train`` commands of one process on the devices it sees: it refuses several
devices or hosts (they start processes of their own), ``--deterministic`` (set before the
devices start) and a client of other ``CUDA_VISIBLE_DEVICES`` or other mjx_arm code; the client
then trains in its own process. It stops when idle for ``--idle-minutes`` or on Ctrl-C.
"""

from __future__ import annotations

import _thread
import argparse
import contextlib
import gc
import io
import os
import socket
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from mjx_arm.inputs import ConfigError
from mjx_arm.train.distributed import ProcessGroup
from mjx_arm.train.server_protocol import Reader, code_digest, send

EXIT_INTERRUPTED = 130
EXIT_FRONT_GONE = 143  # a process of a group whose front ended: as one ended by SIGTERM
FRONT_PID = "MJX_ARM_FRONT_PID"  # the front of a group (mjx_arm.train.server_group)
Command = Callable[[list[str]], int]  # a command line -> its exit code
Parse = Callable[[list[str]], argparse.Namespace]  # a command line -> its parsed flags


class _Stream(io.TextIOBase):
    """A text stream whose writes go to the client as ``{name: text}`` messages."""

    def __init__(self, sock: socket.socket, name: str, tty: bool, lock: threading.Lock) -> None:
        self._sock, self._name, self._tty, self._lock = sock, name, tty, lock

    def write(self, text: str) -> int:
        with self._lock, contextlib.suppress(OSError):  # a client gone: its watcher stops the run
            send(self._sock, {self._name: text})
        return len(text)

    def isatty(self) -> bool:
        return self._tty

    @property
    def encoding(self) -> str:
        return "utf-8"


class _Watch:
    """Stops the run (as Ctrl-C does) when its client goes away before the run ends."""

    def __init__(self, sock: socket.socket) -> None:
        self.done = threading.Event()
        self.fired = False
        threading.Thread(target=self._wait, args=(sock,), daemon=True).start()

    def _wait(self, sock: socket.socket) -> None:
        with contextlib.suppress(OSError):
            while sock.recv(4096):
                pass
        if not self.done.is_set():
            self.fired = True
            _thread.interrupt_main()


def refusal(
    request: dict[str, Any], code: str, devices: str | None, parse: Parse, processes: int = 1
) -> str:
    """Why this server cannot run ``request`` ("" where it can); ``parse`` reads its command
    line (``argv -> argparse.Namespace``, ``mjx-arm``'s parser). ``processes``: the count of
    processes joined in this warm trainer (:mod:`mjx_arm.train.server_group`; 1 alone), which
    take ``--devices`` of that count only."""
    if request.get("code") != code:
        return "it runs other mjx_arm code (started before a change); restart it"
    if request.get("devices") != devices:
        return f"it trains on CUDA_VISIBLE_DEVICES={devices}, the command on {request['devices']}"
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            args = parse(request["argv"])
    except SystemExit:
        return ""  # a bad command line: the run reports it as a local one would
    if args.command != "train":
        return "it runs mjx-arm train commands only"
    if args.hosts or args.coordinator:
        return "several hosts train in processes of their own"
    if processes > 1 and args.devices != processes:
        return f"it trains on {processes} GPUs joined: give --devices {processes}"
    if processes == 1 and (args.devices or 0) > 1:
        return (
            "several devices train in processes of their own (a warm trainer of several GPUs: "
            "mjx-arm serve --devices N)"
        )
    if args.deterministic:
        return "--deterministic is set before the devices start"
    return ""


@contextlib.contextmanager
def _as_client(sock: socket.socket, request: dict[str, Any]) -> Iterator[None]:
    """The client's output streams, working folder and ``MJX_ARM_*`` environment, for the
    block; this process's own given back after it."""
    lock = threading.Lock()
    tty = request.get("tty", [False, False])
    saved = sys.stdout, sys.stderr, os.getcwd(), dict(os.environ)
    try:
        sys.stdout = _Stream(sock, "out", bool(tty[0]), lock)
        sys.stderr = _Stream(sock, "err", bool(tty[1]), lock)
        os.chdir(request["cwd"])
        os.environ.update({k: v for k, v in request["env"].items() if k.startswith("MJX_ARM_")})
        yield
    finally:
        sys.stdout, sys.stderr = saved[0], saved[1]
        os.chdir(saved[2])
        os.environ.clear()
        os.environ.update(saved[3])


def run_request(sock: socket.socket, request: dict[str, Any], command: Command) -> tuple[int, bool]:
    """Run the request's command line with ``command`` (``argv -> exit code``, ``mjx-arm``'s
    entry point) here, its output to the client; (exit code, whether the client went away)."""
    watch = _Watch(sock)
    try:
        with _as_client(sock, request):
            try:
                code = command(list(request["argv"]))
            except SystemExit as stop:  # a bad command line (argparse)
                code = stop.code if isinstance(stop.code, int) else 1
            except KeyboardInterrupt:
                print("interrupted", file=sys.stderr)
                code = EXIT_INTERRUPTED
            except Exception:  # a bug: its traceback to the client, the server goes on
                traceback.print_exc()
                code = 1
            watch.done.set()
    except KeyboardInterrupt:  # the client went away just as the run ended
        code = EXIT_INTERRUPTED
    finally:
        watch.done.set()
        gc.collect()  # the run's device buffers, before the next run allocates its own
    return code, watch.fired


class Server:
    """The warm trainer listening at ``path``: it runs each command line with ``command``
    (``argv -> exit code``) once ``parse`` (``argv -> Namespace``) shows it can
    (:func:`refusal`), and stops after ``idle_s`` seconds without a command (0: never)."""

    def __init__(
        self,
        path: Path,
        command: Command,
        parse: Parse,
        idle_s: float = 0.0,
        log=print,
        warmup: list[str] | None = None,
    ) -> None:
        self.path, self.idle_s, self.log = path, idle_s, log
        self.command, self.parse = command, parse
        self.warmup = warmup  # `mjx-arm warmup` arguments to run before the first command
        self.code = code_digest()
        self.devices = os.environ.get("CUDA_VISIBLE_DEVICES")
        self.group = ProcessGroup.from_env()  # set where a joined warm trainer started this one
        self.served = 0

    def start(self) -> socket.socket:
        """Import the trainer, start the devices and listen (a stale socket file replaced)."""
        free_socket_path(self.path)
        start = time.monotonic()
        if self.group.joined:
            watch_front()  # a process of a group ends with its front
        self.group.join()  # before JAX starts; alone: nothing
        import jax

        from mjx_arm.jax_cache import enable_compilation_cache
        from mjx_arm.train import ppo, warm  # noqa: F401  (imported once, here)

        enable_compilation_cache()
        warm.enable()
        devices = jax.devices()
        sock = listen_at(self.path, self.idle_s)
        joined = self.group.num_processes
        place = f", process {self.group.process_id} of {joined}" if joined > 1 else ""
        self.log(
            f"warm trainer ready in {time.monotonic() - start:.1f} s on {devices} (pid "
            f"{os.getpid()}{place}); train with: MJX_ARM_SERVER={self.path} mjx-arm train "
            "--server ..."
        )
        return sock

    def serve_forever(self) -> int:
        """Run the warmup (if any), then serve commands one at a time until idle or Ctrl-C;
        returns 0, or the warmup's exit code where it failed."""
        sock = self.start()
        with until_stopped(sock, self.path, self.log):
            if self.warmup is not None and (code := self.command(["warmup", *self.warmup])):
                self.log(f"warmup {' '.join(self.warmup)}: exit {code}; stopped")
                return code
            while self._serve_one(sock):
                pass
        return 0

    def _serve_one(self, sock: socket.socket) -> bool:
        """Serve the next command; False once idle for ``idle_s``."""
        return serve_one(sock, self.idle_s, self._answer, self.log)

    def _answer(self, conn: socket.socket, request: dict[str, Any]) -> None:
        """Answer a request: a ping, or a command to run."""
        if request.get("ping"):  # a ping that gave up meanwhile (a long warmup) wants no answer
            with contextlib.suppress(OSError):
                send(conn, {"pong": os.getpid(), "code": self.code, "served": self.served})
            return
        self._run(conn, request)

    def _run(self, conn: socket.socket, request: dict[str, Any]) -> None:
        why = refusal(request, self.code, self.devices, self.parse, self.group.num_processes)
        if why:
            send(conn, {"refused": why})
            return
        send(conn, {"accepted": os.getpid()})
        start = time.monotonic()
        code, gone = run_request(conn, request, self.command)
        with contextlib.suppress(OSError):
            send(conn, {"exit": code})
        self.served += 1
        ended = "the client went away" if gone else f"exit {code}"
        command = " ".join(request["argv"])
        self.log(f"{command}: {ended} after {time.monotonic() - start:.1f} s")


def free_socket_path(path: Path) -> None:
    """Make ``path`` ready for a server to listen at: its folder made (mode 0700) and this
    user's, a stale socket file removed.

    Raises:
        ConfigError: a server already listens at ``path``, or its folder is another user's.
    """
    from mjx_arm.train.client import ping

    if path.exists() and ping(path) is not None:
        raise ConfigError(f"a warm trainer already listens at {path}; stop it first")
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    if path.parent.stat().st_uid != os.getuid():  # whoever can connect runs commands
        raise ConfigError(f"{path.parent} belongs to another user: give --socket")
    path.unlink(missing_ok=True)


def listen_at(path: Path, idle_s: float) -> socket.socket:
    """A socket listening at ``path`` (made ready by :func:`free_socket_path`), this user's
    only, whose ``accept`` gives up after ``idle_s`` seconds (0: never)."""
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.bind(str(path))
    os.chmod(path, 0o600)  # this user's commands only
    sock.listen(16)
    sock.settimeout(idle_s or None)
    return sock


@contextlib.contextmanager
def until_stopped(sock: socket.socket, path: Path, log) -> Iterator[None]:
    """The block serves on ``sock`` until it returns or Ctrl-C ends it (logged); the socket
    is closed and its file at ``path`` removed either way."""
    try:
        yield
    except KeyboardInterrupt:
        log("stopped (Ctrl-C)")
    finally:
        sock.close()
        path.unlink(missing_ok=True)


def serve_one(
    sock: socket.socket, idle_s: float, answer: Callable[[socket.socket, dict], None], log
) -> bool:
    """Accept the next connection on ``sock`` and ``answer`` its request (garbage and a
    client gone before its answer are logged, the server goes on); False once idle for
    ``idle_s`` seconds."""
    try:
        conn, _ = sock.accept()
    except TimeoutError:
        log(f"idle for {idle_s:.0f} s: stopped")
        return False
    with conn:
        try:
            request = Reader(conn).next()
            if isinstance(request, dict):
                answer(conn, request)
        except (OSError, ValueError, KeyError, TypeError) as err:  # a client gone, or garbage
            log(f"a connection ended without its answer ({type(err).__name__}: {err})")
    return True


def watch_front(interval_s: float = 1.0) -> None:
    """In a process of a group: end this process, at once, when the front that started it
    (``MJX_ARM_FRONT_PID``) has ended, even killed (``SIGKILL``), so that no process holds its
    GPU with nobody to stop it. Nothing where no front started this process."""
    front = os.environ.get(FRONT_PID)
    if not front or not front.isdigit():
        return

    def watch() -> None:
        while os.getppid() == int(front):
            time.sleep(interval_s)
        os._exit(EXIT_FRONT_GONE)

    threading.Thread(target=watch, daemon=True, name="front-watch").start()
