"""Hostile policy and trajectory files: ``.npz`` members that would unpack to gigabytes are
refused (or, unused by a policy, never unpacked) before any allocation, and a policy that
computes a non-finite action or holds non-finite weights is a named error, not a traceback.

A policy reads only its own members (metadata, normaliser, layers), each under a size limit; a
trajectory reads all its members under a total budget, so a big unused member is refused there.
"""

from __future__ import annotations

import io
import tracemalloc
import zipfile
from pathlib import Path

import numpy as np
import pytest
from numpy.lib import format as npy

from input_fuzz.corpus import Corpus, build
from mjx_arm.cli import main
from mjx_arm.inputs import InputError, OversizedInputError, read_npz_members
from mjx_arm.names import EXIT_INVALID
from mjx_arm.policy import NonFiniteActionError, PolicyFileError, load
from mjx_arm.policy.numpy_policy import read_npz, write_npz
from mjx_arm.replay import TrajectoryError, load_trajectory

pytestmark = pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
HUGE = (10**6, 10**6)  # 4 TB of float32, declared by a header of a few bytes


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Corpus:
    return build(tmp_path_factory.mktemp("hostile_corpus"))


def _header(shape: tuple[int, ...], descr: str = "<f4") -> bytes:
    buffer = io.BytesIO()
    npy.write_array_header_1_0(buffer, {"descr": descr, "fortran_order": False, "shape": shape})
    return buffer.getvalue()


def _with_member(source: Path, target: Path, name: str, data: bytes | None = None, zeros=0):
    """A copy of the .npz ``source`` whose member ``name`` is ``data`` (a header alone), or a
    float32 array of ``zeros`` bytes streamed through the compressor."""
    with zipfile.ZipFile(source) as old, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as z:
        for info in old.infolist():
            if info.filename != f"{name}.npy":
                z.writestr(info.filename, old.read(info))
        with z.open(f"{name}.npy", "w", force_zip64=True) as member:
            member.write(data if data is not None else _header((zeros // 4,)))
            chunk = bytes(2**20)
            for _ in range(zeros // len(chunk)):
                member.write(chunk)
    return target


def _fails(argv: list[str], capsys) -> str:
    code = main(argv)
    err = capsys.readouterr().err
    assert code == EXIT_INVALID, err
    assert "Traceback" not in err
    (line,) = [line for line in err.splitlines() if line.startswith("error:")]
    return line


def test_a_huge_declared_shape_is_refused_before_allocation(corpus: Corpus, tmp_path: Path, capsys):
    bomb = _with_member(corpus.policy, tmp_path / "bomb.npz", "kernel_0", _header(HUGE))
    assert bomb.stat().st_size < 100_000
    tracemalloc.start()
    with pytest.raises(OversizedInputError, match=r"'kernel_0.npy'.*over the limit of 256 MiB"):
        load(bomb)
    assert tracemalloc.get_traced_memory()[1] < 20 * 2**20
    tracemalloc.stop()
    assert "kernel_0.npy" in _fails(["eval", str(bomb), "--episodes", "1"], capsys)
    traj = _with_member(corpus.trajectory, tmp_path / "traj.npz", "obs", _header(HUGE))
    with pytest.raises(OversizedInputError, match=r"'obs.npy'.*1,000,000,000,000 elements, over"):
        load_trajectory(traj)


def test_a_header_larger_than_its_member_is_a_damaged_file(corpus: Corpus, tmp_path: Path):
    bomb = _with_member(corpus.policy, tmp_path / "lie.npz", "kernel_0", _header((1000, 1000)))
    with pytest.raises(PolicyFileError, match=r"declares shape \(1000, 1000\).*more than"):
        load(bomb)
    pickled = io.BytesIO()
    np.save(pickled, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    bad = _with_member(corpus.trajectory, tmp_path / "pickle.npz", "obs", pickled.getvalue())
    with pytest.raises(TrajectoryError, match="pickled Python objects, refused"):
        load_trajectory(bad)


def test_a_big_unused_member_is_never_unpacked(corpus: Corpus, tmp_path: Path):
    """Policies and trajectories skip it (300 MiB unpacked, a few hundred kB packed); a reader
    of all the members refuses it from the zip directory's sizes, before unpacking anything."""
    big = _with_member(corpus.policy, tmp_path / "big.npz", "unused", zeros=300 * 2**20)
    assert big.stat().st_size < 2 * 2**20
    tracemalloc.start()
    policy = load(big)
    assert tracemalloc.get_traced_memory()[1] < 20 * 2**20
    with pytest.raises(
        OversizedInputError, match="members it reads, together, would unpack to 300"
    ):
        read_npz_members(big, "test", max_member_bytes=2**30, max_total_bytes=2**28)
    assert tracemalloc.get_traced_memory()[1] < 20 * 2**20
    tracemalloc.stop()
    assert policy(np.zeros(policy.obs_size)).shape == (policy.action_size,)
    traj = _with_member(corpus.trajectory, tmp_path / "traj.npz", "unused", zeros=300 * 2**20)
    tracemalloc.start()
    assert "unused" not in load_trajectory(traj)
    assert tracemalloc.get_traced_memory()[1] < 20 * 2**20
    tracemalloc.stop()


def _overflowing(corpus: Corpus, tmp_path: Path) -> tuple[Path, dict, dict]:
    """A policy of finite weights, +-3e38 (the columns alternate), whose layers overflow."""
    arrays, meta = read_npz(corpus.policy)
    for key in [k for k in arrays if k.startswith("kernel")]:
        arrays[key] = np.full_like(arrays[key], 3e38)
        arrays[key][:, ::2] *= -1
    return write_npz(tmp_path / "overflow.npz", arrays, meta), arrays, meta


def test_an_overflowing_policy_is_a_named_error_in_eval(corpus: Corpus, tmp_path: Path, capsys):
    path, arrays, _ = _overflowing(corpus, tmp_path)
    line = _fails(["eval", str(path), "--episodes", "1"], capsys)
    assert "non-finite action" in line and "observation step 1" in line
    assert "damaged or its training diverged" in line
    policy = load(path)
    with pytest.raises(NonFiniteActionError, match="observation step 1"):
        policy(arrays["obs_mean"] + arrays["obs_std"], deterministic=False)
    assert isinstance(NonFiniteActionError("x"), PolicyFileError)


def test_an_onnx_policy_that_outputs_nan_is_a_named_error(corpus: Corpus, tmp_path: Path):
    if corpus.onnx is None:
        pytest.skip("onnx or onnxruntime is not installed")
    from mjx_arm.policy.onnx_export import write_onnx

    _, arrays, meta = _overflowing(corpus, tmp_path)
    policy = load(write_onnx(tmp_path / "overflow.onnx", arrays, meta))
    with pytest.raises(NonFiniteActionError, match=r"non-finite action .* observation step 1:"):
        policy(arrays["obs_mean"] + arrays["obs_std"])


def test_non_finite_weights_are_refused_at_load(corpus: Corpus, tmp_path: Path, capsys):
    arrays, meta = read_npz(corpus.policy)
    for value in (np.nan, np.inf):
        bias = arrays["bias_0"].copy()
        bias[0] = value
        path = write_npz(tmp_path / "nan.npz", {**arrays, "bias_0": bias}, meta)
        with pytest.raises(PolicyFileError, match="bias_0 holds NaN or infinite numbers"):
            load(path)
    assert "bias_0 holds NaN" in _fails(["eval", str(path), "--episodes", "1"], capsys)
    assert issubclass(OversizedInputError, InputError)


METADATA_FAULTS = {
    "an observation key the env lacks": (
        lambda m: m["obs_layout"][0].__setitem__(0, "bogus_key"),
        "reads observation keys the env does not give: 'bogus_key' (7)",
    ),
    "an unknown task": (
        lambda m: m.update(task="fly"),
        "names task 'fly', not a registered task (reach, touch",
    ),
    "a text ctrl_dt": (
        lambda m: m.update(ctrl_dt="fast"),
        "ctrl_dt must be a number of seconds > 0, not 'fast'",
    ),
    "a key named twice": (
        lambda m: m["obs_layout"][1].__setitem__(0, "ee_pose"),
        "obs_layout names a key twice",
    ),
    "another task than its training config's": (
        lambda m: m.update(task="touch"),
        "names task 'touch', its training config 'reach'",
    ),
    "another ctrl_dt than its training task's": (
        lambda m: m.update(ctrl_dt=0.05),
        "records ctrl_dt 0.05 s, its training task",
    ),
}


@pytest.mark.parametrize("suffix", [".npz", ".onnx"])
@pytest.mark.parametrize("fault", list(METADATA_FAULTS))
def test_metadata_eval_cannot_honour_is_a_named_error(corpus, tmp_path, capsys, fault, suffix):
    """Keys the env lacks were a traceback in the first step; an unknown task, a text
    ctrl_dt or metadata disagreeing with the training config ran to exit 0."""
    import copy

    if suffix == ".onnx" and corpus.onnx is None:
        pytest.skip("onnx or onnxruntime is not installed")
    arrays, meta = read_npz(corpus.policy)
    meta = copy.deepcopy(meta)
    change, message = METADATA_FAULTS[fault]
    change(meta)
    path = tmp_path / f"policy{suffix}"
    if suffix == ".onnx":
        from mjx_arm.policy.onnx_export import write_onnx

        write_onnx(path, arrays, meta)
    else:
        write_npz(path, arrays, meta)
    line = _fails(["eval", str(path), "--episodes", "1"], capsys)
    assert message in line and len(line) < 300, line


def _zeros_npz(path: Path, members: dict[str, tuple[tuple[int, ...], str]]) -> Path:
    """An .npz whose members are zero arrays of the given (shape, dtype), streamed through
    the compressor (no array of that size is ever made here)."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, (shape, descr) in members.items():
            with z.open(f"{name}.npy", "w", force_zip64=True) as member:
                member.write(_header(shape, descr))
                left = int(np.prod(shape)) * np.dtype(descr).itemsize
                chunk = bytes(2**22)
                while left > 0:
                    member.write(chunk[: min(left, len(chunk))])
                    left -= len(chunk)
    return path


def test_ten_million_steps_of_uint8_are_refused_before_unpacking(tmp_path: Path, capsys):
    """10 M steps of uint8 and bool arrays: 257 kB packed, 260 MB unpacked, which the byte
    limits let through and replay widened to 3.35 GB; the element limit refuses the first
    member from its header."""
    from mjx_arm.trajectory_files import TRAJECTORY_MEMBER_ELEMENTS

    steps = 10_000_000
    path = _zeros_npz(
        tmp_path / "long.npz",
        {
            "obs": ((steps, 22), "|u1"),
            "reward": ((steps,), "|b1"),
            "ee_pos": ((steps, 3), "|u1"),
            "contact_force": ((steps,), "|u1"),
        },
    )
    assert path.stat().st_size < 2**20
    tracemalloc.start()
    with pytest.raises(
        OversizedInputError, match=rf"over the limit of {TRAJECTORY_MEMBER_ELEMENTS:,}"
    ):
        load_trajectory(path)
    assert tracemalloc.get_traced_memory()[1] < 20 * 2**20
    tracemalloc.stop()
    line = _fails(["replay", str(path), "-o", str(tmp_path / "plot.png")], capsys)
    assert "elements, over the limit" in line and not (tmp_path / "plot.png").exists()


def test_more_steps_than_a_trajectory_holds_are_refused(tmp_path: Path):
    """250,000 steps: each array under the element limit, the steps over theirs."""
    from mjx_arm.trajectory_files import TRAJECTORY_MAX_STEPS

    steps = 250_000
    path = _zeros_npz(
        tmp_path / "steps.npz",
        {
            "obs": ((steps, 22), "<f4"),
            "reward": ((steps,), "<f4"),
            "ee_pos": ((steps, 3), "<f4"),
            "contact_force": ((steps,), "<f4"),
        },
    )
    with pytest.raises(TrajectoryError, match=rf"holds 250,000 steps, over the limit of "
                       rf"{TRAJECTORY_MAX_STEPS:,}"):  # fmt: skip
        load_trajectory(path)


def test_a_task_config_text_over_its_limit_is_refused(corpus: Corpus, tmp_path: Path):
    """A trajectory's ``task_config`` is a JSON text of a few kB; 4 MiB of it is refused
    before it is unpacked, far below the arrays' limits."""
    big = _with_member(
        corpus.trajectory, tmp_path / "text.npz", "task_config", _header((), "<U1048576")
    )
    with pytest.raises(OversizedInputError, match=r"'task_config.npy'.*over the limit of 1 MiB"):
        load_trajectory(big)


def test_a_zip_directory_of_too_many_members_is_refused_before_it_is_read(tmp_path, capsys):
    """100,000 empty members (zipfile writes a zip64 end record past 65,535): opening it
    cost about 550 bytes of memory per member (a million: 545 MB, 10 s); the end record's
    counts refuse it first, for a policy and a trajectory alike."""
    from mjx_arm.zip_directory import MAX_ENTRIES

    path = tmp_path / "many.npz"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as z:
        for i in range(100_000):
            z.writestr(f"{i}.npy", b"")
    tracemalloc.start()
    with pytest.raises(
        PolicyFileError, match=rf"lists 100,000 members .* limits of {MAX_ENTRIES:,}"
    ):
        load(path)
    assert tracemalloc.get_traced_memory()[1] < 2 * 2**20
    tracemalloc.stop()
    with pytest.raises(TrajectoryError, match="its zip directory lists 100,000 members"):
        load_trajectory(path)
    assert "zip directory lists 100,000" in _fails(["eval", str(path), "--episodes", "1"], capsys)


def test_a_policy_metadata_text_over_its_limit_is_refused(corpus: Corpus, tmp_path: Path):
    """The metadata is a JSON text parsed whole: 4 MiB of it is refused before unpacking,
    far below the weights' limit (256 MiB of "[0,0,...]" parses to gigabytes)."""
    big = _with_member(corpus.policy, tmp_path / "meta.npz", "metadata", _header((), "<U1048576"))
    with pytest.raises(OversizedInputError, match=r"'metadata.npy'.*over the limit of 1 MiB"):
        load(big)


def test_the_standalone_reader_bounds_members_by_the_zip_directory(corpus: Corpus, tmp_path):
    """numpy_policy.read_npz on its own (numpy.load, as on a robot computer): a member that
    unpacks to more than its limit is refused before numpy unpacks it."""
    big = _with_member(corpus.policy, tmp_path / "meta.npz", "metadata", zeros=2 * 2**20)
    with pytest.raises(PolicyFileError, match=r"'metadata.npy' unpacks to 2,097,2\d\d bytes"):
        read_npz(big)
    arrays, meta = read_npz(corpus.policy)  # an exported policy reads as before
    assert meta["format"] == "mjx_arm.policy" and "kernel_0" in arrays
