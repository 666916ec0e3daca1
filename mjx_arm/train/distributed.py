"""The processes of one training, joined by ``jax.distributed``: one per GPU, on one host or many.

MuJoCo Warp, the default GPU physics, crashes with two GPUs in one process (its JAX foreign
call assumes the first device), so a training on several GPUs runs one process per GPU, each
seeing its own GPU alone (``CUDA_VISIBLE_DEVICES``), and JAX's own multi-controller runtime
joins them: the processes' devices form one mesh, the env batch is split over it and XLA
reduces the gradient across processes (NCCL between GPUs, gloo between CPU processes). The
same code serves one host and many: a host's processes are started by
:mod:`mjx_arm.train.launch`, and hosts are told apart by their rank.

Process 0 (the leader) evaluates, logs and writes checkpoints; every process takes part in the
collectives that decide when a run stops (:meth:`ProcessGroup.share`) and in the gathers that
save the env state.
"""

from __future__ import annotations

import os
import socket
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from mjx_arm.inputs import ConfigError, InputError

# What the launcher tells each process it starts (and what a user may set by hand).
ENV_COORDINATOR = "MJX_ARM_COORDINATOR"
ENV_NUM_PROCESSES = "MJX_ARM_NUM_PROCESSES"
ENV_PROCESS_ID = "MJX_ARM_PROCESS_ID"
# What a user sets for a job of several hosts (flags win over them); SLURM's names are read too.
ENV_HOSTS = "MJX_ARM_HOSTS"
ENV_HOST_RANK = "MJX_ARM_HOST_RANK"
DEFAULT_JOIN_TIMEOUT = 300  # seconds a process waits for the others at the start
HELLO = "mjx-arm-join"  # the first word a process sends to process 0 when it joins
_JOINED: list = []  # the group this process joined (jax.distributed starts once per process)


class JoinError(InputError):
    """The processes of a training did not all join (a host not started, a wrong address)."""


@dataclass(frozen=True)
class Hosts:
    """Where this host stands in a job of several hosts (one command per host).

    Attributes:
        coordinator: ``HOST:PORT`` of host 0, which every process connects to ("" for one host).
        count: hosts in the job.
        rank: this host's rank, 0 to ``count - 1``; host 0 runs process 0.
        join_timeout: seconds to wait for every process to join.
    """

    coordinator: str = ""
    count: int = 1
    rank: int = 0
    join_timeout: int = DEFAULT_JOIN_TIMEOUT

    def __post_init__(self) -> None:
        if self.count < 1 or not 0 <= self.rank < self.count:
            raise ConfigError(
                f"host rank {self.rank} of {self.count} hosts: give --hosts N >= 1 and a "
                "--host-rank from 0 to N-1"
            )
        if self.count > 1 and not _address_ok(self.coordinator):
            raise ConfigError(
                f"a job of {self.count} hosts needs --coordinator HOST:PORT (host 0's address "
                f"and a free port), got {self.coordinator!r}"
            )
        if self.join_timeout < 1:
            raise ConfigError(f"--join-timeout must be >= 1 s, got {self.join_timeout}")

    @staticmethod
    def from_args(
        coordinator: str | None, count: int | None, rank: int | None, join_timeout: int | None
    ) -> Hosts:
        """The flags, each one missing read from the environment: ``MJX_ARM_COORDINATOR``,
        ``MJX_ARM_HOSTS`` (else SLURM's ``SLURM_NNODES``), ``MJX_ARM_HOST_RANK`` (else
        ``SLURM_NODEID``).

        Raises:
            ConfigError: a count or rank that is not a whole number, or out of range.
        """
        env = os.environ
        count = count if count is not None else _env_int(ENV_HOSTS, "SLURM_NNODES", default=1)
        rank = rank if rank is not None else _env_int(ENV_HOST_RANK, "SLURM_NODEID", default=0)
        coordinator = coordinator if coordinator is not None else env.get(ENV_COORDINATOR, "")
        timeout = join_timeout if join_timeout is not None else DEFAULT_JOIN_TIMEOUT
        return Hosts(coordinator, count, rank, timeout)


@dataclass(frozen=True)
class ProcessGroup:
    """This process's place among the training's processes.

    Attributes:
        coordinator: ``HOST:PORT`` of process 0's coordination service ("" alone).
        num_processes: processes in the training (1: no ``jax.distributed``).
        process_id: this process's id, 0 to ``num_processes - 1``.
        join_timeout: seconds to wait for every process to join.
    """

    coordinator: str = ""
    num_processes: int = 1
    process_id: int = 0
    join_timeout: int = DEFAULT_JOIN_TIMEOUT

    @property
    def joined(self) -> bool:
        """Whether there are other processes (``jax.distributed`` is used)."""
        return self.num_processes > 1

    @property
    def leader(self) -> bool:
        """Whether this process evaluates, logs and writes the run directory."""
        return self.process_id == 0

    def env(self) -> dict[str, str]:
        """The environment variables that hand this group to a started process."""
        return {
            ENV_COORDINATOR: self.coordinator,
            ENV_NUM_PROCESSES: str(self.num_processes),
            ENV_PROCESS_ID: str(self.process_id),
            "MJX_ARM_JOIN_TIMEOUT": str(self.join_timeout),
        }

    @staticmethod
    def from_env() -> ProcessGroup:
        """The group the launcher handed this process (alone where none was)."""
        env = os.environ
        if ENV_PROCESS_ID not in env or ENV_NUM_PROCESSES not in env:
            return ProcessGroup()
        return ProcessGroup(
            env.get(ENV_COORDINATOR, ""),
            _env_int(ENV_NUM_PROCESSES, default=1),
            _env_int(ENV_PROCESS_ID, default=0),
            _env_int("MJX_ARM_JOIN_TIMEOUT", default=DEFAULT_JOIN_TIMEOUT),
        )

    def join(self) -> None:
        """Join the other processes (``jax.distributed.initialize``); a no-op alone.

        Must run before anything else uses JAX; a second call in the same process (each
        command a joined warm trainer runs) does nothing. The processes first meet on the
        coordinator's port (:meth:`_meet`): JAX's own join ends the process natively
        (SIGABRT, no Python error) when one does not come, so a missing process is told apart
        here, before it.
        Afterwards computations that name no device run on this process's own first device,
        and CPU processes reduce through gloo.

        Raises:
            JoinError: not every process joined within ``join_timeout`` seconds.
        """
        if not self.joined or _JOINED:  # a warm trainer's process joins once, then trains
            return
        self._meet(time.monotonic() + self.join_timeout)
        import jax

        jax.config.update("jax_cpu_collectives_implementation", "gloo")
        try:
            jax.distributed.initialize(
                self.coordinator,
                self.num_processes,
                self.process_id,
                initialization_timeout=self.join_timeout,
            )
        except Exception as err:  # XlaRuntimeError: DEADLINE_EXCEEDED, UNAVAILABLE, ...
            raise self._join_error(str(err).splitlines()[0][:200]) from err
        jax.config.update("jax_default_device", jax.local_devices()[0])
        _JOINED.append(self)

    def _join_error(self, reason: str) -> JoinError:
        return JoinError(
            f"process {self.process_id} of {self.num_processes} could not join the training "
            f"at {self.coordinator} within {self.join_timeout} s ({reason}): start the same "
            "command on every host, each with its own --host-rank, check that host 0's "
            "address and port are reachable from every host, or raise --join-timeout"
        )

    def _meet(self, deadline: float) -> None:
        """Wait until every process is up: process 0 listens on the coordinator's port until
        each other process said hello, then answers all of them and frees the port for JAX's
        service; the others connect (again and again until ``deadline``) and wait for it.

        Raises:
            JoinError: a process missing at ``deadline``, or two with the same id.
        """
        if self.leader:
            self._gather(deadline)
            return
        host, _, port = self.coordinator.rpartition(":")
        last = "nothing listens there"
        while True:
            try:
                conn = socket.create_connection((host.strip("[]"), int(port)), timeout=5)
                break
            except OSError as err:  # refused, unreachable, an unknown name
                last = err.strerror or type(err).__name__
            if time.monotonic() >= deadline:
                raise self._join_error(f"process 0 could not be reached: {last}")
            time.sleep(0.2)
        with conn:  # process 0 answers by its own deadline: wait a little longer
            conn.settimeout(max(deadline - time.monotonic(), 0.0) + 15)
            try:
                conn.sendall(f"{HELLO} {self.num_processes} {self.process_id}\n".encode())
                reply = conn.makefile("r").readline().strip()
            except OSError as err:
                reply = f"process 0 did not answer ({err.strerror or type(err).__name__})"
        if reply != "go":
            raise self._join_error(reply or "process 0 closed the connection")

    def _gather(self, deadline: float) -> None:
        """Process 0's side of :meth:`_meet`: accept a hello from every other process, then
        answer each one ``go`` (or what went wrong)."""
        port = int(self.coordinator.rpartition(":")[2])
        try:
            dual = socket.has_dualstack_ipv6()
            family = socket.AF_INET6 if dual else socket.AF_INET
            server = socket.create_server(("", port), family=family, dualstack_ipv6=dual)
        except OSError as err:
            raise self._join_error(f"port {port} cannot be listened on: {err.strerror}") from err
        joined: dict[int, socket.socket] = {}
        problem = ""
        with server:
            while len(joined) < self.num_processes - 1 and not problem:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    missing = sorted(set(range(1, self.num_processes)) - set(joined))
                    problem = f"process(es) {', '.join(map(str, missing))} did not come"
                    break
                server.settimeout(remaining)
                try:
                    conn, _ = server.accept()
                except TimeoutError:
                    continue
                problem = self._hello(conn, remaining, joined)
        for conn in joined.values():
            with conn:
                try:
                    conn.sendall(f"{problem or 'go'}\n".encode())
                    conn.settimeout(2)
                    conn.recv(1)  # the other side closes first: no TIME_WAIT on the port
                except OSError:
                    pass
        if problem:
            raise self._join_error(problem)

    def _hello(self, conn: socket.socket, timeout: float, joined: dict) -> str:
        """Read a process's hello; keep its connection in ``joined`` under its id. What is
        wrong with it ("" where nothing; a connection that is not one of ours is closed)."""
        conn.settimeout(timeout)
        try:
            words = conn.makefile("r").readline().split()
        except (OSError, UnicodeDecodeError):
            words = []
        if len(words) != 3 or words[0] != HELLO or not all(w.isdigit() for w in words[1:]):
            conn.close()
            return ""
        count, ident = int(words[1]), int(words[2])
        taken = ident in joined or not 0 < ident < self.num_processes
        joined[-len(joined) - 1 if taken else ident] = conn  # a negative key: told, then closed
        if count != self.num_processes:
            return (
                f"process {ident} expects {count} processes, process 0 "
                f"{self.num_processes}: give every host the same --hosts"
            )
        return f"two processes have id {ident}: give each its own --host-rank" if taken else ""


def is_leader() -> bool:
    """Whether this process is process 0 (alone: always), the one that evaluates and writes."""
    import jax

    return jax.process_index() == 0


def share(values: dict[str, float]) -> dict[str, float]:
    """Process 0's ``values`` on every process (a collective: every process calls it with the
    same names)."""
    import jax

    if jax.process_count() == 1:
        return values
    from jax.experimental import multihost_utils

    names = sorted(values)
    vector = np.asarray([values[n] for n in names], np.float32)
    vector = np.asarray(multihost_utils.broadcast_one_to_all(vector))
    return dict(zip(names, (float(v) for v in vector), strict=True))


def barrier(name: str) -> None:
    """Wait until every process got here (alone: return at once)."""
    import jax

    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        multihost_utils.sync_global_devices(name)


def gather(tree: Any) -> Any:
    """Every leaf of ``tree`` (global arrays, split or replicated) whole on the host, in every
    process (a collective where several processes run)."""
    import jax

    if jax.process_count() == 1:
        return jax.device_get(tree)
    from jax.experimental import multihost_utils

    def whole(x: Any) -> np.ndarray:
        if getattr(x, "is_fully_replicated", True):
            return np.asarray(x)
        return np.asarray(multihost_utils.process_allgather(x, tiled=True))

    return jax.tree.map(whole, tree)


def _address_ok(address: str) -> bool:
    host, _, port = address.rpartition(":")
    return bool(host) and port.isdigit() and 0 < int(port) < 65536


def _env_int(*names: str, default: int) -> int:
    """The first of ``names`` set in the environment, as a whole number (else ``default``).

    Raises:
        ConfigError: a value that is not a whole number.
    """
    for name in names:
        text = os.environ.get(name)
        if text is None or text == "":
            continue
        try:
            return int(text)
        except ValueError:
            raise ConfigError(f"{name}={text!r} is not a whole number") from None
    return default
