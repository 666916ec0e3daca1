"""``mjx-arm serve --devices N``: a warm trainer of N GPUs, a process per GPU joined once.

``train --devices N`` on MuJoCo Warp starts a process per GPU (:mod:`mjx_arm.train.launch`),
and each new process pays the imports, the devices' start, ``jax.distributed``'s join, the envs
and the traces again before its first epoch. This front keeps N warm trainers
(:class:`~mjx_arm.train.server.Server`, one per GPU, each started with its place in the group)
joined for as long as it runs, and hands each ``train --devices N --server`` command to all of
them: process 0's output goes back to the client, the others' to their logs (beside the
socket: ``SOCKET.pK.log``), and a new seed of a config they trained starts at once on every GPU.

The front itself never imports JAX: each GPU's memory is left to the process that trains on it.
A run that did not end the same way on every process (a client gone, a crash, a bug) may have
left the processes at different collectives, so the front then stops them all and starts the
group again (a cold start for the next command), as ``train --devices N`` would for a new run.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from mjx_arm.inputs import ConfigError
from mjx_arm.train.distributed import (
    ENV_COORDINATOR,
    ENV_HOST_RANK,
    ENV_HOSTS,
    ENV_NUM_PROCESSES,
    ENV_PROCESS_ID,
    Hosts,
)
from mjx_arm.train.launch import plan, stop_processes
from mjx_arm.train.server import (
    EXIT_INTERRUPTED,
    FRONT_PID,
    Parse,
    free_socket_path,
    listen_at,
    refusal,
    serve_one,
    until_stopped,
)
from mjx_arm.train.server_protocol import Reader, code_digest, send

READY_TIMEOUT_S = 600.0  # the processes' imports, devices' start and join, at most
CHILD_IDLE_MARGIN_MIN = 5.0  # minutes a process waits past the front's own idle limit
STOP_S = 30.0  # how long a stopped run's processes get to end before the group restarts
# What places a process in its group: the client's values never replace a child's own.
GROUP_VARIABLES = (
    ENV_COORDINATOR,
    ENV_NUM_PROCESSES,
    ENV_PROCESS_ID,
    ENV_HOSTS,
    ENV_HOST_RANK,
    "MJX_ARM_JOIN_TIMEOUT",
    FRONT_PID,
)
# Exit codes after which the group goes on: a run every process ended alike, by its end or a
# named error (a bug, 1, or an interruption may have stopped them at different collectives).
KEEPS_GROUP = (0, 2)


def group_gpus(count: int, warmup: list[str] | None = None) -> list[str]:
    """The first ``count`` GPUs of this host (``CUDA_VISIBLE_DEVICES`` entries) for
    ``serve --devices count``.

    Raises:
        ConfigError: fewer GPUs than ``count``, or a ``--warmup`` (a joined group builds its
            programs with its first command).
    """
    from mjx_arm.train.launch import visible_gpus

    if warmup is not None:
        raise ConfigError(
            "serve --devices N takes no --warmup: the group's first command builds the envs "
            "and programs (drop --warmup, or use it with one GPU)"
        )
    gpus = visible_gpus()
    if len(gpus) < count:
        raise ConfigError(
            f"serve --devices {count} needs {count} GPUs; this host shows {len(gpus)} to JAX "
            "(CUDA_VISIBLE_DEVICES, JAX_PLATFORMS and the CUDA plugin decide which)"
        )
    return gpus[:count]


class ServerGroup:
    """A warm trainer per GPU of ``gpus`` (``CUDA_VISIBLE_DEVICES`` entries), joined by
    ``jax.distributed``, behind the socket ``path``; it stops after ``idle_s`` seconds without a
    command (0: never). ``parse`` reads a command line (``argv -> Namespace``); ``env`` is the
    children's environment (default: this process's)."""

    def __init__(
        self,
        path: Path,
        parse: Parse,
        gpus: list[str],
        idle_s: float = 0.0,
        log=print,
        env: dict[str, str] | None = None,
    ) -> None:
        if len(gpus) < 2:
            raise ConfigError(f"a joined warm trainer needs 2 GPUs or more, got {gpus}")
        self.path, self.parse, self.gpus = path, parse, list(gpus)
        self.idle_s, self.log = idle_s, log
        self.env = dict(os.environ if env is None else env)
        self.code = code_digest()
        self.devices = self.env.get("CUDA_VISIBLE_DEVICES")
        self.served = 0
        self.restarts = 0
        self.sockets = [path.with_name(f"{path.name}.p{i}") for i in range(len(gpus))]
        self.logs = [path.with_name(f"{path.name}.p{i}.log") for i in range(len(gpus))]
        self._procs: list[subprocess.Popen] = []

    def start_processes(self) -> None:
        """Start a warm trainer per GPU, each with its place in a new group, and wait until
        every one answers (they answer once all have joined).

        Raises:
            ConfigError: a process that ended, or did not answer within READY_TIMEOUT_S.
        """
        from mjx_arm.train.client import ping

        start = time.monotonic()
        groups = plan(Hosts(), len(self.gpus), self.gpus, per_gpu=True).groups
        for gpu, group, path, log in zip(self.gpus, groups, self.sockets, self.logs, strict=True):
            env = {**self.env, **group.env(), "CUDA_VISIBLE_DEVICES": gpu}
            env[FRONT_PID] = str(os.getpid())
            command = [sys.executable, "-m", "mjx_arm.cli", "serve", "--socket", str(path)]
            with log.open("ab") as out:
                self._procs.append(
                    subprocess.Popen(
                        [*command, "--idle-minutes", f"{self._child_idle_minutes():g}"],
                        env=env,
                        stdout=out,
                        stderr=subprocess.STDOUT,
                    )
                )
        for gpu, path, proc in zip(self.gpus, self.sockets, self._procs, strict=True):
            while ping(path) is None:
                if proc.poll() is not None or time.monotonic() - start > READY_TIMEOUT_S:
                    self.stop_processes()
                    raise ConfigError(
                        f"the warm trainer of GPU {gpu} did not start; its log: "
                        f"{self.logs[self.gpus.index(gpu)]}"
                    )
                time.sleep(0.2)
        self.log(
            f"{len(self.gpus)} warm trainers joined in {time.monotonic() - start:.1f} s, one "
            f"per GPU ({', '.join(self.gpus)}); their logs: {self.logs[0]} ..."
        )

    def _child_idle_minutes(self) -> float:
        """A process's own idle limit: the front's and a margin (the front stops them first;
        a process also ends within seconds of its front's end,
        :func:`~mjx_arm.train.server.watch_front`)."""
        return self.idle_s / 60.0 + CHILD_IDLE_MARGIN_MIN if self.idle_s else 0.0

    def stop_processes(self) -> None:
        """Stop every process of the group (Ctrl-C, then killed after STOP_S)."""
        stop_processes(self._procs, signal.SIGINT, STOP_S)
        self._procs = []

    def serve_forever(self) -> int:
        """Start the group, then serve commands one at a time until idle, Ctrl-C or SIGTERM
        (the group stopped with it); 0."""
        free_socket_path(self.path)
        sock = listen_at(self.path, self.idle_s)
        previous = signal.signal(signal.SIGTERM, _interrupt)  # a timeout's stop: as Ctrl-C
        try:
            with until_stopped(sock, self.path, self.log):
                self.start_processes()
                self.log(f"train with: MJX_ARM_SERVER={self.path} mjx-arm train --server ...")
                while self._serve_one(sock):
                    pass
        finally:
            self.stop_processes()
            signal.signal(signal.SIGTERM, previous)
        return 0

    def _serve_one(self, sock: socket.socket) -> bool:
        """Serve the next connection; False once idle for ``idle_s``."""
        return serve_one(sock, self.idle_s, self._answer, self.log)

    def _answer(self, conn: socket.socket, request: dict[str, Any]) -> None:
        """Answer a ping, or run a command on every process of the group."""
        if request.get("ping"):
            with contextlib.suppress(OSError):
                pong = {"pong": os.getpid(), "code": self.code, "served": self.served}
                send(conn, {**pong, "restarts": self.restarts})
            return
        why = refusal(request, self.code, self.devices, self.parse, len(self.gpus))
        if why:
            send(conn, {"refused": why})
            return
        if any(p.poll() is not None for p in self._procs):
            self._restart("a process of the group had ended")
        start = time.monotonic()
        codes, gone = self._run(conn, self.child_request(request))
        ended = "the client went away" if gone else f"exit {codes[0]}"
        self.served += 1
        self.log(f"{' '.join(request['argv'])}: {ended} after {time.monotonic() - start:.1f} s")
        if gone or len(set(codes)) > 1 or codes[0] not in KEEPS_GROUP:
            self._restart(f"the run ended with exit codes {codes} (client gone: {gone})")

    def child_request(self, request: dict[str, Any]) -> dict[str, Any]:
        """``request`` as every process runs it: one run directory named for all of them (the
        client's folder as the base of a relative one) and the client's environment without
        the variables that place a process in its group."""
        args = self.parse(list(request["argv"]))
        argv = list(request["argv"])
        if not args.run_dir and not args.resume:
            from mjx_arm.train.cli import default_run_dir

            run_dir = Path(request["cwd"]) / default_run_dir(args)
            argv += ["--run-dir", str(run_dir)]
        env = {k: v for k, v in request["env"].items() if k not in GROUP_VARIABLES}
        return {**request, "argv": argv, "env": env}

    def _run(self, conn: socket.socket, request: dict[str, Any]) -> tuple[list[int], bool]:
        """Run ``request`` on every process; process 0's output to ``conn``. Returns each
        process's exit code (EXIT_INTERRUPTED for one that did not end within STOP_S of its
        run being stopped) and whether the client went away."""
        links = [_Link(path, {**request, "devices": gpu}) for path, gpu in self._pairs()]
        refused = next((link.refused for link in links if link.refused), "")
        if refused:
            for link in links:
                link.close()
            send(conn, {"refused": f"a process of the group refused it: {refused}"})
            return [2] * len(links), False
        send(conn, {"accepted": os.getpid()})
        links[0].sink = lambda message: _forward(conn, message)
        for link, log in zip(links[1:], self.logs[1:], strict=True):
            link.sink = _to_log(log)
        for link in links:
            link.start()
        why = _wait_run(conn, links)
        if why:
            _stop_run(links)
        if why == "process":
            lost = [i for i, link in enumerate(links) if link.lost]
            _forward(conn, {"err": f"error: process {lost[0]} of the group ended during the run\n"})
        codes = [EXIT_INTERRUPTED if link.code is None else link.code for link in links]
        with contextlib.suppress(OSError):
            send(conn, {"exit": codes[0] or int(why == "process")})
        for link in links:
            link.close()
        return codes, why == "client"

    def _pairs(self) -> list[tuple[Path, str]]:
        return list(zip(self.sockets, self.gpus, strict=True))

    def _restart(self, why: str) -> None:
        """Stop every process and start the group again."""
        self.log(f"{why}: restarting the group")
        self.stop_processes()
        self.restarts += 1
        self.start_processes()


class _Link:
    """One process's side of a run: the request sent, its answer read."""

    def __init__(self, path: Path, request: dict[str, Any]) -> None:
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.code: int | None = None
        self.sink = _dropped
        try:
            self.sock.connect(str(path))
            send(self.sock, request)
            self.reader = Reader(self.sock)
            answer = self.reader.next() or {"refused": "it closed the connection"}
        except OSError as err:
            answer = {"refused": f"no answer at {path} ({err.strerror or err})"}
        self.refused = str(answer.get("refused", ""))

    def start(self) -> None:
        """Pump the process's output on a thread of its own (:meth:`pump`)."""
        self.thread = threading.Thread(target=self.pump, daemon=True)
        self.thread.start()

    def pump(self) -> None:
        """Pass the process's output to ``sink`` until its exit code comes (or it ends)."""
        with contextlib.suppress(OSError, ValueError):
            while (message := self.reader.next()) is not None:
                if "exit" in message:
                    self.code = int(message["exit"])
                    return
                self.sink(message)

    @property
    def running(self) -> bool:
        """Whether the process's run has not answered yet."""
        return self.thread.is_alive()

    @property
    def lost(self) -> bool:
        """Whether the process went away without its exit code (it died, or its server)."""
        return not self.thread.is_alive() and self.code is None

    def end_request(self) -> None:
        """Tell the process its client went away (the output still comes back)."""
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_WR)

    def close(self) -> None:
        self.sock.close()


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def _forward(conn: socket.socket, message: dict[str, Any]) -> None:
    with contextlib.suppress(OSError):  # a client gone: the front's watch stops the run
        send(conn, message)


def _dropped(message: dict[str, Any]) -> None:
    """Output nobody reads (a link's before its run starts)."""


def _to_log(path: Path):
    """A sink that appends a process's output to its log (``message -> None``)."""

    def write(message: dict[str, Any]) -> None:
        with path.open("a", encoding="utf-8") as out:
            out.write(message.get("out", "") + message.get("err", ""))

    return write


def _wait_run(conn: socket.socket, links: list[_Link]) -> str:
    """Wait until every process answered its exit code (""), the client went away first
    ("client": its end of ``conn`` closed), or a process went away without its exit code
    ("process": the others may wait for it at a collective for ever)."""
    gone = threading.Event()

    def watch() -> None:
        with contextlib.suppress(OSError):
            while conn.recv(4096):
                pass
        gone.set()

    threading.Thread(target=watch, daemon=True).start()
    while any(link.running for link in links):
        if any(link.lost for link in links):
            return "process"
        if gone.wait(0.1) and any(link.running for link in links):
            return "client"
    return "process" if any(link.lost for link in links) else ""


def _stop_run(links: list[_Link]) -> None:
    """Stop a run on every process (each one's watcher stops it, as Ctrl-C would) and give
    them STOP_S seconds to answer."""
    for link in links:
        link.end_request()
    deadline = time.monotonic() + STOP_S
    for link in links:
        link.thread.join(max(deadline - time.monotonic(), 0.0))
