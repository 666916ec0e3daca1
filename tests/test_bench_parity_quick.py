"""``bench parity --quick`` on a CPU (the tutorial's first look at engine agreement on an arm):
it leaves MJX out, and says so, unless --engines names it; MJX's compiles say how long they
take while they run."""

from __future__ import annotations

import io
import json
from contextlib import redirect_stderr
from pathlib import Path

import jax
import numpy as np
import pytest

from mjx_arm.cli import EXIT_OK, main

on_cpu = pytest.mark.skipif(jax.default_backend() != "cpu", reason="MJX stays in on a GPU")


@on_cpu
def test_quick_parity_on_a_cpu_leaves_mjx_out_and_says_so(tmp_path: Path, capsys) -> None:
    out = tmp_path / "parity"
    assert main(["bench", "parity", "--quick", "--arm", "ur5e", "--out", str(out)]) == EXIT_OK
    result = json.loads((out / "parity.json").read_text())
    assert result["engines"] == ["mujoco", "pybullet"]
    err = capsys.readouterr().err
    assert "note: --quick on a CPU leaves mjx out" in err
    assert "--engines mujoco mjx pybullet compares them all" in err


@on_cpu
def test_named_engines_keep_mjx_in_a_quick_run() -> None:
    from mjx_arm.bench.cli import _quick_on_cpu
    from mjx_arm.bench.parity_config import ParityConfig
    from mjx_arm.cli import build_parser

    argv = ["bench", "parity", "--quick", "--engines", "mujoco", "mjx"]
    args = build_parser().parse_args(argv)
    config = ParityConfig.quick(engines=("mujoco", "mjx"))
    assert _quick_on_cpu(config, args) is config


def test_an_mjx_parity_program_says_while_it_compiles() -> None:
    from mjx_arm.bench.engines import MjxEngine

    engine = object.__new__(MjxEngine)  # only what _call reads: its name and the total
    engine.name, engine.compile_seconds = "mjx-jax", 0.0
    stream = io.StringIO()
    with redirect_stderr(stream):
        out = engine._call("a sum", jax.jit(lambda x: x + 1.0), np.zeros(3, np.float32))
    np.testing.assert_array_equal(out, np.ones(3))
    lines = stream.getvalue().splitlines()
    assert lines[0].startswith("compiling mjx-jax's a sum")
    assert lines[-1].startswith("compiled mjx-jax's a sum in ")
    assert engine.compile_seconds > 0
