"""The command line against generated inputs (:mod:`input_fuzz`): every subcommand's arguments
and good, mutated and hostile policy files (``.npz``, ONNX), arm files, configs, run
directories, trajectories, URDFs and URDFs with meshes, special files in their place (FIFOs,
devices, sockets, folders, links), and output paths of 250-byte names, under absent folders or
in a user's folder, run through ``mjx_arm.cli.main`` in capped worker processes
(:mod:`input_fuzz.pool`).

A case passes when it exits 0, or 2 with one ``error:`` line, or reaches the work its command
would start (stopped there: no training, no MJX); a traceback, a crash of the worker, running
out of memory under the cap, another exit code, a hang, a spoiled good output, a file changed
outside the named outputs or a peak RSS over 1.5 GB fails it.
:data:`FUZZ_EXAMPLES` cases of each command and a few of each new kind run in one pool of two
workers (its warm-up, 20-30 s, paid once); the file's fast tests take about 80 s on a 2-core
CPU. The hostile mutations are checked to really be hostile (a header that declares 2^40
elements, a graph that allocates 2^36 floats, names of the exact lengths, a FIFO, a .zae that
unpacks to 3 GiB, a PNG header of 10^10 pixels). benchmarks/bench_input_fuzz.py runs 8,000 cases.
"""

from __future__ import annotations

import itertools
import json
import os
import re
import shutil
import stat
import struct
import subprocess
import sys
import zipfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings

from input_fuzz import (
    hostile,
    hostile_mesh,
    hostile_npz,
    hostile_onnx,
    hostile_run,
    sentinel,
    special,
)
from input_fuzz import mutate as mutate_module
from input_fuzz.cases import CASES, QUICK_PARITY, Case, In, Out, cases
from input_fuzz.corpus import Corpus, build
from input_fuzz.harness import MAX_ERROR_CHARS, RSS_LIMIT_MB, Outcome, run_case, tally
from input_fuzz.hostile_npz import pick
from input_fuzz.pool import CAP_BYTES, Pool, probe
from mjx_arm.urdf import findings as hostile_mesh_limits

FUZZ_EXAMPLES = 2  # of each command
MUST_BE_ZERO = ("traceback", "crash", "memory", "lost", "outside", "unnamed", "hang", "rss")
_COUNTER = itertools.count()


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Corpus:
    return build(tmp_path_factory.mktemp("input_corpus"))


@pytest.fixture(scope="module")
def cases_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("input_cases")


@pytest.fixture(scope="module")
def pool(corpus: Corpus) -> Iterator[Pool]:
    """Two workers, warmed up once for the module's pool tests."""
    with Pool(corpus, workers=2) as workers:
        yield workers


def _run(case: Case, corpus: Corpus, folder: Path) -> Outcome:
    return run_case(case, corpus, folder / f"case{next(_COUNTER)}")


def _explain(outcome: Outcome) -> str:
    return f"{outcome.status}: mjx-arm {' '.join(outcome.argv)}\n{outcome.detail}"


def _draw(count: int, commands: tuple[str, ...] | None = None) -> list[Case]:
    drawn: list[Case] = []

    @settings(
        max_examples=count,
        phases=[Phase.generate],
        derandomize=True,
        database=None,
        deadline=None,
        suppress_health_check=list(HealthCheck),
    )
    @given(case=cases(commands))
    def draw(case: Case) -> None:
        drawn.append(case)

    draw()
    return drawn


def _fuzz(pool: Pool, folder: Path, count: int, per_command: bool = False) -> list[Outcome]:
    """``count`` generated cases (``per_command``: that many of each command) run in ``pool``."""
    drawn = [c for name in CASES for c in _draw(count, (name,))] if per_command else _draw(count)
    jobs = [(case, folder / f"gen{next(_COUNTER)}") for case in drawn]
    return list(pool.run(jobs))


def _assert_clean(outcomes: list[Outcome]) -> dict:
    counts = tally(outcomes)["all"]
    bad = [o for o in outcomes if o.status in MUST_BE_ZERO]
    assert not bad, "\n\n".join(_explain(o) for o in bad[:5])
    assert all(counts[s] == 0 for s in MUST_BE_ZERO), counts
    return counts


def test_generated_command_lines_in_capped_workers(pool: Pool, cases_dir: Path) -> None:
    outcomes = _fuzz(pool, cases_dir, FUZZ_EXAMPLES, per_command=True)
    counts = _assert_clean(outcomes)
    assert counts["cases"] == FUZZ_EXAMPLES * len(CASES)
    assert {o.command for o in outcomes} == set(CASES), "every subcommand was tried"
    modes = {label.split()[1] for o in outcomes for label in o.inputs}
    assert {"good", "hostile", "missing"} <= modes, modes
    assert 0 < max(o.peak_rss_mb for o in outcomes) < CAP_BYTES / 2**20


@pytest.mark.slow
def test_a_thousand_generated_command_lines(pool: Pool, cases_dir: Path) -> None:
    _assert_clean(_fuzz(pool, cases_dir, 1000))


GOOD_CASES = {
    "arm": (["arm", In("arm_file", "good", 0), "-o", Out(".toml", True)], "ok"),
    "arm_json": (["arm", In("arm_json", "good", 0), "-o", Out(".toml", True)], "ok"),
    "export": (["export", In("run_dir", "good", 0), "-o", Out(".npz", True)], "ok"),
    "eval": (["eval", In("policy", "good", 0), "--episodes", "1", "-o", Out(".json", True)], "ok"),
    "replay": (["replay", In("trajectory", "good", 0), "-o", Out(".png", True)], "ok"),
    "train": (
        ["train", "--preset", "cpu", "--backend", "mujoco", "--run-dir", Out("", False)],
        "work",
    ),
    "resume": (["train", "--resume", In("run_dir", "good", 0)], "work"),
    "deploy-sim": (["deploy-sim", In("policy", "good", 0), "--episodes", "1"], "work"),
    # a 250-byte file name is a file name like any other
    "eval_long_name": (
        ["eval", In("policy", "good", 0), "--episodes", "1", "-o", Out(".json", True, "long")],
        "ok",
    ),
    "export_long_name": (["export", In("run_dir", "good", 0), "-o", Out(".onnx", False, "long")],
                         "ok"),
    # a folder of the user's holding their config.json and metrics.csv is not a run's
    "user_run_dir": (
        ["train", "--preset", "cpu", "--backend", "mujoco", "--run-dir", Out("", True, "user")],
        "named",
    ),
}  # fmt: skip


@pytest.mark.parametrize("name", sorted(GOOD_CASES))
def test_good_inputs_pass_and_overwrite_outputs_whole(
    name: str, corpus: Corpus, cases_dir: Path
) -> None:
    argv, expected = GOOD_CASES[name]
    outcome = _run(Case(name, list(argv)), corpus, cases_dir)
    assert outcome.status == expected, _explain(outcome)


def test_a_held_run_directory_is_refused_by_name(corpus: Corpus, cases_dir: Path) -> None:
    case = Case("train", ["train", "--resume", In("run_dir", "good", 0)], lock=True)
    outcome = _run(case, corpus, cases_dir)
    assert outcome.status == "named" and "in use by another training (pid 4242)" in outcome.detail


def test_the_judge_sees_tracebacks_spoiled_outputs_memory_and_long_lines(
    corpus: Corpus, cases_dir: Path, monkeypatch
) -> None:
    """A bug in a command is a traceback; a failing command that overwrites its output is a
    lost output; a MemoryError is ``memory``; an error line over 300 characters is ``long``."""
    import mjx_arm.policy.export as export
    from mjx_arm.train.checkpoints import CheckpointError

    case = Case("export", ["export", In("run_dir", "good", 0), "-o", Out(".npz", True)])

    def fail(exc: BaseException):
        def raiser(*_args, **_kwargs):
            raise exc

        return raiser

    monkeypatch.setattr(export, "load_run", fail(RuntimeError("a bug")))
    assert _run(case, corpus, cases_dir).status == "traceback"
    monkeypatch.setattr(export, "load_run", fail(MemoryError()))
    assert _run(case, corpus, cases_dir).status == "memory"

    def long_line(*_args, **_kwargs):  # past the command's own shortening of its lines
        print("error: " + "x" * MAX_ERROR_CHARS, file=sys.stderr)
        raise SystemExit(2)

    monkeypatch.setattr(export, "load_run", long_line)
    outcome = _run(case, corpus, cases_dir)
    assert outcome.status == "long" and outcome.error_chars > MAX_ERROR_CHARS

    def spoil(run_dir, output, step=None):
        Path(output).write_bytes(b"half a file")
        raise CheckpointError("damaged")

    monkeypatch.undo()
    monkeypatch.setattr(export, "export_run", spoil)
    assert _run(case, corpus, cases_dir).status == "lost"


def test_the_pool_reports_a_crash_and_a_capped_allocation_and_goes_on(
    corpus: Corpus, tmp_path: Path
) -> None:
    jobs = [
        (Case("allocate", [str(2 * CAP_BYTES)]), tmp_path),
        (Case("segfault", []), tmp_path),
        (Case("fine", []), tmp_path),
    ]
    with Pool(corpus, workers=1, runner=probe) as pool:
        statuses = {o.command: (o.status, o.detail) for o in pool.run(jobs)}
        restarts = pool.restarts
    assert statuses["allocate"][0] == "memory"
    assert statuses["segfault"] == ("crash", "worker killed by SIGSEGV")
    assert statuses["fine"][0] == "ok" and restarts == 2  # after the memory case and the crash


# --------------------------------------------------------------------------- hostile .npz


def _member_header(path: Path, name: str) -> tuple[tuple[int, ...], np.dtype]:
    from numpy.lib import format as npy

    with zipfile.ZipFile(path) as archive, archive.open(f"{name}.npy") as stream:
        npy.read_magic(stream)
        shape, _, dtype = npy.read_array_header_1_0(stream)
    return shape, dtype


def test_a_huge_header_declares_2_to_the_40_elements_in_a_small_file(corpus, tmp_path) -> None:
    out = tmp_path / "huge.npz"
    what = hostile_npz.huge_header(corpus.policy, out, np.random.default_rng(0))
    name = what.split()[0]
    shape, dtype = _member_header(out, name)
    assert int(np.prod(shape, dtype=object)) == hostile_npz.HUGE_ELEMENTS and dtype == np.float32
    assert out.stat().st_size < 100_000


def test_a_zip_bomb_member_declares_3_gib_of_zeros_in_3_mb(corpus, tmp_path) -> None:
    out = tmp_path / "bomb.npz"
    hostile_npz.zip_bomb(corpus.policy, out, np.random.default_rng(0))
    with zipfile.ZipFile(out) as archive:
        (info,) = [i for i in archive.infolist() if i.compress_type == zipfile.ZIP_DEFLATED]
        assert info.file_size > hostile_npz.BOMB_BYTES and info.compress_size < 4 * 2**20
        with archive.open(info) as stream:  # the first 128 MiB really unpack, to zeros
            stream.read(128)
            chunk = stream.read(128 * 2**20)
    assert len(chunk) == 128 * 2**20 and chunk.count(0) == len(chunk)
    shape, dtype = _member_header(out, info.filename[:-4])
    assert shape == (hostile_npz.BOMB_BYTES,) and dtype == np.uint8


@pytest.mark.slow
def test_the_zip_bomb_unpacks_whole_with_its_crc(corpus, tmp_path) -> None:
    out = tmp_path / "bomb.npz"
    hostile_npz.zip_bomb(corpus.policy, out, np.random.default_rng(0))
    with zipfile.ZipFile(out) as archive:
        assert archive.testzip() is None  # every member read to its end, CRC checked


@pytest.mark.parametrize(
    ("mutation", "check"),
    [
        (hostile_npz.object_member, lambda a: a.dtype.hasobject),
        (hostile_npz.wrong_dtype, lambda a: a.dtype != np.float32),
        (hostile_npz.extreme_values, lambda a: not np.isfinite(a).all() or abs(a).max() >= 3e38
         or 0 < abs(a).max() < 1e-44),
        (hostile_npz.misfit_shape, lambda a: True),
    ],
)  # fmt: skip
def test_npz_members_are_made_hostile(mutation, check, corpus, tmp_path) -> None:
    for seed in range(6):
        out = tmp_path / f"{mutation.__name__}{seed}.npz"
        what = mutation(corpus.trajectory, out, np.random.default_rng(seed))
        name = what.split()[0]
        with np.load(out, allow_pickle=True) as data:
            good = np.load(corpus.trajectory)
            if name in good.files and mutation is hostile_npz.misfit_shape:
                assert data[name].shape != good[name].shape, what
            elif name in data.files:
                assert check(data[name]) or data[name].size == 0, what


# --------------------------------------------------------------------------- hostile ONNX

_RUN_GRAPH = """
import resource, sys
import numpy as np, onnxruntime as ort
resource.setrlimit(resource.RLIMIT_AS, (2 * 2**30, 2 * 2**30))
try:
    s = ort.InferenceSession(sys.argv[1], providers=["CPUExecutionProvider"])
    s.run(None, {"state": np.zeros((1, 22), np.float32)})
    print("RAN_WHOLE")
except Exception as exc:
    print(type(exc).__name__, exc)
"""


@pytest.mark.parametrize("how", ["expand", "constant_of_shape", "tile"])
def test_the_onnx_bomb_really_allocates_2_to_the_36_floats(how, corpus, tmp_path) -> None:
    """Run by onnxruntime itself under a 2 GiB cap, the graph fails to allocate its tensor (or
    onnxruntime's Tile refuses an output over 4 GiB)."""
    pytest.importorskip("onnxruntime")
    out = tmp_path / f"{how}.onnx"
    for seed in range(40):  # the mutation picks how; find a seed that picks this one
        if how in hostile_onnx.runtime_bomb(corpus.onnx, out, np.random.default_rng(seed)):
            break
    result = subprocess.run(
        [sys.executable, "-c", _RUN_GRAPH, str(out)], capture_output=True, text=True, timeout=60
    )
    said = result.stdout.lower()
    assert "RAN_WHOLE" not in result.stdout, said
    assert "allocat" in said or "would require more than 4294967296 bytes" in said, said


def test_onnx_graphs_are_made_hostile(corpus, tmp_path) -> None:
    import onnx
    import onnxruntime as ort

    out = tmp_path / "p.onnx"
    hostile_onnx.input_double(corpus.onnx, out, np.random.default_rng(0))
    assert onnx.load(str(out)).graph.input[0].type.tensor_type.elem_type == onnx.TensorProto.DOUBLE
    ranks = set()
    for seed in range(12):
        hostile_onnx.input_shape(corpus.onnx, out, np.random.default_rng(seed))
        dims = onnx.load(str(out)).graph.input[0].type.tensor_type.shape.dim
        ranks.add(len(dims) if len(dims) != 2 else ("obs", dims[1].dim_value))
    assert {1, 3} <= ranks and any(isinstance(r, tuple) and r[1] != 22 for r in ranks)
    hostile_onnx.nan_output(corpus.onnx, out, np.random.default_rng(0))
    session = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"])
    (params,) = session.run(["distribution_params"], {"state": np.zeros((2, 22), np.float32)})
    assert params.shape == (2, 12) and not np.isfinite(params).any()


# --------------------------------------------------------------------------- other kinds


def test_urdf_names_of_the_limit_lengths_and_big_chains(corpus, tmp_path) -> None:
    text = corpus.urdf.read_text()
    lengths, chains = set(), set()
    for seed in range(60):
        rng = np.random.default_rng(seed)
        mutated, what = hostile.long_name(text, rng)
        length = int(what.split()[-2])
        names = hostile._names(mutated, "link") + hostile._names(mutated, "joint")
        assert any(len(n) == length for n in names), what
        lengths.add(length)
        chains.add(hostile.deep_chain(text, rng)[0].count("<joint "))
    limit = hostile.MAX_NAME_CHARS
    assert {limit - 1, limit, limit + 1, 100_000} <= lengths
    assert min(chains) > 500 and max(chains) > 2000
    mutated, what = hostile.non_ascii_name(text, np.random.default_rng(1))
    assert not mutated.isascii()
    mesh, _ = hostile.huge_mesh(text, np.random.default_rng(0))
    assert len(mesh) > len(text) + 1000 or "1e30" in mesh


@pytest.mark.parametrize("fmt", ["json", "toml"])
def test_tables_get_hostile_values(fmt: str, corpus) -> None:
    import tomllib

    data = tomllib.loads(corpus.arm_file.read_text())
    kinds = set()
    for seed in range(80):
        text, what = hostile.hostile_table_text(dict(data), fmt, np.random.default_rng(seed))
        kinds.add(what.split(":")[0])
        if what.startswith("nesting") and " 100000 " in f" {what.split()[-2]} ":
            assert "[" * 100_000 in text
        if what.startswith("unknown_keys"):
            assert text.count("no_such_key_") == 20_000
    assert {"type", "huge", "nesting", "long", "unknown_keys"} <= kinds


def test_run_directories_get_hostile_parts(corpus, tmp_path) -> None:
    seen = set()
    for seed in range(40):
        out = tmp_path / f"run{seed}"
        what = hostile.hostile_run_dir(corpus.run_dir, out, np.random.default_rng(seed))
        checkpoint = sorted((out / "checkpoints").glob("step_*"))[-1]
        seen.add(what.split()[0])
        if what.startswith("resume.npz"):
            assert (checkpoint / "resume.npz").is_file()
        if what.startswith("orbax sparse"):
            sizes = [p.stat().st_size for p in (checkpoint / "params").rglob("*") if p.is_file()]
            assert max(sizes) == 3 * 2**30
    assert {"resume.npz", "env_state.npz", "orbax", "config.json", "meta.json"} <= seen


# --------------------------------------------------------------------------- new kinds


def _seed_where(predicate, limit: int = 2000) -> int:
    """The first seed whose rng makes ``predicate(rng)`` true (the draws a generator makes)."""
    return next(s for s in range(limit) if predicate(np.random.default_rng(s)))


def _special_seed(how: str) -> int:
    return _seed_where(lambda rng: pick(rng, special.SPECIALS) == how)


def _hostile_seed(kind: str, mutation) -> int:
    return _seed_where(lambda rng: pick(rng, mutate_module._hostile()[kind]) is mutation)


def _run_file_seed(edit) -> int:
    files = hostile_run.hostile_run_files
    runs = mutate_module._hostile()["run_dir"]
    return _seed_where(
        lambda r: pick(r, runs) is files and pick(r, hostile_run.RUN_FILE_EDITS) is edit
    )


SPECIAL_COMMANDS = {
    "urdf": lambda slot: ["validate", slot],
    "mesh": lambda slot: ["convert", slot, "-o", Out(".xml", True)],
    "arm_file": lambda slot: ["arm", slot, "--check"],
    "arm_json": lambda slot: ["arm", slot],
    "config": lambda slot: ["train", "--preset", "cpu", "--backend", "mujoco", "--run-dir",
                            Out("", False), "--config", slot],
    "policy": lambda slot: ["eval", "--episodes", "1", slot],
    "onnx": lambda slot: ["eval", "--episodes", "1", slot, "-o", Out(".json", True)],
    "trajectory": lambda slot: ["replay", slot, "-o", Out(".png", True)],
    "run_dir": lambda slot: ["export", slot, "-o", Out(".npz", True)],
}  # fmt: skip


def _new_kind_cases() -> list[Case]:
    """A few cases of each new kind: special files of every input kind (a FIFO among them),
    hostile meshes, damaged run directories, ONNX work bombs, odd output paths."""
    found = []
    for i, (kind, make) in enumerate(SPECIAL_COMMANDS.items()):
        how = ("fifo", "zero_link", "socket")[i % 3]
        seed = _special_seed(how) if kind not in ("mesh", "run_dir") else i
        found.append(Case(f"special {kind}", make(In(kind, "special", seed))))
    for mutation in hostile_mesh.MESH_MUTATIONS[::2]:  # side files, zae, obj, long paths
        slot = In("mesh", "hostile", _hostile_seed("mesh", mutation))
        found.append(Case("mesh", ["convert", slot, "-o", Out(".xml", False)]))
    for edit in (hostile_run.config_strings, hostile_run.metrics_long, hostile_run.read_only_old):
        slot = In("run_dir", "hostile", _run_file_seed(edit))
        found.append(Case("run files", ["export", slot, "-o", Out(".npz", True)]))
        found.append(Case("run files", ["train", "--resume", slot]))
    for bomb in hostile_onnx.WORK_BOMBS:
        slot = In("onnx", "hostile", _hostile_seed("onnx", bomb))
        found.append(Case("onnx", ["eval", "--episodes", "1", slot]))
    found.append(
        Case("out", ["export", In("run_dir", "good", 0), "-o", Out(".npz", False, "deep")])
    )
    return found


def test_new_kinds_of_input_in_capped_workers(pool: Pool, cases_dir: Path) -> None:
    drawn = _new_kind_cases()
    outcomes = list(pool.run((case, cases_dir / f"new{next(_COUNTER)}") for case in drawn))
    _assert_clean(outcomes)
    labels = " ".join(label for o in outcomes for label in o.inputs)
    for what in ("=fifo", "=socket", "zae_bomb", "side_special", "old_step", "identity_flood"):
        assert what in labels, (what, labels)
    assert all(o.seconds < 10 for o in outcomes), max(o.seconds for o in outcomes)


@pytest.mark.slow
def test_a_quick_parity_run_writes_into_runs_not_results(corpus: Corpus, cases_dir: Path) -> None:
    case = Case("bench parity", list(QUICK_PARITY), real=True)
    folder = cases_dir / f"parity{next(_COUNTER)}"
    outcome = run_case(case, corpus, folder)  # the working folder: its runs/ gets the run
    assert outcome.status == "ok", _explain(outcome)
    assert list((folder / "runs" / "bench").glob("parity-*/parity.json"))


@pytest.mark.parametrize("fmt", hostile_mesh.FORMATS)
def test_good_meshes_of_every_format_convert(fmt: str, corpus: Corpus, cases_dir: Path) -> None:
    seed = _seed_where(lambda rng: pick(rng, hostile_mesh.FORMATS) == fmt)
    case = Case("convert", ["convert", In("mesh", "good", seed), "-o", Out(".xml", False)])
    outcome = _run(case, corpus, cases_dir)
    assert outcome.status == "ok" and outcome.inputs == ["mesh good"], _explain(outcome)


def test_special_files_are_what_they_say(corpus: Corpus, tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    checks = {
        "fifo": lambda p: stat.S_ISFIFO(os.lstat(p).st_mode),
        "zero_link": lambda p: os.readlink(p) == "/dev/zero",
        "urandom_link": lambda p: os.readlink(p) == "/dev/urandom",
        "device_path": lambda p: os.readlink(p) in special.DEVICES,
        "socket": lambda p: stat.S_ISSOCK(os.lstat(p).st_mode),
        "folder": lambda p: p.is_dir() and not p.is_symlink(),
        "outside_link": lambda p: os.readlink(p) in (*special.OUTSIDE, str(corpus.policy)),
        "dangling_link": lambda p: p.is_symlink() and not p.exists(),
    }
    for how in special.SPECIALS:
        path = tmp_path / f"x_{how}.npz"
        special.make_special(path, how, rng, outside=corpus.policy)
        if how == "link_loop":
            with pytest.raises(OSError, match="many levels of symbolic links"):
                path.stat()
        else:
            assert checks[how](path), how
    run = tmp_path / "run"
    path, what = special.special_run_dir(corpus.run_dir, run, np.random.default_rng(3))
    _, _, how = what.partition("=")
    assert path == run and how in special.SPECIALS, what


def test_zae_archives_are_made_hostile(corpus: Corpus, tmp_path: Path) -> None:
    seen = set()
    ops = hostile_mesh.ZAE_OPS
    seeds = [_seed_where(lambda r, op=op: pick(r, ops) == op and (op != "many" or pick(
        r, (255, 256, 257, 5000, 65_535)) == 257)) for op in ops]  # fmt: skip
    for seed in seeds:
        out = tmp_path / f"z{seed}.urdf"
        what = hostile_mesh.zae_bomb(corpus.mesh, out, np.random.default_rng(seed))
        op = what.split(":")[0].split()[1]
        seen.add(op)
        with zipfile.ZipFile(hostile_mesh.meshes_of(out) / "part.zae") as archive:
            infos = archive.infolist()
        dae = [i for i in infos if i.filename.endswith(".dae")]
        if op == "bomb":
            assert dae[0].file_size > hostile_npz.BOMB_BYTES and dae[0].compress_size < 4 * 2**20
        elif op == "declares_big":
            assert dae[0].file_size == 3 * 2**30 and dae[0].compress_size < 10_000
        elif op == "declares_small":
            assert dae[0].file_size < 10_000 and dae[0].compress_size > 10_000
        elif op == "many":
            assert len(infos) > hostile_mesh_limits.MAX_ZAE_MEMBERS - 2
        else:
            assert ".." in dae[0].filename or dae[0].filename.startswith("/"), dae[0].filename
    assert seen == set(hostile_mesh.ZAE_OPS)


def test_objs_textures_and_mesh_paths_are_made_hostile(corpus: Corpus, tmp_path: Path) -> None:
    for op in ("cr", "index", "mtllib"):
        seed = _seed_where(lambda r, op=op: pick(r, ("cr", "index", "index", "mtllib")) == op)
        out = tmp_path / f"o{op}.urdf"
        what = hostile_mesh.obj_damage(corpus.mesh, out, np.random.default_rng(seed))
        data = (hostile_mesh.meshes_of(out) / "part.obj").read_bytes()
        if op == "cr":
            assert b"\n" not in data and data.count(b"\r") > 8, what
        elif op == "index":
            assert data.rstrip().endswith(what.split()[-1].encode()), what
        else:
            assert b"mtllib ../../../dev/zero" in data, what
    for op in ("file", "package", "long", "long_dirs"):
        seed = _seed_where(lambda r, op=op: pick(r, ("file", "package", "long", "long_dirs")) == op)
        out = tmp_path / f"l{op}.urdf"
        what = hostile_mesh.long_mesh_path(corpus.mesh, out, np.random.default_rng(seed))
        (name,) = re.findall(r'<mesh filename="([^"]*)"', out.read_text())
        assert len(name) >= 3990 or name.startswith(("file:", "package:")), what
    hostile_mesh.texture_bomb(corpus.mesh, tmp_path / "t.urdf", np.random.default_rng(0))
    png = (hostile_mesh.meshes_of(tmp_path / "t.urdf") / "tex.png").read_bytes()
    width, height = struct.unpack(">II", png[16:24])
    assert width * height > 4096 * 4096 and len(png) < 100_000


def test_run_directory_files_are_damaged(corpus: Corpus, tmp_path: Path) -> None:
    checks = {
        hostile_run.config_strings: lambda run: any(
            isinstance(table.get(k), str) for t, k in hostile_run.NUMBER_KEYS
            for table in [json.loads((run / "config.json").read_text())[t]]),
        hostile_run.config_bytes: lambda run: _not_utf8(run / "config.json"),
        hostile_run.metrics_long: lambda run: len((run / "metrics.csv").read_text()) > 200_000,
        hostile_run.metrics_bytes: lambda run: _not_utf8(run / "metrics.csv"),
        hostile_run.metrics_no_step: lambda run: "step," not in (run / "metrics.csv").read_text(),
        hostile_run.metrics_folder: lambda run: (run / "metrics.csv").is_dir(),
        hostile_run.bad_step_names: lambda run: any(
            p.name in hostile_run.BAD_STEPS for p in (run / "checkpoints").iterdir()),
        hostile_run.read_only_old: lambda run: any(
            p.name.startswith(".old-step_") for p in (run / "checkpoints").iterdir()),
    }  # fmt: skip
    for i, (edit, check) in enumerate(checks.items()):
        run = tmp_path / f"run{i}"
        shutil.copytree(corpus.run_dir, run)
        what = edit(run, np.random.default_rng(i))
        assert check(run), what
    for folder in (tmp_path / "run7", tmp_path / "run7" / "checkpoints"):
        os.chmod(folder, 0o755)  # read_only_old, for the clean-up


def _not_utf8(path: Path) -> bool:
    try:
        path.read_bytes().decode("utf-8")
    except UnicodeDecodeError:
        return True
    return False


def test_onnx_work_bombs_are_what_they_say(corpus: Corpus, tmp_path: Path) -> None:
    import onnx

    out = tmp_path / "m.onnx"
    what = hostile_onnx.matmul_flood(corpus.onnx, out, np.random.default_rng(3))
    count, size = (int(w) for w in re.findall(r"(\d+) MatMul by a (\d+)", what)[0])
    model = onnx.load(str(out))
    assert sum(n.op_type == "MatMul" for n in model.graph.node) >= count + 1
    assert any(list(t.dims) == [size, size] for t in model.graph.initializer)
    seed = _seed_where(lambda rng: int(pick(rng, (4000, 5000, 100_000, 300_000))) == 100_000)
    hostile_onnx.identity_flood(corpus.onnx, out, np.random.default_rng(seed))
    assert out.read_bytes().count(b"Identity") == 100_000
    hostile_onnx.sparse_bomb(corpus.onnx, out, np.random.default_rng(1))
    (sparse,) = onnx.load(str(out)).graph.sparse_initializer
    assert int(np.prod(list(sparse.dims), dtype=object)) > 2**24
    hostile_onnx.local_functions(corpus.onnx, out, np.random.default_rng(0))
    assert len(onnx.load(str(out)).functions) > 1
    for seed in (0, 1):
        hostile_onnx.duplicate_outputs(corpus.onnx, out, np.random.default_rng(seed))
        graph = onnx.load(str(out)).graph
        written = [o for n in graph.node for o in n.output] + [o.name for o in graph.output]
        assert written.count("action") > 1
    kinds = set()
    for seed in range(12):
        what = hostile_onnx.hostile_metadata(corpus.onnx, out, np.random.default_rng(seed))
        kinds.add(what.split()[1])
    assert kinds == {"task", "ctrl_dt", "obs_layout"}


def test_the_judge_sees_files_changed_outside_the_outputs(
    corpus: Corpus, cases_dir: Path, tmp_path: Path, monkeypatch
) -> None:
    """A command that writes beside its output (the user's file), into benchmarks/results or
    into its input is ``outside``; the same command writing its named output is ``ok``, and so
    is it while another process writes into benchmarks/results (reported apart)."""
    import mjx_arm.policy.export as export

    case = Case("export", ["export", In("run_dir", "good", 0), "-o", Out(".npz", False)])
    results = tmp_path / "results"
    (results / "topic").mkdir(parents=True)
    (results / "topic" / "kept.json").write_text("{}")
    monkeypatch.setattr(sentinel, "REPO_RESULTS", results)
    real = export.export_run
    targets = {
        "user": lambda out: out.parent / sentinel.USER_FILE,
        "results": lambda out: results / "topic" / "new.json",
        "input": lambda out: out.parent / "in1_run_dir" / "metrics.csv",
    }
    for name, target in targets.items():

        def also_write(run_dir, output, step=None, target=target):
            target(Path(output)).write_text("changed")
            return real(run_dir, output, step)

        monkeypatch.setattr(export, "export_run", also_write)
        outcome = _run(case, corpus, cases_dir)
        assert outcome.status == "outside", (name, _explain(outcome))
    monkeypatch.setattr(export, "export_run", real)
    assert _run(case, corpus, cases_dir).status == "ok"

    def another_process_writes(run_dir, output, step=None):
        code = f"open({str(results / 'topic' / 'theirs.json')!r}, 'w').write('{{}}')"
        subprocess.run([sys.executable, "-c", code], check=True)
        return real(run_dir, output, step)

    monkeypatch.setattr(export, "export_run", another_process_writes)
    outcome = _run(case, corpus, cases_dir)
    assert outcome.status == "ok" and "theirs.json" in outcome.external, _explain(outcome)


def test_sentinels_allow_a_moved_back_checkpoint_and_the_lock(tmp_path: Path) -> None:
    run = tmp_path / "run" / "checkpoints" / ".old-step_1"
    run.mkdir(parents=True)
    (run / "meta.json").write_text("{}")
    before = sentinel.record([tmp_path])
    run.rename(run.with_name("step_1"))
    (tmp_path / "run" / ".lock").write_text("123")
    assert sentinel.changes(before, sentinel.record([tmp_path])) == []
    (run.with_name("step_1") / "meta.json").write_text('{"x": 1}')
    (tmp_path / "run" / "new").mkdir()
    changed = sentinel.changes(before, sentinel.record([tmp_path]))
    assert len(changed) == 2 and changed[0].startswith("changed") and "added" in changed[1]


def test_the_pool_counts_a_peak_over_1_5_gb_and_drops_roots_permissions(
    corpus: Corpus, tmp_path: Path
) -> None:
    locked = tmp_path / "locked"
    locked.mkdir()
    os.chmod(locked, 0o555)
    jobs = [
        (Case("touch", [str(int(1.5e9))]), tmp_path),
        (Case("write", [str(locked)]), tmp_path),
    ]
    with Pool(corpus, workers=1, runner=probe) as workers:
        found = {o.command: o for o in workers.run(jobs)}
    os.chmod(locked, 0o755)
    assert found["touch"].status == "rss" and found["touch"].peak_rss_mb > RSS_LIMIT_MB
    assert found["write"].status == "ok" and found["write"].detail == "refused"


def test_export_keeps_its_error_reports_out_of_the_run_it_reads(corpus: Corpus) -> None:
    """Found by the fuzz: export's run directory was taken for the folder it writes into, so a
    long error line's report was written into the user's run."""
    from mjx_arm.cli import build_parser, report_folders

    args = build_parser().parse_args(["export", str(corpus.run_dir), "-o", "policy.npz"])
    assert corpus.run_dir not in report_folders(args)
