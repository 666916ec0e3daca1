"""The files of a case, made in its folder: each input slot filled by its mode (a good copy, a
mutation, a missing path, another kind's file, a special file), each output path named and
seeded with a good file where asked, and the sentinel files a case must leave alone
(:mod:`input_fuzz.sentinel`).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np

from input_fuzz.cases import Case, In, Out
from input_fuzz.corpus import Corpus
from input_fuzz.mutate import mutate
from input_fuzz.sentinel import USER_FILE

GOOD_OUTPUT = {".json": b'{"good": true}\n', ".txt": b"good\n", ".script": b"def good():\nend\n"}
LONG_NAME_BYTES = 250  # a file name this long must work (Linux allows 255)
DEEP_ROOT = Path("/mjx_arm_fuzz_absent")  # a folder of / that does not exist (per worker)
DEEP_PARTS = ("a", "b", "c", "d", "e")
USER_RESULTS = Path("benchmarks") / "results" / "user.json"  # in a bench case's folder


def _suffix(kind: str, good: Path) -> str:
    return "" if kind == "run_dir" else good.suffix


def _special(slot: In, good: Path, name: Path, rng: np.random.Generator) -> tuple[Path, str]:
    """A special input of the slot's kind at ``name`` (or a device path), and what it is."""
    if slot.kind == "mesh":
        from input_fuzz.hostile_mesh import special_mesh

        return special_mesh(good, name, rng)
    from input_fuzz.special import special_input

    return special_input(slot.kind, good, name, rng)


def fill_in(slot: In, corpus: Corpus, folder: Path, index: int) -> tuple[Path, str]:
    """The path of an input slot, made in ``folder``, and what it is (``kind mode[ how]``)."""
    good = corpus.run_dir if slot.kind == "run_dir" else corpus.files().get(slot.kind)
    label = f"{slot.kind} {slot.mode}"
    if good is None:  # onnx without the onnx package: another kind's good file
        good, label = corpus.policy, f"{slot.kind} other"
    name = folder / f"in{index}_{slot.kind}{_suffix(slot.kind, good)}"
    rng = np.random.default_rng(slot.seed)
    if slot.mode == "missing":
        return name.with_name("missing_" + name.name), label
    if slot.mode == "other":
        files = list(corpus.files().values())
        return files[int(rng.integers(len(files)))], label
    if slot.mode == "special":
        path, how = _special(slot, good, name, rng)
        return path, f"{label} {how}"
    if slot.mode in ("mutated", "hostile"):
        what = mutate(slot.kind, good, name, rng, hostile=slot.mode == "hostile")
        how, _, rest = what.partition(": ")
        if how.startswith("hostile_"):  # a dispatcher: its own edit names the mutation
            how = rest.partition(": ")[0]
        return name, f"{label} {how}"
    if slot.kind == "run_dir":
        shutil.copytree(good, name)
    elif slot.kind == "mesh":
        from input_fuzz.hostile_mesh import good_mesh

        good_mesh(good, name, rng)
    else:
        shutil.copy(good, name)
    return name, label


def _seed_output(slot: Out, corpus: Corpus, path: Path) -> None:
    """A good file at ``path`` before the case (what a failing command must not spoil), or a
    user's folder of their own files."""
    if slot.name == "user":
        from input_fuzz.hostile_run import user_folder

        user_folder(path)
        return
    if not slot.seeded or slot.name == "deep":
        return
    if slot.suffix == "":
        path.mkdir(parents=True, exist_ok=True)
        (path / "good.txt").write_bytes(b"good\n")
        return
    sources = {".npz": corpus.policy, ".onnx": corpus.onnx, ".toml": corpus.arm_file}
    source = sources.get(slot.suffix)
    if source is not None:
        shutil.copy(source, path)
    else:
        path.write_bytes(GOOD_OUTPUT.get(slot.suffix, b"good output\n"))


def deep_root() -> Path:
    """This process's folder of / that does not exist before a case (removed after it)."""
    return DEEP_ROOT.with_name(f"{DEEP_ROOT.name}_{os.getpid()}")


def output_path(slot: Out, folder: Path, index: int) -> Path:
    """Where an output slot points: beside the inputs, under a 250-byte name, or deep under a
    folder of / that does not exist."""
    tail = f"{index}{slot.suffix}"
    if slot.name == "long":
        return folder / ("o" * (LONG_NAME_BYTES - len(tail)) + tail)
    if slot.name == "deep":
        return deep_root().joinpath(folder.name, *DEEP_PARTS, f"out{tail}")
    return folder / f"out{tail}"


def materialise(
    case: Case, corpus: Corpus, folder: Path, inputs: list[str] | None = None
) -> tuple[list[str], dict[Path, Out]]:
    """The argv of ``case`` with its files made in ``folder``; and its output paths. Each input
    slot's ``kind mode[ how]`` is appended to ``inputs``. The folder also gets a file of the
    user's (:data:`~input_fuzz.sentinel.USER_FILE`) and, for a benchmark, a
    ``benchmarks/results/`` tree of the user's."""
    (folder / USER_FILE).write_bytes(b"the user's own file, beside the outputs\n")
    if case.command.startswith("bench"):
        (folder / USER_RESULTS).parent.mkdir(parents=True, exist_ok=True)
        (folder / USER_RESULTS).write_bytes(b'{"mine": true}\n')
    argv, outputs = [], {}
    for i, token in enumerate(case.argv):
        if isinstance(token, In):
            path, label = fill_in(token, corpus, folder, i)
            argv.append(str(path))
            if inputs is not None:
                inputs.append(label)
        elif isinstance(token, Out):
            path = output_path(token, folder, i)
            _seed_output(token, corpus, path)
            outputs[path] = token
            argv.append(str(path))
        else:
            argv.append(str(token))
    return argv, outputs


def remove_deep_outputs() -> None:
    """Remove what a case wrote under :func:`deep_root` (a command may create the folders)."""
    root = deep_root()
    if root.exists():
        shutil.rmtree(root, ignore_errors=True)
