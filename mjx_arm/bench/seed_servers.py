"""The warm trainers of ``mjx-arm bench seeds --server``: one ``mjx-arm serve`` per GPU (per
group of GPUs with ``--gpus-per-seed N``: ``serve --devices N``, a process per GPU joined once).

Each seed still runs as its own ``mjx-arm train`` command, timed from that command's start, but
with ``--server``: the GPU's warm trainer trains it, on the envs and programs the seed before
it on that GPU left (:mod:`mjx_arm.train.warm`). A seed is warm where its GPU's server had
finished a seed before it; the first seed on each GPU pays the start-up a new process pays.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from mjx_arm.bench.seeds_config import SeedsConfig
from mjx_arm.inputs import ConfigError
from mjx_arm.train.launch import stop_processes
from mjx_arm.train.server_protocol import user_folder

READY_TIMEOUT_S = 600.0  # a server's imports and device start, at most


def gpu_env(gpu: str) -> dict[str, str]:
    """This process's environment for a process that trains on ``gpu`` (a
    ``CUDA_VISIBLE_DEVICES`` entry): its GPU's memory taken as a training takes it (this
    benchmark's own process does not preallocate)."""
    env = {k: v for k, v in os.environ.items() if k != "XLA_PYTHON_CLIENT_PREALLOCATE"}
    return {**env, "CUDA_VISIBLE_DEVICES": gpu}


class SeedServers:
    """A warm trainer per entry of ``gpus`` (``CUDA_VISIBLE_DEVICES`` entries: ``"0"``, or
    ``"0,1"`` for a joined group), logging to ``runs_dir/server_gpuN.log``."""

    def __init__(self, gpus: list[str], runs_dir: Path, log=print) -> None:
        folder = user_folder()  # each server makes it (mode 0700) and checks it is this user's
        self.sockets = {gpu: folder / f"bench-{os.getpid()}-{i}.sock" for i, gpu in enumerate(gpus)}
        self.served = dict.fromkeys(gpus, 0)
        self.log = log
        self._procs: dict[str, subprocess.Popen] = {}
        self._runs_dir = runs_dir

    def start(self) -> SeedServers:
        """Start every server and wait until each answers (the imports and device start).

        Raises:
            ConfigError: a server that ended or did not answer within READY_TIMEOUT_S.
        """
        from mjx_arm.train.client import ping

        start = time.time()
        for gpu, path in self.sockets.items():
            command = [sys.executable, "-m", "mjx_arm.cli", "serve", "--socket", str(path)]
            command += ["--devices", str(len(gpu.split(",")))]  # "0,1": a joined group
            with (self._runs_dir / f"server_gpu{gpu.replace(',', '_')}.log").open("wb") as out:
                self._procs[gpu] = subprocess.Popen(
                    command, env=gpu_env(gpu), stdout=out, stderr=subprocess.STDOUT
                )
        for gpu, path in self.sockets.items():
            while ping(path) is None:
                if self._procs[gpu].poll() is not None or time.time() - start > READY_TIMEOUT_S:
                    self.stop()
                    raise ConfigError(f"the warm trainer of GPU {gpu} did not start ({path})")
                time.sleep(0.5)
            self.log(f"warm trainer on GPU {gpu} ready after {time.time() - start:.1f} s")
        return self

    def seed_env(self, gpu: str) -> dict[str, str]:
        """The environment a seed's ``train --server`` command finds its GPU's server by."""
        return {"MJX_ARM_SERVER": str(self.sockets[gpu])}

    def stop(self) -> None:
        """Stop every server (Ctrl-C, as a user would) and wait for it (30 s, then killed)."""
        stop_processes(list(self._procs.values()), signal.SIGINT, 30)


def check_server_settings(config: SeedsConfig) -> None:
    """A warm trainer trains a seed with the devices it started.

    Raises:
        ConfigError: ``--server`` with ``--deterministic``.
    """
    if not config.server:
        return
    if config.deterministic:
        raise ConfigError(
            "--deterministic sets XLA's flags before a process starts its devices, which a "
            "warm trainer has done: drop --deterministic or --server"
        )
