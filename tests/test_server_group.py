"""A warm trainer of several GPUs (``mjx-arm serve --devices N``,
:mod:`mjx_arm.train.server_group`): a process per device joined once, every command run on all.

Here the group's processes are CPU processes joined through gloo (the front is started from
Python: ``serve --devices 2`` itself asks the driver for GPUs). A seed trained on the kept
programs of a joined group must be the seed the group trained first, bit for bit. The slow test
takes about three minutes on a 2-core CPU.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import pytest
from tiny_run import SETTINGS

from mjx_arm.cli import build_parser
from mjx_arm.inputs import ConfigError
from mjx_arm.train import distributed
from mjx_arm.train.client import ping, request_for
from mjx_arm.train.distributed import ProcessGroup
from mjx_arm.train.repeat import compare_runs
from mjx_arm.train.server import refusal
from mjx_arm.train.server_group import ServerGroup, group_gpus

SETS = [f"{k}={v}" for k, v in SETTINGS.items()]
TRAIN = ["train", "--quiet", "--devices", "2", "--preset", "cpu", "--set", *SETS]
PARSE = build_parser().parse_args
# The front, started as `serve --devices 2` starts it, on two CPU "GPUs".
FRONT = (
    "import sys; from pathlib import Path; from mjx_arm.cli import build_parser; "
    "from mjx_arm.train.server_group import ServerGroup; "
    "sys.exit(ServerGroup(Path(sys.argv[1]), build_parser().parse_args, ['0', '1'], "
    "log=lambda line: print(line, flush=True)).serve_forever())"
)


def _env() -> dict[str, str]:
    """CPU processes, the tests' compilation cache, XLA's CPU collectives given 10 minutes
    (two processes share 2 cores: tests/test_distributed.py)."""
    import jax

    cache = jax.config.jax_compilation_cache_dir or os.environ.get("MJX_ARM_JAX_CACHE", "")
    env = {k: v for k, v in os.environ.items() if k not in ("CUDA_VISIBLE_DEVICES",)}
    flags = "--xla_cpu_collective_call_terminate_timeout_seconds=600"
    return {**env, "JAX_PLATFORMS": "cpu", "MJX_ARM_JAX_CACHE": cache, "XLA_FLAGS": flags}


def test_a_group_takes_only_commands_of_its_device_count() -> None:
    ok = request_for(TRAIN)
    code, devices = ok["code"], ok["devices"]
    assert refusal(ok, code, devices, PARSE, processes=2) == ""
    alone = request_for([a for a in TRAIN if a not in ("--devices", "2")])
    assert "give --devices 2" in refusal(alone, code, devices, PARSE, processes=2)
    three = request_for([*TRAIN, "--devices", "3"])
    assert "give --devices 2" in refusal(three, code, devices, PARSE, processes=2)
    assert "serve --devices N" in refusal(ok, code, devices, PARSE)  # a server of one device


def test_every_process_of_a_run_gets_one_run_directory_and_its_own_place(tmp_path) -> None:
    group = ServerGroup(tmp_path / "t.sock", PARSE, ["0", "1"])
    request = request_for(TRAIN)
    request.update(cwd=str(tmp_path), env={"MJX_ARM_PROCESS_ID": "5", "MJX_ARM_X": "1"})
    sent = group.child_request(request)
    assert sent["argv"][: len(TRAIN)] == TRAIN and sent["argv"][-2] == "--run-dir"
    named = Path(sent["argv"][-1])
    assert named.parent == tmp_path / "runs" and named.name.startswith("reach-")
    assert sent["env"] == {"MJX_ARM_X": "1"}  # a process's place is its own
    given = request_for([*TRAIN, "--run-dir", "mine"])
    assert group.child_request(given)["argv"] == given["argv"]


def test_a_group_needs_its_gpus(monkeypatch) -> None:
    monkeypatch.setenv("JAX_PLATFORMS", "cpu")
    with pytest.raises(ConfigError, match="serve --devices 2 needs 2 GPUs; this host shows 0"):
        group_gpus(2)
    with pytest.raises(ConfigError, match="takes no --warmup"):
        group_gpus(2, ["--task", "touch"])
    with pytest.raises(ConfigError, match="needs 2 GPUs or more"):
        ServerGroup(Path("t.sock"), PARSE, ["0"])
    done = subprocess.run(
        [sys.executable, "-m", "mjx_arm.cli", "serve", "--devices", "2", "--socket", "x.sock"],
        env=_env(),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2 and "needs 2 GPUs" in done.stderr, done.stderr


def test_a_process_joins_once(monkeypatch) -> None:
    """A joined warm trainer's process runs each command's join again: it must do nothing
    (jax.distributed starts once per process)."""
    monkeypatch.setattr(distributed, "_JOINED", [object()])
    ProcessGroup("127.0.0.1:1", 2, 1, join_timeout=1).join()  # no meeting: no JoinError


def _train(front: SimpleNamespace, run: Path, seed: int, *extra: str):
    command = [sys.executable, "-m", "mjx_arm.cli", *TRAIN, *extra]
    command += ["--seed", str(seed), "--run-dir", str(run), "--server"]
    return subprocess.Popen(command, env=front.env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def _done(proc: subprocess.Popen) -> None:
    out, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err.decode()[-3000:]
    assert b"done:" in out


def _kept(run: Path) -> dict:
    return json.loads((run / "compile.json").read_text())[-1]


def _wait_for(front: SimpleNamespace, text: str, count: int = 1, timeout: float = 180) -> None:
    deadline = time.time() + timeout
    while front.log.read_text().count(text) < count:
        assert time.time() < deadline and front.proc.poll() is None, front.log.read_text()
        time.sleep(0.2)


def _start_front() -> SimpleNamespace:
    """A group's front (``serve --devices 2`` on two CPU processes), once they have joined."""
    folder = Path(tempfile.mkdtemp(prefix="mjxg"))
    path, log = folder / "g.sock", folder / "front.log"
    env = _env()
    with log.open("wb") as out:
        proc = subprocess.Popen(
            [sys.executable, "-c", FRONT, str(path)], env=env, stdout=out, stderr=out
        )
    client_env = {**env, "MJX_ARM_SERVER": str(path)}
    served = SimpleNamespace(path=path, log=log, proc=proc, env=client_env)
    _wait_for(served, "warm trainers joined")
    return served


@pytest.fixture(scope="module")
def front():
    served = _start_front()
    yield served
    if served.proc.poll() is None:
        served.proc.kill()


@pytest.mark.slow
def test_a_joined_group_trains_warm_and_restarts_after_a_stopped_run(front, tmp_path) -> None:
    cold = _train(front, tmp_path / "a4", 4)
    _done(cold)
    assert "kept_warm" not in _kept(tmp_path / "a4")  # the group's first run builds all
    for seed in (5, 4):
        _done(_train(front, tmp_path / f"b{seed}", seed))
        report = _kept(tmp_path / f"b{seed}")
        assert report["kept_warm"] == ["envs", "programs"] and report["compile_s"] < 0.5
    same = compare_runs(tmp_path / "a4", tmp_path / "b4")
    assert same.identical and same.rows == 4 and same.checkpoints >= 3, same.line()
    second = front.path.with_name("g.sock.p1.log").read_text()  # process 1 ran them too
    assert second.count(": exit 0 after") == 3 and "done:" not in second  # 0 alone reports

    gone = _long_run(front, tmp_path / "gone")
    gone.send_signal(signal.SIGINT)
    assert gone.wait(timeout=60) == 130
    _wait_for(front, "restarting the group")
    _wait_for(front, "warm trainers joined", count=2)
    assert ping(front.path)["restarts"] == 1
    _done(_train(front, tmp_path / "again", 4))  # a cold group again, the same run
    assert compare_runs(tmp_path / "a4", tmp_path / "again").identical

    lost = _long_run(front, tmp_path / "lost")
    os.kill(int(_ready_lines(front)[1].split("pid ")[1].split(",")[0]), signal.SIGKILL)
    _, err = lost.communicate(timeout=120)  # the others may wait for it at a collective
    assert lost.returncode != 0 and b"process 1 of the group ended during the run" in err
    _wait_for(front, "warm trainers joined", count=3)
    assert ping(front.path)["restarts"] == 2

    children = [int(line.split("pid ")[1].split(",")[0]) for line in _ready_lines(front)]
    front.proc.send_signal(signal.SIGTERM)  # a timeout's stop: the group goes with the front
    assert front.proc.wait(timeout=90) == 0
    assert not front.path.exists() and ping(front.path) is None
    for pid in children:
        assert not Path(f"/proc/{pid}").exists() or _zombie(pid), f"process {pid} still runs"


def _long_run(front: SimpleNamespace, run: Path) -> subprocess.Popen:
    """A run the group cannot finish soon, once it has started (its config saved)."""
    proc = _train(front, run, 6, "--set", "num_timesteps=1920000", "num_evals=3001")
    deadline = time.time() + 120
    while not (run / "config.json").exists():
        assert time.time() < deadline and proc.poll() is None
        time.sleep(0.05)
    return proc


def _ready_lines(front: SimpleNamespace) -> list[str]:
    """The ready lines of the group's processes now running (their logs' last two)."""
    lines = []
    for index in (0, 1):
        log = front.path.with_name(f"g.sock.p{index}.log").read_text().splitlines()
        lines.append([line for line in log if line.startswith("warm trainer ready")][-1])
    return lines


def _zombie(pid: int) -> bool:
    with open(f"/proc/{pid}/stat") as stat:
        return stat.read().split(")")[-1].split()[0] == "Z"


def test_the_group_ends_with_its_front_even_killed() -> None:
    """A front killed at once (SIGKILL: no handler runs) leaves no process holding a GPU."""
    served = _start_front()
    children = [int(line.split("pid ")[1].split(",")[0]) for line in _ready_lines(served)]
    served.proc.kill()
    served.proc.wait(timeout=30)
    deadline = time.time() + 30
    while any(Path(f"/proc/{pid}").exists() and not _zombie(pid) for pid in children):
        assert time.time() < deadline, f"processes {children} outlived their front"
        time.sleep(0.2)
