"""The warm trainer: ``mjx-arm serve`` runs ``mjx-arm train --server`` commands in one process
and keeps the envs and compiled programs of a config for its next seed.

A seed trained on kept programs must be the seed trained in a process of its own: every logged
figure but time and every checkpoint's params, bit for bit (CPU, the C MuJoCo backend). About a
minute on a 2-core CPU.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from mjx_arm.bench.seed_servers import check_server_settings
from mjx_arm.bench.seeds import run_seeds
from mjx_arm.bench.seeds_config import SeedsConfig
from mjx_arm.bench.seeds_gpus import run_seeds_on_gpus
from mjx_arm.cli import build_parser
from mjx_arm.inputs import ConfigError
from mjx_arm.train import warm
from mjx_arm.train.client import ping, request_for
from mjx_arm.train.config import TrainConfig
from mjx_arm.train.repeat import compare_runs
from mjx_arm.train.server import refusal

SMALL = ("num_timesteps=20000", "num_evals=3", "num_envs=16", "batch_size=16", "num_eval_envs=16")
TRAIN = ["train", "--task", "reach", "--preset", "cpu", "--backend", "mujoco", "--quiet"]
TRAIN += ["--set", *SMALL]
_CACHE = os.environ.get(
    "MJX_ARM_JAX_CACHE", str(Path(__file__).resolve().parents[1] / ".jax_cache")
)
ENV = {**os.environ, "MJX_ARM_JAX_CACHE": _CACHE, "JAX_PLATFORMS": "cpu"}


def _cli(*argv: str, env: dict | None = None, **kwargs) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", "mjx_arm.cli", *argv]
    return subprocess.run(command, env=env or ENV, capture_output=True, text=True, **kwargs)


def _start_up(run: Path) -> dict:
    return json.loads((run / "compile.json").read_text())[-1]


def _sigint_ignored(command: list[str]) -> list[str]:
    """``command`` started as a non-interactive shell starts a background job: SIGINT ignored
    (a shell's ``trap '' INT`` before the ``exec``)."""
    return ["sh", "-c", 'trap "" INT; exec "$@"', "sh", *command]


@contextlib.contextmanager
def _serving(*flags: str):
    """A warm trainer (``mjx-arm serve FLAGS``) on a short socket path, once it answers. It
    starts with SIGINT ignored, and must stop on it all the same (``mjx_arm.cli.take_ctrl_c``)."""
    folder = Path(tempfile.mkdtemp(prefix="mjxs"))
    path, log = folder / "t.sock", folder / "server.log"
    with log.open("wb") as out:
        command = [sys.executable, "-m", "mjx_arm.cli", "serve", "--socket", str(path), *flags]
        proc = subprocess.Popen(
            _sigint_ignored(command), env=ENV, stdout=out, stderr=subprocess.STDOUT
        )
    deadline = time.time() + 120
    while ping(path) is None:
        assert proc.poll() is None and time.time() < deadline, log.read_text()
        time.sleep(0.2)
    yield SimpleNamespace(path=path, log=log, env={**ENV, "MJX_ARM_SERVER": str(path)})
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=90)  # a JAX process ends in seconds alone, slower on a busy 2-core CPU
    assert not path.exists()  # the socket file goes with the server


@pytest.fixture(scope="module")
def server():
    """A warm trainer; its socket, log file and the environment that finds it."""
    with _serving() as served:
        assert stat.S_IMODE(served.path.stat().st_mode) == 0o600  # this user's commands only
        yield served


def test_a_warmup_makes_the_first_command_warm(tmp_path: Path) -> None:
    with _serving("--warmup", " ".join(TRAIN[1:])) as served:
        run = tmp_path / "first"
        done = _cli(*TRAIN, "--seed", "8", "--run-dir", str(run), "--server", env=served.env)
        assert done.returncode == 0, done.stderr
        assert _start_up(run)["kept_warm"] == ["envs", "programs"]
        assert "warming up reach" in served.log.read_text()


def test_a_seed_trained_warm_is_the_seed_trained_alone(server, tmp_path: Path) -> None:
    first = _cli(
        *TRAIN, "--seed", "3", "--run-dir", str(tmp_path / "a3"), "--server", env=server.env
    )
    assert first.returncode == 0, first.stderr
    assert "kept_warm" not in _start_up(tmp_path / "a3")  # the server's first run builds all
    warm_run = _cli(
        *TRAIN, "--seed", "4", "--run-dir", str(tmp_path / "a4"), "--server", env=server.env
    )
    assert warm_run.returncode == 0, warm_run.stderr
    assert "\ndone: 20,480 steps" in warm_run.stdout  # the output comes back to the client
    report = _start_up(tmp_path / "a4")
    assert report["kept_warm"] == ["envs", "programs"]
    assert "trace + lower" not in report["stages"] and report["compile_s"] < 0.5
    nobody = {**ENV, "MJX_ARM_SERVER": str(tmp_path / "none.sock")}
    alone = _cli(*TRAIN, "--seed", "4", "--run-dir", str(tmp_path / "b4"), "--server", env=nobody)
    assert alone.returncode == 0, alone.stderr
    assert (
        "no warm trainer answers at" in alone.stderr and "training in this process" in alone.stderr
    )
    assert "kept_warm" not in _start_up(tmp_path / "b4")
    same = compare_runs(tmp_path / "a4", tmp_path / "b4")
    assert same.identical and same.rows == 3 and same.checkpoints >= 1, same.line()


def test_a_client_that_goes_away_stops_its_run_and_the_server_goes_on(server, tmp_path) -> None:
    run = tmp_path / "gone"
    # a budget the run cannot finish before the signal, however late the poll below sees it
    # start, in epochs as short as the others': the client's going is seen between them
    longer = ["--set", "num_timesteps=4000000", "num_evals=400"]
    command = [sys.executable, "-m", "mjx_arm.cli", *TRAIN, *longer, "--seed", "5", "--server"]
    client = subprocess.Popen(_sigint_ignored([*command, "--run-dir", str(run)]), env=server.env)
    deadline = time.time() + 60
    while not (run / "config.json").exists():  # saved before the first epoch
        assert time.time() < deadline and client.poll() is None
        time.sleep(0.02)
    client.send_signal(signal.SIGINT)
    assert client.wait(timeout=30) == 130
    deadline = time.time() + 60
    while "the client went away" not in server.log.read_text():
        assert time.time() < deadline, server.log.read_text()
        time.sleep(0.1)
    assert ping(server.path)["pong"] > 0  # still serving
    again = _cli(
        *TRAIN, "--seed", "5", "--run-dir", str(tmp_path / "again"), "--server", env=server.env
    )
    assert again.returncode == 0, again.stderr


def test_garbage_on_the_socket_leaves_the_server_serving(server) -> None:
    for garbage in (b"not json\n", b"[1, 2]\n", b'{"argv": 3}\n', b""):
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
            sock.connect(str(server.path))
            sock.sendall(garbage)
    assert ping(server.path)["pong"] > 0


def test_the_server_refuses_what_one_process_cannot_train() -> None:
    parse = build_parser().parse_args
    ok = request_for(TRAIN)
    code, devices = ok["code"], ok["devices"]
    assert refusal(ok, code, devices, parse) == ""
    assert "other mjx_arm code" in refusal({**ok, "code": "older"}, code, devices, parse)
    assert "CUDA_VISIBLE_DEVICES=7" in refusal(ok, code, "7", parse)
    assert "several devices" in refusal(
        request_for([*TRAIN, "--devices", "2"]), code, devices, parse
    )
    assert "--deterministic" in refusal(
        request_for([*TRAIN, "--deterministic"]), code, devices, parse
    )
    assert "train commands only" in refusal(request_for(["demo"]), code, devices, parse)
    assert request_for([*TRAIN, "--server"])["argv"] == TRAIN  # the server never calls itself


def test_the_kept_envs_are_keyed_on_all_but_the_seed(tmp_path: Path) -> None:
    urdf = tmp_path / "arm.urdf"
    urdf.write_text("<robot name='a'/>")
    setup = SimpleNamespace(arm=SimpleNamespace(urdf=urdf))
    base = warm.config_key(TrainConfig(), setup)
    assert warm.config_key(TrainConfig(seed=7), setup) == base
    assert warm.config_key(TrainConfig(learning_rate=1e-3), setup) != base
    urdf.write_text("<robot name='b'/>")  # the arm's file changed in place
    assert warm.config_key(TrainConfig(), setup) != base


def test_one_config_is_kept_and_another_replaces_it(tmp_path: Path, keeps_nothing_after) -> None:
    """The envs of the last config alone: the same config but its seed finds them; another
    config builds its own and drops the first's; nothing is kept where not enabled."""
    setup = SimpleNamespace(arm=SimpleNamespace(urdf=tmp_path / "none.urdf"))
    built = []

    def build(name: str):
        return lambda: built.append(name) or (f"{name}-env", f"{name}-eval")

    a, b = TrainConfig(), TrainConfig(learning_rate=1e-3)
    assert warm.envs(a, setup, build("a")) == ("a-env", "a-eval", False)  # not enabled
    warm.enable()
    assert warm.envs(a, setup, build("a"))[2] is False
    env, eval_env, kept = warm.envs(a.replace(seed=9), setup, build("a"))
    assert (env, eval_env, kept) == ("a-env", "a-eval", True)
    warm.keep_programs(env, "a-programs")  # the envs are known by identity
    assert warm.programs_of(env) == "a-programs" and warm.programs_of(object()) is None
    assert warm.envs(b, setup, build("b"))[2] is False
    assert warm.programs_of(env) is None  # dropped with its envs
    assert warm.envs(a, setup, build("a"))[2] is False
    assert built == ["a", "a", "b", "a"]


@pytest.fixture
def keeps_nothing_after():
    yield
    warm.disable()  # run_seeds with server=True keeps things in this process


def test_seeds_in_turn_keep_what_they_share(tmp_path: Path, keeps_nothing_after) -> None:
    config = SeedsConfig(task="reach", preset="cpu", backend="mujoco", seeds="3-4", server=True)
    runs, _ = run_seeds(config, tmp_path, SMALL, log=lambda *_: None)
    assert "kept_warm" not in runs[0].compile_report
    assert runs[1].compile_report["kept_warm"] == ["envs", "programs"]


def test_seeds_on_a_warm_trainer_per_gpu(tmp_path: Path, monkeypatch) -> None:
    """The GPU path on a CPU: ``CUDA_VISIBLE_DEVICES`` means nothing to JAX's CPU backend."""
    for key, value in ENV.items():
        monkeypatch.setenv(key, value)
    config = SeedsConfig(task="reach", preset="cpu", backend="mujoco", seeds="3-4", server=True)
    runs, _ = run_seeds_on_gpus(config, tmp_path, ["0"], SMALL, log=lambda *_: None)
    assert [r.error for r in runs] == ["", ""]
    assert [r.warm for r in runs] == [False, True]
    assert runs[1].compile_report["kept_warm"] == ["envs", "programs"]
    assert "warm trainer ready" in (tmp_path / "server_gpu0.log").read_text()


def test_server_settings_the_seeds_benchmark_refuses() -> None:
    check_server_settings(SeedsConfig(server=True, gpus_per_seed=2))  # a joined group each
    with pytest.raises(ConfigError, match="--deterministic"):
        check_server_settings(SeedsConfig(server=True, deterministic=True))
    check_server_settings(SeedsConfig(gpus_per_seed=2, deterministic=True))  # no --server
