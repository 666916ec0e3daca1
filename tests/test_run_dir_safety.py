"""Run directories and the files they hold: read only as bounded regular files, written only
where the user asked, never through a link, and every damaged one a named error."""

from __future__ import annotations

import argparse
import errno
import json
import math
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from input_fuzz.corpus import CHECKPOINT_STEP, Corpus, brax_params, build
from mjx_arm.cli import build_parser, main, report_folders
from mjx_arm.inputs import (
    InputFileError,
    MiB,
    MissingInputError,
    OversizedInputError,
    open_regular,
    read_bytes,
    read_json_object,
    read_npz_members,
    read_text,
)
from mjx_arm.names import EXIT_INVALID
from mjx_arm.policy.export import load_run
from mjx_arm.train import checkpoints
from mjx_arm.train.checkpoints import CheckpointError
from mjx_arm.train.rundir import MARKER, RunDir, RunDirError, claim, is_run_dir

# orbax's restore threads outlive their event loop after a read error: noise, not our error
pytestmark = pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")

# --------------------------------------------------------------------------- bounded reads


def test_read_bytes_takes_a_regular_file_within_its_bound(tmp_path: Path) -> None:
    path = tmp_path / "a.json"
    path.write_bytes(b'{"step": 3}')
    assert read_bytes(path, "file", 11) == b'{"step": 3}'
    assert read_json_object(path, "file", within=tmp_path) == {"step": 3}
    with open_regular(path, "file", 11) as f:
        assert f.read() == b'{"step": 3}'
    with pytest.raises(OversizedInputError, match=r"file '.*a\.json' holds 11 bytes or more"):
        read_bytes(path, "file", 10)


def test_a_fifo_a_device_or_a_folder_is_refused_without_reading(tmp_path: Path) -> None:
    """A FIFO with no writer would block a plain open; /dev/zero would read without end."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    zero = tmp_path / "zero"
    zero.symlink_to("/dev/zero")
    for path in (fifo, zero):
        with pytest.raises(InputFileError, match="not a regular file"):
            read_text(path, "meta")
    with pytest.raises(InputFileError, match="is a folder"):
        read_text(tmp_path, "meta")
    with pytest.raises(MissingInputError, match="does not exist"):
        read_text(tmp_path / "none", "meta")


def test_within_refuses_a_link_out_of_the_folder_and_keeps_one_inside(tmp_path: Path) -> None:
    run = tmp_path / "run"
    run.mkdir()
    (tmp_path / "elsewhere.json").write_text("{}")
    (run / "out.json").symlink_to(tmp_path / "elsewhere.json")
    (run / "in.json").write_text('{"a": 1}')
    (run / "link.json").symlink_to("in.json")
    with pytest.raises(InputFileError, match=r"is a link to .*elsewhere\.json, outside"):
        read_json_object(run / "out.json", "config", within=run)
    assert read_json_object(run / "out.json", "config") == {}  # no folder given: followed
    assert read_json_object(run / "link.json", "config", within=run) == {"a": 1}


def test_an_npz_that_is_a_fifo_is_refused_unread(tmp_path: Path) -> None:
    """zipfile would block on opening a FIFO with no writer."""
    fifo = tmp_path / "resume.npz"
    os.mkfifo(fifo)
    with pytest.raises(InputFileError, match="not a regular file"):
        read_npz_members(fifo, "resume state", max_member_bytes=MiB, max_total_bytes=MiB)


# --------------------------------------------------------------------------- run directories


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Corpus:
    return build(tmp_path_factory.mktemp("run_dir_corpus"))


def _run(corpus: Corpus, tmp_path: Path) -> Path:
    """A copy of the corpus's run directory (config.json, metrics.csv, one checkpoint)."""
    run_dir = tmp_path / "run"
    shutil.copytree(corpus.run_dir, run_dir)
    return run_dir


def _fails(argv: list[str], capsys) -> str:
    """Run ``mjx-arm argv``: exit 2, one error line, no traceback; the line."""
    code = main(argv)
    err = capsys.readouterr().err
    assert code == EXIT_INVALID and "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, err
    return lines[0]


def _listing(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` and its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def _checkpoint(run_dir: Path) -> Path:
    return next((run_dir / "checkpoints").iterdir())


def test_a_lock_file_that_is_a_link_is_refused_and_its_target_untouched(
    corpus: Corpus, tmp_path: Path, capsys
) -> None:
    run_dir = _run(corpus, tmp_path)
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    (run_dir / ".lock").symlink_to(victim)
    line = _fails(["train", "--resume", str(run_dir), "--quiet"], capsys)
    assert "lock file" in line and "is a symbolic link: refused" in line
    assert victim.read_text() == "precious"
    (run_dir / ".lock").unlink()
    os.mkfifo(run_dir / ".lock")
    with pytest.raises(RunDirError, match="is not a regular file"), RunDir(run_dir).lock():
        pass


def test_no_run_file_is_written_through_a_link(corpus: Corpus, tmp_path: Path) -> None:
    """metrics.csv appended, rewritten or truncated; the write probe; a checkpoints/ or tb/
    folder that links out of the run directory: never the link's target."""
    run_dir = _run(corpus, tmp_path)
    victim = tmp_path / "victim.csv"
    victim.write_text("step,x\n1,2\n")
    (run_dir / "metrics.csv").unlink()
    (run_dir / "metrics.csv").symlink_to(victim)
    run = RunDir(run_dir)
    with pytest.raises(RunDirError, match="outside"):
        run.log_metrics(20, {"eval/episode_reward": 1.0})
    with pytest.raises(RunDirError, match="outside"):
        run.truncate_metrics(0)
    (run_dir / "metrics.csv").unlink()
    (run_dir / "other.csv").write_text("step,time,eval/episode_reward\n1,2,3\n")
    (run_dir / "metrics.csv").symlink_to("other.csv")  # a link inside: read, never written
    with pytest.raises(RunDirError, match="symbolic link"):
        RunDir(run_dir).log_metrics(20, {"eval/episode_reward": 1.0})
    (run_dir / ".write-probe").symlink_to(victim)  # the probe of an older version's name
    run.check_writable()
    (run_dir / "tb").rename(tmp_path / "tb")
    (run_dir / "tb").symlink_to(tmp_path / "tb")
    with pytest.raises(RunDirError, match=r"tb is a link to .*, outside the run directory"):
        run.check_writable()
    assert victim.read_text() == "step,x\n1,2\n"
    assert (run_dir / "other.csv").read_text() == "step,time,eval/episode_reward\n1,2,3\n"


def test_a_save_deletes_nothing_through_a_checkpoint_link(tmp_path: Path) -> None:
    """A save drops the older checkpoints' env state: never a file a link leads to."""
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    (outside / "env_state.npz").write_bytes(b"kept")
    run = RunDir(tmp_path / "run")
    run.checkpoints.mkdir()
    run.checkpoint_dir(1).symlink_to(outside)
    params = brax_params(22, 6, np.random.default_rng(0))
    run.save_checkpoint(2, params, {"task": "reach"}, newest_only=("env_state.npz",))
    assert (outside / "env_state.npz").read_bytes() == b"kept"


def test_the_launcher_writes_no_process_log_through_a_link(tmp_path: Path, monkeypatch) -> None:
    from mjx_arm.train import launch
    from mjx_arm.train.distributed import ProcessGroup

    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    logs = tmp_path / "run" / "logs"
    logs.mkdir(parents=True)
    (logs / "process_1.log").symlink_to(victim)
    monkeypatch.setattr(launch.sys, "executable", "/bin/true")  # no training is started
    groups = tuple(ProcessGroup("127.0.0.1:1", 2, i, 60) for i in (0, 1))
    with pytest.raises(RunDirError, match=r"process log .* is a symbolic link"):
        launch.run(launch.Plan(("0", "1"), groups), ["train"], logs, log=lambda _: None)
    assert victim.read_text() == "precious"


def test_a_users_folder_is_never_taken_for_a_new_run(tmp_path: Path, capsys) -> None:
    """A folder holding the user's own config.json and metrics.csv (without a step column):
    refused, named, nothing in it written or added (no marker, no error report)."""
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "config.json").write_text('{"mine": 1}')
    (folder / "metrics.csv").write_text("a,b\n1,2\n")
    before = _listing(folder)
    argv = ["train", "--preset", "cpu", "--task", "reach", "--backend", "mujoco"]
    line = _fails([*argv, "--run-dir", str(folder), "--quiet"], capsys)
    assert str(folder) in line and "is not an mjx-arm run directory" in line
    assert "new or empty folder" in line and "--resume" in line
    assert _listing(folder) == before and sorted(p.name for p in folder.iterdir()) == [
        "config.json",
        "metrics.csv",
    ]
    with pytest.raises(RunDirError, match="is not an mjx-arm run directory"):
        claim(folder)


def test_new_and_empty_folders_and_the_projects_run_directories_are_claimed(
    corpus: Corpus, tmp_path: Path
) -> None:
    assert claim(tmp_path / "new" / "run") == tmp_path / "new" / "run"
    (tmp_path / "empty").mkdir()
    claim(tmp_path / "empty")
    run_dir = _run(corpus, tmp_path)  # a run of a version before the marker: its config.json
    assert not (run_dir / MARKER).exists() and is_run_dir(run_dir)
    claim(run_dir)
    for folder in (tmp_path / "new" / "run", tmp_path / "empty", run_dir):
        assert (folder / MARKER).is_file() and is_run_dir(folder)
    (run_dir / "config.json").write_text('{"train": "a string, not a table"}')
    assert is_run_dir(run_dir)  # its marker says so now
    with pytest.raises(RunDirError, match="is a file"):
        claim(run_dir / "config.json")


def test_a_killed_run_before_its_config_is_claimed_again(tmp_path: Path) -> None:
    """A run killed while compiling left its marker, lock and logs, no config.json yet."""
    folder = claim(tmp_path / "run")
    (folder / ".lock").write_text("123")
    (folder / "logs").mkdir()
    assert claim(folder) == folder


@pytest.mark.parametrize(
    "damage, message",
    [
        ("long field", "is not a CSV file of metrics (field larger than field limit"),
        ("not utf-8", "cannot be read as UTF-8 text"),
        ("a folder", "is a folder, not a file"),
        ("no step column", "has no step column"),
    ],
)
def test_a_damaged_metrics_file_is_a_named_error_on_resume(
    corpus: Corpus, tmp_path: Path, capsys, damage: str, message: str
) -> None:
    run_dir = _run(corpus, tmp_path)
    metrics = run_dir / "metrics.csv"
    if damage == "long field":
        metrics.write_text(metrics.read_text() + "10240," + "x" * 200_000 + "\n")
    elif damage == "not utf-8":
        metrics.write_bytes(metrics.read_bytes() + b"\xff\xfe\x80")
    elif damage == "a folder":
        metrics.unlink()
        metrics.mkdir()
    else:
        metrics.write_text("reward,time\n1,2\n")
    line = _fails(["train", "--resume", str(run_dir), "--quiet"], capsys)
    assert message in line and "aside" in line
    with pytest.raises(RunDirError, match=message.split(" (")[0]):
        RunDir(run_dir).read_metrics()


def test_metrics_cells_that_are_not_numbers_read_as_nan(tmp_path: Path) -> None:
    run = RunDir(tmp_path / "run")
    (run.path / "metrics.csv").write_text("step,reward\n10,abc\n20,1.5,extra\n30\n")
    rows = run.read_metrics()
    assert [r["step"] for r in rows] == [10.0, 20.0, 30.0] and rows[1]["reward"] == 1.5
    assert math.isnan(rows[0]["reward"]) and math.isnan(rows[2]["reward"])
    assert run.truncate_metrics(20) == 2  # the row with an extra cell and the cut row
    assert [r["step"] for r in run.read_metrics()] == [10.0]


def test_a_config_of_strings_where_numbers_belong_is_a_named_error(
    corpus: Corpus, tmp_path: Path, capsys
) -> None:
    run_dir = _run(corpus, tmp_path)
    config = json.loads((run_dir / "config.json").read_text())
    (run_dir / "config.json").write_text(json.dumps(_strings(config)))
    for argv in (["export", str(run_dir), "-o", str(tmp_path / "p.npz")], ["eval", str(run_dir)]):
        line = _fails(argv, capsys)
        assert "must be a finite number, got '0.5'" in line or "finite numbers" in line, line
    assert not (tmp_path / "p.npz").exists()


def _strings(value):
    """``value`` with every number in it a string."""
    if isinstance(value, dict):
        return {k: _strings(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_strings(v) for v in value]
    return str(value) if isinstance(value, int | float) and not isinstance(value, bool) else value


def test_a_folder_named_like_a_checkpoint_is_none(corpus: Corpus, tmp_path: Path, capsys) -> None:
    run_dir = _run(corpus, tmp_path)
    (run_dir / "checkpoints" / "step_abc").mkdir()
    (run_dir / "checkpoints" / "step_abc" / "meta.json").write_text('{"step": 5}')
    (run_dir / "checkpoints" / "step_abc" / "params").mkdir()
    line = _fails(["export", str(run_dir), "-o", str(tmp_path / "p.npz"), "--step", "7"], capsys)
    assert f"no usable checkpoint at step 7 in {run_dir / 'checkpoints'}" in line
    assert f"steps available: [{CHECKPOINT_STEP}]" in line
    assert RunDir(run_dir).latest_checkpoint() == _checkpoint_at(run_dir, CHECKPOINT_STEP)


def _checkpoint_at(run_dir: Path, step: int) -> Path:
    return RunDir(run_dir).checkpoint_dir(step)


def test_a_read_only_run_with_a_killed_saves_old_checkpoint_is_read_in_place(
    corpus: Corpus, tmp_path: Path, monkeypatch
) -> None:
    """``.old-step_N`` cannot be moved back where the run directory is read-only: it is read
    where it lies (as root, which chmod does not stop, the rename is made to fail)."""
    run_dir = _run(corpus, tmp_path)
    folder = _checkpoint(run_dir)
    old = folder.with_name(".old-" + folder.name)
    os.replace(folder, old)
    if os.geteuid() == 0:

        def read_only(*_):
            raise PermissionError(errno.EACCES, "Permission denied")

        monkeypatch.setattr(checkpoints.os, "replace", read_only)
    for path in (run_dir, run_dir / "checkpoints"):
        path.chmod(0o555)
    try:
        assert RunDir(run_dir).latest_checkpoint() == old
        arrays, metadata, _ = load_run(run_dir)
        assert metadata["step"] == CHECKPOINT_STEP and arrays["obs_mean"].shape == (22,)
    finally:
        for path in (run_dir, run_dir / "checkpoints"):
            path.chmod(0o755)
    assert old.is_dir() and not folder.exists()


def test_checkpoint_files_that_are_devices_fifos_or_links_out_are_named(
    corpus: Corpus, tmp_path: Path, capsys
) -> None:
    """meta.json a link to /dev/zero (read whole, it filled the memory), a FIFO (a plain open
    blocks), a link out of the run; a params file that is a FIFO."""
    run_dir = _run(corpus, tmp_path)
    meta = _checkpoint(run_dir) / "meta.json"
    kept = meta.read_bytes()
    (tmp_path / "meta.json").write_bytes(kept)
    for make, message in [
        (lambda: meta.symlink_to("/dev/zero"), "is a link to /dev/zero, outside"),
        (lambda: os.mkfifo(meta), "is not a regular file"),
        (lambda: meta.symlink_to(tmp_path / "meta.json"), "outside"),
    ]:
        meta.unlink()
        make()
        line = _fails(["export", str(run_dir), "-o", str(tmp_path / "p.npz")], capsys)
        assert "no usable checkpoint in" in line and "meta.json" in line, line
        with pytest.raises(CheckpointError, match=message):
            RunDir.load_meta(meta.parent)
    meta.unlink()
    meta.write_bytes(kept)
    data = next(p for p in (meta.parent / "params").rglob("*") if p.is_file())
    data.unlink()
    os.mkfifo(data)
    with pytest.raises(CheckpointError, match="is not a regular file"):
        RunDir.load_params(meta.parent)


def test_a_refused_run_dir_gets_no_error_report(tmp_path: Path) -> None:
    """A long error line's report goes to the command's run directory only where that is a
    run directory: never into a folder of the user's that train refused."""
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    run_dir = claim(tmp_path / "run")
    assert mine not in report_folders(argparse.Namespace(run_dir=str(mine)))
    assert report_folders(argparse.Namespace(run_dir=str(run_dir)))[0] == run_dir


# --------------------------------------------------------------------------- bench outputs


def test_no_bench_command_defaults_into_the_committed_results() -> None:
    """Every ``bench`` command's --out defaults to none: a new runs/bench/KIND-TIMESTAMP."""
    bench = _subparsers(build_parser())["bench"]
    commands = _subparsers(bench)
    assert set(commands) == {"parity", "grasp", "transfer", "robustness", "seeds"}
    for name, parser in commands.items():
        out = next(a for a in parser._actions if a.dest == "out")
        assert out.default is None, name
        assert f"runs/bench/{name}-TIMESTAMP" in out.help and "benchmarks/results" in out.help


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def test_bench_from_a_clone_leaves_the_committed_results_alone(
    tmp_path: Path, monkeypatch, capsys
) -> None:
    """Run where a clone's benchmarks/results/grasp/grasp.json lies: the report goes to a new
    runs/bench/grasp-TIMESTAMP folder; with --out naming the committed folder, there."""
    committed = tmp_path / "benchmarks" / "results" / "grasp"
    committed.mkdir(parents=True)
    (committed / "grasp.json").write_text('{"committed": true}')
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "grasp", "--engines", "mujoco"]) == 0
    assert (committed / "grasp.json").read_text() == '{"committed": true}'
    (made,) = (tmp_path / "runs" / "bench").iterdir()
    assert made.name.startswith("grasp-") and sorted(p.name for p in made.iterdir()) == [
        "grasp.json",
        "grasp.md",
    ]
    assert f"wrote {Path('runs', 'bench', made.name, 'grasp.json')}" in capsys.readouterr().out
    assert main(["bench", "grasp", "--engines", "mujoco", "--out", str(committed)]) == 0
    assert json.loads((committed / "grasp.json").read_text())["starts"]


def test_compile_reports_are_read_bounded_and_a_damaged_file_starts_afresh(tmp_path: Path) -> None:
    run = RunDir(tmp_path / "run")
    assert run.compile_reports() == []
    run.save_compile_report({"compile_s": 3.0})
    assert run.compile_reports() == [{"compile_s": 3.0}]
    (run.path / "compile.json").unlink()
    (run.path / "compile.json").symlink_to("/dev/zero")
    assert run.compile_reports() == []
    run.save_compile_report({"compile_s": 1.0})  # replaces the link, writes nothing through it
    assert run.compile_reports() == [{"compile_s": 1.0}]
    assert not (run.path / "compile.json").is_symlink()


def test_a_run_config_that_is_a_fifo_or_a_device_is_named(
    corpus: Corpus, tmp_path: Path, capsys
) -> None:
    run_dir = _run(corpus, tmp_path)
    (run_dir / "config.json").unlink()
    os.mkfifo(run_dir / "config.json")
    line = _fails(["export", str(run_dir), "-o", str(tmp_path / "p.npz")], capsys)
    assert "run config" in line and "not a regular file" in line
    (run_dir / "config.json").unlink()
    (run_dir / "config.json").symlink_to("/dev/zero")
    line = _fails(["train", "--resume", str(run_dir)], capsys)
    assert "run config" in line and "outside" in line
