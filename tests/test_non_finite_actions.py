"""A policy that acts NaN or inf is one named error line (exit 2) wherever it acts from the
command line: ``eval`` and ``deploy-sim``, with an ``.npz`` and with an ``.onnx`` policy."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from input_fuzz.corpus import Corpus, build
from mjx_arm.cli import main
from mjx_arm.names import EXIT_INVALID
from mjx_arm.policy.numpy_policy import read_npz, write_npz


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Corpus:
    return build(tmp_path_factory.mktemp("non_finite_corpus"))


@pytest.fixture(scope="module")
def overflowing(corpus: Corpus, tmp_path_factory) -> dict[str, Path]:
    """Policies of finite weights, +-3e38 (the columns alternate), whose layers overflow to inf
    and then NaN: ``.npz`` always, ``.onnx`` where onnx is installed."""
    folder = tmp_path_factory.mktemp("overflowing")
    arrays, meta = read_npz(corpus.policy)
    for key in [k for k in arrays if k.startswith("kernel")]:
        arrays[key] = np.full_like(arrays[key], 3e38)
        arrays[key][:, ::2] *= -1
    paths = {"npz": write_npz(folder / "overflow.npz", arrays, meta)}
    if corpus.onnx is not None:
        from mjx_arm.policy.onnx_export import write_onnx

        paths["onnx"] = write_onnx(folder / "overflow.onnx", arrays, meta)
    return paths


@pytest.mark.parametrize("kind", ["npz", "onnx"])
@pytest.mark.parametrize("command", ["eval", "deploy-sim"])
def test_a_non_finite_action_is_one_error_line(overflowing, kind: str, command: str, capsys):
    if kind not in overflowing:
        pytest.skip("onnx or onnxruntime is not installed")
    code = main([command, str(overflowing[kind]), "--episodes", "1"])
    err = capsys.readouterr().err
    assert code == EXIT_INVALID, err
    assert "Traceback" not in err
    (line,) = [x for x in err.splitlines() if x.startswith("error:")]
    assert "non-finite action (NaN or inf) at observation step 1" in line
