"""The command line against generated inputs (:mod:`input_fuzz`): every subcommand's arguments
and good, mutated and hostile policy files (``.npz``, ONNX), arm files, configs, run
directories, trajectories and URDFs, run through ``mjx_arm.cli.main`` in capped worker
processes (:mod:`input_fuzz.pool`).

A case passes when it exits 0, or 2 with one ``error:`` line, or reaches the work its command
would start (stopped there: no training, no MJX); a traceback, a crash of the worker, running
out of memory under the cap, another exit code, a hang or a spoiled good output fails it.
:data:`FUZZ_EXAMPLES` cases of each command take about 20 s on a 2-core CPU; the hostile
mutations are checked to really be hostile (a header that declares 2^40 elements, a graph that
allocates 2^36 floats, names of the exact lengths). benchmarks/bench_input_fuzz.py runs 6,000 cases.
"""

from __future__ import annotations

import itertools
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings

from input_fuzz import hostile, hostile_npz, hostile_onnx
from input_fuzz.cases import CASES, Case, In, Out, cases
from input_fuzz.corpus import Corpus, build
from input_fuzz.harness import MAX_ERROR_CHARS, Outcome, run_case, tally
from input_fuzz.pool import CAP_BYTES, Pool, probe

FUZZ_EXAMPLES = 2  # of each command
MUST_BE_ZERO = ("traceback", "crash", "memory", "lost", "unnamed", "hang")
_COUNTER = itertools.count()


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Corpus:
    return build(tmp_path_factory.mktemp("input_corpus"))


@pytest.fixture(scope="module")
def cases_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("input_cases")


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


def _fuzz(corpus: Corpus, folder: Path, count: int, per_command: bool = False) -> list[Outcome]:
    """``count`` generated cases (``per_command``: that many of each command) run in a pool."""
    drawn = [c for name in CASES for c in _draw(count, (name,))] if per_command else _draw(count)
    jobs = [(case, folder / f"gen{next(_COUNTER)}") for case in drawn]
    with Pool(corpus, workers=2) as pool:
        return list(pool.run(jobs))


def _assert_clean(outcomes: list[Outcome]) -> dict:
    counts = tally(outcomes)["all"]
    bad = [o for o in outcomes if o.status in MUST_BE_ZERO]
    assert not bad, "\n\n".join(_explain(o) for o in bad[:5])
    assert all(counts[s] == 0 for s in MUST_BE_ZERO), counts
    return counts


def test_generated_command_lines_in_capped_workers(corpus: Corpus, cases_dir: Path) -> None:
    outcomes = _fuzz(corpus, cases_dir, FUZZ_EXAMPLES, per_command=True)
    counts = _assert_clean(outcomes)
    assert counts["cases"] == FUZZ_EXAMPLES * len(CASES)
    assert {o.command for o in outcomes} == set(CASES), "every subcommand was tried"
    modes = {label.split()[1] for o in outcomes for label in o.inputs}
    assert {"good", "hostile", "missing"} <= modes, modes
    assert 0 < max(o.peak_rss_mb for o in outcomes) < CAP_BYTES / 2**20


@pytest.mark.slow
def test_a_thousand_generated_command_lines(corpus: Corpus, cases_dir: Path) -> None:
    _assert_clean(_fuzz(corpus, cases_dir, 1000))


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
}


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
