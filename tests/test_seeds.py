"""The seeds benchmark: seed lists, the statistics over seeds, the report, and one tiny run."""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import pytest

from mjx_arm.bench.seeds import first_at
from mjx_arm.bench.seeds_config import SeedRun, SeedsConfig, parse_seeds
from mjx_arm.bench.seeds_report import write_report
from mjx_arm.bench.seeds_summary import quartiles, summarize


def _run(seed: int, time_to: float | None, final: float = 0.97) -> SeedRun:
    curve = [(1.0, 0, 0.0), (5.0, 1000, 0.5)]
    if time_to is not None:
        curve.append((time_to, 2000, 0.96))
    return SeedRun(
        seed=seed,
        final_success=final,
        best_success=max(v for _, _, v in curve),
        steps_to_threshold=2000 if time_to is not None else None,
        time_to_threshold=time_to,
        total_steps=2000,
        wall_s=10.0,
        compile_s=2.0,
        training_steps_per_s=1000.0,
        curve=curve,
    )


@pytest.mark.parametrize(
    ("text", "seeds"),
    [("0-9", tuple(range(10))), ("3", (3,)), ("0,3,7", (0, 3, 7)), ("0-2, 5", (0, 1, 2, 5))],
)
def test_parse_seeds(text: str, seeds: tuple[int, ...]) -> None:
    assert parse_seeds(text) == seeds


@pytest.mark.parametrize("text", ["", "a", "5-2", "1,1", "-3", "0-2,2"])
def test_parse_seeds_rejects(text: str) -> None:
    with pytest.raises(ValueError):
        parse_seeds(text)


def test_first_at_takes_the_first_evaluation_at_the_threshold() -> None:
    curve = [(1.0, 0, 0.2), (2.0, 10, 0.95), (3.0, 20, 0.99)]
    assert first_at(curve, 0.95) == (2.0, 10)
    assert first_at(curve, 0.995) is None


def test_quartiles_count_unsolved_seeds_as_infinitely_slow() -> None:
    # sorted: 10, 20, 30, inf -> median between 20 and 30; q75 falls on the unsolved seed
    q = quartiles([30.0, None, 10.0, 20.0])
    assert q["median"] == pytest.approx(25.0)
    assert q["q25"] == pytest.approx(10.0)
    assert q["q75"] is None and q["n"] == 4
    # a majority unsolved: the median itself is "not reached"
    assert quartiles([None, None, 5.0])["median"] is None
    assert quartiles([])["median"] is None


def test_summary_counts_solved_seeds_and_warm_times() -> None:
    runs = [_run(0, 80.0), _run(1, 30.0), _run(2, None, final=0.4), _run(3, 40.0)]
    summary = summarize(runs, 0.95)
    assert summary["solved"] == 3 and summary["fraction_solved"] == pytest.approx(0.75)
    warm = summary["time_to_threshold_warm"]  # seeds 1-3: 30, 40, inf
    assert warm["median"] == pytest.approx(40.0) and warm["n"] == 3
    assert summary["time_to_threshold_all"]["median"] == pytest.approx(60.0)  # (40 + 80) / 2


def test_report_files(tmp_path: Path) -> None:
    runs = [_run(0, 12.0), _run(1, None, final=0.1)]
    meta = {"device": {"kind": "cpu"}}
    config = SeedsConfig(seeds="0-1")
    paths = write_report(config, runs, [{}, {}], meta, tmp_path, "s", ("a=1",))
    assert [p.name for p in paths] == ["s.json", "s.md"]  # a picture only when asked for
    data = json.loads(paths[0].read_text())
    assert data["summary"]["solved"] == 1 and data["overrides"] == ["a=1"]
    text = paths[1].read_text()
    assert "not reached" in text and "1 of 2 seeds" in text and "with a=1" in text
    paths = write_report(config, runs, [{}, {}], meta, tmp_path, "s", ("a=1",), png=True)
    assert paths[2] == tmp_path / "s.png" and paths[2].stat().st_size > 1000  # a PNG drawn
    # written while the benchmark runs: the seeds finished so far, and how many are to come
    paths = write_report(config, runs[:1], [{}], meta, tmp_path, "s", pending=1)
    assert json.loads(paths[0].read_text())["pending_seeds"] == 1
    assert "1 seeds finished, 1 not: still to come or stopped" in paths[1].read_text()


@pytest.mark.slow
def test_two_tiny_seeds_on_the_c_backend(tmp_path: Path) -> None:
    """Two seeds of a few thousand steps: each trains, its curve starts at step 0, and the
    report sees the saved config of each seed (its own seed); the command writes the report
    of the first seed before the second trains (a benchmark stopped early keeps it)."""
    from mjx_arm.bench.seeds_gpus import train_seeds

    config = SeedsConfig(task="reach", preset="cpu", seeds="0,1", backend="mujoco")
    sets = ("num_timesteps=2560", "num_evals=2", "num_eval_envs=8")
    reports = []

    def report(runs, configs, **kwargs):
        reports.append(([r.seed for r in runs], kwargs["pending"]))

    command_start = time.time() - 5.0  # the command started 5 s ago (its imports)
    runs, configs, pending = train_seeds(
        config, tmp_path, [], sets, command_start, lambda _: None, report
    )
    assert pending == 0
    assert reports == [([0], 1)]  # the final report is the command's own
    # the first seed's time before training counts from the command's start, the next's from
    # its own: a few hundredths of a second in this process
    before = [run.compile_report["stages"]["before training"] for run in runs]
    assert before[0] >= 5.0 and 0.0 <= before[1] < 1.0
    assert next(iter(runs[0].compile_report["stages"])) == "before training"
    assert [r.seed for r in runs] == [0, 1]
    assert [c["train"]["seed"] for c in configs] == [0, 1]
    assert [r.warm for r in runs] == [False, True]  # in turn: the second found warm caches
    for run in runs:
        assert run.curve[0][1] == 0 and run.total_steps >= 2560
        assert 0.0 <= run.final_success <= 1.0 and not math.isnan(run.wall_s)


@pytest.mark.slow
def test_seeds_in_processes_of_their_own(tmp_path: Path) -> None:
    """Each seed trains in a process of its own (as on each GPU of a host; here two CPU
    processes at once): the same report, each seed's own config, the GPU it ran on, and a seed
    whose process fails is reported unsolved with its error while the others go on."""
    from mjx_arm.bench.seeds_gpus import run_seeds_on_gpus

    config = SeedsConfig(task="reach", preset="cpu", seeds="0-1", backend="mujoco")
    sets = ("num_timesteps=2560", "num_evals=2", "num_eval_envs=8")
    runs, configs = run_seeds_on_gpus(config, tmp_path, ["", ""], sets, log=lambda _: None)
    assert [r.seed for r in runs] == [0, 1] and not any(r.error for r in runs)
    assert [r.warm for r in runs] == [False, False]  # both started before either had ended
    assert [c["train"]["seed"] for c in configs] == [0, 1]
    for run in runs:
        assert run.curve[0][1] == 0 and run.total_steps >= 2560 and run.compile_report
        assert "stages" in run.compile_report and 0.0 <= run.final_success <= 1.0
        # a process of its own imports JAX, MuJoCo and Brax before its trainer starts
        before = run.compile_report["stages"]["before training"]
        assert 0.5 < before < run.wall_s
    failed, _ = run_seeds_on_gpus(
        SeedsConfig(task="reach", preset="cpu", seeds="2", backend="mujoco"),
        tmp_path,
        [""],
        (*sets, "num_envs=63"),
        log=lambda _: None,
    )
    assert not failed[0].solved and "exit code 2" in failed[0].error
    assert "num_envs" in failed[0].error
    paths = write_report(config, runs + failed, [*configs, {}], {"device": {"kind": "cpu"}},
                         tmp_path, "p", sets, wall_s=12.5)  # fmt: skip
    summary = json.loads(paths[0].read_text())["summary"]
    assert summary["wall_s"] == 12.5 and summary["solved"] <= 2


@pytest.mark.slow
def test_a_sigterm_keeps_the_finished_seeds_and_stops_the_rest(tmp_path: Path) -> None:
    """A SIGTERM (here sent as the third of three seeds starts, two GPUs' worth at a time):
    the finished seeds are kept, those training are stopped and waited for, and the benchmark
    hands back how many it left out; the SIGTERM handler is the caller's again."""
    import os
    import signal

    from mjx_arm.bench.seeds_gpus import train_seeds

    config = SeedsConfig(task="reach", preset="cpu", seeds="0-2", backend="mujoco")
    sets = ("num_timesteps=2560", "num_evals=2", "num_eval_envs=8")
    reports, lines = [], []

    def log(line: str) -> None:
        lines.append(line)
        if line.startswith("seed 2: training"):
            os.kill(os.getpid(), signal.SIGTERM)  # as a deadline's timeout would

    def report(runs, configs, **kwargs) -> None:
        reports.append((len(runs), kwargs["pending"]))

    before = signal.getsignal(signal.SIGTERM)
    runs, configs, pending = train_seeds(config, tmp_path, ["", ""], sets, time.time(), log, report)
    assert signal.getsignal(signal.SIGTERM) == before
    # seed 2 starts on the first GPU freed: seed 1 has ended by then, or is stopped with it
    finished = [r.seed for r in runs]
    assert finished in ([0, 1], [0], [1]) and pending == 3 - len(runs)
    assert not any(r.error for r in runs) and [c["train"]["seed"] for c in configs] == finished
    assert reports[-1] == (len(runs), pending)  # the last report the benchmark wrote
    assert lines[-1] == f"stopped by SIGTERM: {len(runs)} of 3 seeds finished"
    assert (tmp_path / "seed2.log").exists()  # it had started; train_seeds waited for its end


def test_a_seed_whose_process_a_sigterm_ended_is_left_out(tmp_path: Path) -> None:
    """A deadline's ``timeout`` signals the whole process group: a seed's process killed by
    that SIGTERM frees its GPU but is left out of the results (not a seed that failed to
    learn); one that failed of itself is kept as not solved."""
    import signal
    import subprocess

    from mjx_arm.bench.seeds_gpus import _collect

    config = SeedsConfig(task="reach", preset="cpu", seeds="0-1", backend="mujoco")
    killed = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    failed = subprocess.Popen([sys.executable, "-c", "raise SystemExit(3)"])
    killed.send_signal(signal.SIGTERM)
    killed.wait(), failed.wait()
    for seed in (0, 1):
        (tmp_path / f"seed{seed}.log").write_text("RuntimeError: boom\n")
    running = {0: (killed, "0", time.time(), True), 1: (failed, "1", time.time(), True)}
    done, lines = {}, []
    assert sorted(_collect(config, tmp_path, running, done, None, lines.append)) == ["0", "1"]
    assert running == {} and list(done) == [1]
    assert done[1][0].error == "exit code 3: RuntimeError: boom"
    assert lines[0].startswith("seed 0: its process was stopped by a SIGTERM; left out")


def test_a_failed_seed_reports_the_exception_its_log_ends_with():
    """The error of a seed whose process died is the log's last exception line (a GPU out of
    memory raised through JAX), not the traceback's last code lines; a log without one gives
    its last three lines."""
    from mjx_arm.bench.seeds import log_error

    log = (
        "Traceback (most recent call last):\n"
        '  File "jax/_src/array.py", line 623, in _value\n'
        "    npy_value, did_copy = self._single_device_array_to_np_array_did_copy()\n"
        "                          ^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^\n"
        "jax.errors.JaxRuntimeError: UNKNOWN: FFI callback error: RuntimeError: Failed to "
        "allocate 1006632960 bytes on device 'cuda:0' [executable_name='jit_unroll']\n"
    )
    assert log_error(log).startswith("jax.errors.JaxRuntimeError: UNKNOWN: FFI callback error")
    assert "Failed to allocate 1006632960 bytes" in log_error(log)
    assert log_error("one\ntwo\nthree\nfour") == "two | three | four"
    assert len(log_error("ValueError: " + "x" * 1000)) == 400


def test_gpus_per_seed_groups_the_gpus_and_trains_each_seed_on_its_group() -> None:
    """``--gpus-per-seed 2`` on 4 GPUs runs two seeds at once, each on two GPUs (a
    ``CUDA_VISIBLE_DEVICES`` pair) through ``train --devices 2``; a host short of the GPUs one
    seed needs is a named error, and one GPU per seed is the plain one-GPU list."""
    from mjx_arm.bench.cli import _seed_gpus
    from mjx_arm.bench.seeds import seed_command
    from mjx_arm.inputs import ConfigError

    four = ["0", "1", "2", "3"]
    assert _seed_gpus(four, 0, 2) == ["0,1", "2,3"]
    assert _seed_gpus(four, 3, 2) == ["0,1"]  # the third GPU alone cannot take a seed
    assert _seed_gpus(four, 0) == four and _seed_gpus(four, 2) == ["0", "1"]
    with pytest.raises(ConfigError, match="needs 2 GPUs of one host; there is 1 GPU"):
        _seed_gpus(["0"], 0, 2)
    with pytest.raises(ConfigError, match="no GPU"):
        _seed_gpus([], 0, 4)
    config = SeedsConfig(task="touch", seeds="5", gpus_per_seed=2)
    command = seed_command(config, 5, Path("runs/x"))
    assert command[command.index("--devices") + 1] == "2" and "seed=5" in command
    with pytest.raises(ConfigError, match="gpus_per_seed"):
        SeedsConfig(gpus_per_seed=0)


def test_a_seed_on_several_gpus_is_checked_on_the_batch_it_trains() -> None:
    """The settings check of a seed on N GPUs uses the config ``train --devices N`` trains:
    the preset's batch split over them (the default), or grown N times with
    ``scale_with_devices=true``, so a batch that splits over N GPUs only once grown passes
    there, and fails before any seed starts where it is split."""
    from mjx_arm.bench.seeds import check_seed_settings
    from mjx_arm.inputs import ConfigError

    config = SeedsConfig(task="touch", preset="fast", seeds="0", gpus_per_seed=2)
    odd = ("num_envs=2049", "batch_size=2049", "num_minibatches=1")  # grown: 4098 each
    check_seed_settings(config, (*odd, "scale_with_devices=true"), devices=2)
    check_seed_settings(config, (), devices=2)  # the preset's 8192 envs split in two
    with pytest.raises(ConfigError, match="multiple of the device count"):
        check_seed_settings(config, odd, devices=2)


def test_the_threshold_defaults_to_where_the_task_counts_as_solved() -> None:
    """Without --threshold a seed counts as solved at its task's ``solved_at`` (where ``fast``
    stops: Lift 0.9); a threshold over the training's stop is refused before any seed starts,
    since every seed would stop short of it."""
    from mjx_arm.bench.seeds import check_seed_settings
    from mjx_arm.inputs import ConfigError

    assert SeedsConfig(task="lift").threshold == 0.9
    assert SeedsConfig(task="touch").threshold == 0.95
    assert SeedsConfig(task="lift", threshold=0.8).threshold == 0.8
    check_seed_settings(SeedsConfig(task="lift", seeds="0"), devices=1)
    with pytest.raises(ConfigError, match=r"stops at its first evaluation at 0\.9 .*--threshold"):
        check_seed_settings(SeedsConfig(task="lift", seeds="0", threshold=0.95), devices=1)
    check_seed_settings(
        SeedsConfig(task="lift", seeds="0", threshold=0.95), ("stop_at_success=0.95",), devices=1
    )


def test_the_seconds_before_training_are_split_at_the_start_up_marks() -> None:
    """A seed's ``before training`` (its process start to the trainer's report) is split into
    the seconds from one start-up mark to the next, in time order, summing to the whole."""
    from mjx_arm.bench.seeds import with_time_before_training

    report = {"opened_at": 110.0, "marks": {"config read": 106.5, "trainer imported": 104.0}}
    stages = with_time_before_training(report, 100.0)["stages"]
    assert stages["before training"] == 10.0
    assert stages["of it trainer imported"] == 4.0 and stages["of it config read"] == 2.5
    assert stages["of it up to the trainer's report"] == 3.5
    assert list(stages)[1:3] == ["of it trainer imported", "of it config read"]
    assert with_time_before_training({"stages": {}}, 1.0) == {"stages": {}}
    # a mark from before the seed's start (the process's, for seeds trained in turn) is left out
    report["marks"]["command read"] = 90.0
    assert "of it command read" not in with_time_before_training(report, 100.0)["stages"]


def test_warm_seeds_are_those_started_after_a_seed_had_ended() -> None:
    """On a host of two GPUs the first two seeds start at once with empty caches: a record's
    ``warm`` flag leaves both out of the warm times, and records without the flag (reports
    written before it) leave out the first alone."""
    runs = [_run(0, 40.0), _run(1, 50.0), _run(2, 20.0), _run(3, 30.0)]
    for run, warm in zip(runs, (False, False, True, True), strict=True):
        run.warm = warm
    assert summarize(runs, 0.95)["time_to_threshold_warm"]["n"] == 2
    assert summarize(runs, 0.95)["time_to_threshold_warm"]["median"] == 25.0
    for run in runs:
        run.warm = None
    assert summarize(runs, 0.95)["time_to_threshold_warm"]["median"] == 30.0


def test_the_report_lines_give_the_median_steps_and_speed() -> None:
    """The markdown summary names the median env steps to the threshold and the median
    training env steps/s, which the time alone does not separate."""
    from mjx_arm.bench.seeds_summary import summary_lines

    text = summary_lines(summarize([_run(0, 12.0), _run(1, 14.0), _run(2, None, 0.5)], 0.95))
    assert "- median env steps to it: 2,000; median training env steps/s: 1,000\n" in text
    assert "median env steps" not in summary_lines(
        {**summarize([_run(0, 9.0)], 0.95)}
        | {"median_steps_to_threshold": None, "median_training_steps_per_s": None}
    )
