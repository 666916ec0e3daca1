"""``eval_from_step`` and ``eval_gate``: no evaluation of the initial policy, nor of the epochs
before that step or whose training episodes succeeded under the gate's rate.

The tiny run of ``tiny_run`` (three epochs of Reach on the C MuJoCo batch) with its evaluations
from the second epoch on, beside the same run evaluated at every epoch: the training is the same
to the bit (evaluations draw from their own key and change no state), the skipped epoch logs its
training figures alone, a run stopped after that epoch resumes into the run it continues, and
the evaluation, first needed epochs later, compiles on a thread of its own meanwhile.
"""

from __future__ import annotations

import json
import math
import shutil
import sys
from pathlib import Path

import pytest
from tiny_run import EPOCH_STEPS, EPOCHS, SETTINGS

from mjx_arm.bench.seeds import read_curve
from mjx_arm.train.evaluation import Evaluator, run_aside
from mjx_arm.train.loop import evaluates_at
from mjx_arm.train.ppo import train
from mjx_arm.train.presets import load_config
from mjx_arm.train.rundir import RunDir

SETS = [f"{k}={v}" for k, v in SETTINGS.items()]
EVERY_EPOCH = load_config("cpu", None, SETS)
FROM_SECOND = load_config("cpu", None, [*SETS, f"eval_from_step={2 * EPOCH_STEPS}"])
GATED = load_config("cpu", None, [*SETS, "eval_gate=1"])  # no epoch of it passes the gate
SUCCESS = "eval/episode_success"


def _rows(run_dir: Path) -> list[dict[str, float]]:
    return RunDir(run_dir).read_metrics()


def _training(row: dict[str, float]) -> dict[str, float]:
    """A row's training figures without timings."""
    timings = ("walltime", "sps", "_s")
    return {k: v for k, v in row.items() if k.startswith("training/") and not k.endswith(timings)}


def _same(a: dict[str, float], b: dict[str, float]) -> bool:
    """Equal rows, NaN (an empty cell) equal to NaN."""
    return a.keys() == b.keys() and all(
        a[k] == b[k] or (math.isnan(a[k]) and math.isnan(b[k])) for k in a
    )


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The run evaluated at every epoch, and from the second epoch on."""
    folder = tmp_path_factory.mktemp("eval_from_step")
    train(EVERY_EPOCH, folder / "every", quiet=True)
    train(FROM_SECOND, folder / "from_second", quiet=True)
    train(GATED, folder / "gated", quiet=True)
    return {name: folder / name for name in ("every", "from_second", "gated")}


def test_the_epochs_before_eval_from_step_log_training_figures_only(runs) -> None:
    rows = _rows(runs["from_second"])
    assert [int(r["step"]) for r in rows] == [i * EPOCH_STEPS for i in range(1, EPOCHS + 1)]
    assert math.isnan(rows[0].get(SUCCESS, math.nan)) and _training(rows[0])
    assert all(math.isfinite(r[SUCCESS]) for r in rows[1:])
    # the seeds benchmark reads the evaluations alone
    steps = [step for _, step, _ in read_curve(runs["from_second"], 0.0)]
    assert steps == [i * EPOCH_STEPS for i in range(2, EPOCHS + 1)]


@pytest.mark.parametrize("skipped", ["from_second", "gated"])
def test_skipping_evaluations_leaves_the_training_as_it_was(runs, skipped: str) -> None:
    """Every epoch's losses, KL and gradient norm equal those of the run evaluated throughout,
    exactly: evaluations read the params and their own key, nothing else."""
    every = {int(r["step"]): _training(r) for r in _rows(runs["every"])[1:]}
    figures_of = {int(r["step"]): _training(r) for r in _rows(runs[skipped])}
    assert every.keys() == figures_of.keys()
    for step, figures in figures_of.items():
        assert figures and _same(figures, every[step]), step


def test_epochs_under_the_gate_log_training_figures_only(runs) -> None:
    """With ``eval_gate=1``: the initial policy is not evaluated, an epoch is where every
    training episode that ended in it succeeded, and the last epoch always is (in this tiny run
    few episodes end: those of a success, before the 150-step limit)."""
    rows = _rows(runs["gated"])
    assert [int(r["step"]) for r in rows] == [i * EPOCH_STEPS for i in range(1, EPOCHS + 1)]
    evaluated = [math.isfinite(r.get(SUCCESS, math.nan)) for r in rows]
    rates = [float(r["training/episode_success"]) for r in rows]
    assert evaluated == [rate >= 1 for rate in rates[:-1]] + [True]
    assert not all(evaluated), rates


def test_the_gate_reads_the_epochs_training_success() -> None:
    config = load_config("cpu", None, [*SETS, "eval_gate=0.3"])
    rate = "training/episode_success"
    assert not evaluates_at(config, EPOCH_STEPS, {rate: 0.29})
    assert evaluates_at(config, EPOCH_STEPS, {rate: 0.3})
    assert evaluates_at(config, EPOCHS * EPOCH_STEPS, {rate: 0.0})  # the last epoch
    both = load_config("cpu", None, [*SETS, "eval_gate=0.3", f"eval_from_step={2 * EPOCH_STEPS}"])
    assert not evaluates_at(both, EPOCH_STEPS, {rate: 0.9})
    assert evaluates_at(both, 2 * EPOCH_STEPS, {rate: 0.9})


def test_a_run_stopped_before_eval_from_step_resumes_into_the_same_run(runs, tmp_path) -> None:
    run_dir = tmp_path / "stopped"
    result = train(FROM_SECOND, run_dir, quiet=True, stop_after=1)
    assert result.steps == EPOCH_STEPS and math.isnan(result.metrics.get(SUCCESS, math.nan))
    resumed = tmp_path / "resumed"
    shutil.copytree(run_dir, resumed)
    assert train(FROM_SECOND, resumed, resume=True, quiet=True).steps == EPOCHS * EPOCH_STEPS
    timings = ("time", "walltime", "sps", "_s")
    whole, got = _rows(runs["from_second"]), _rows(resumed)
    assert len(got) == len(whole)
    for a, b in zip(got, whole, strict=True):
        keep = [k for k in a if not k.endswith(timings)]
        assert _same({k: a[k] for k in keep}, {k: b[k] for k in keep})


def test_the_last_epoch_is_always_evaluated() -> None:
    config = load_config("cpu", None, [*SETS, "eval_from_step=10000000"])
    assert not evaluates_at(config, EPOCH_STEPS, {})
    assert evaluates_at(config, EPOCHS * EPOCH_STEPS, {})
    assert evaluates_at(EVERY_EPOCH, EPOCH_STEPS, {})


def _stages(run_dir: Path) -> dict[str, float]:
    return json.loads((run_dir / "compile.json").read_text())[-1]["stages"]


def test_an_evaluation_epochs_away_compiles_aside_while_they_train(runs) -> None:
    """From the second epoch on: the evaluation compiles on its own thread (timed apart from
    the start-up's compile) and the first evaluation waits for it where it is not done yet;
    evaluated from the start, it compiles with the training's programs."""
    aside, every = _stages(runs["from_second"]), _stages(runs["every"])
    assert aside["evaluation compiled aside"] > 0.0
    assert aside["waited for the evaluation's compile"] >= 0.0
    assert "evaluation compiled aside" not in every and "first evaluation run" in every
    assert sys.getswitchinterval() == pytest.approx(0.005)  # Python's default, given back


def test_the_evaluation_compiled_aside_evaluates_as_one_compiled_before(
    runs, tmp_path, monkeypatch
) -> None:
    """The same run with its evaluation compiled on the main thread, up front: every metric
    of every row but the timings is equal."""

    def up_front(self: Evaluator, params, report) -> None:
        self.use(self.lower(params).compile())

    monkeypatch.setattr(Evaluator, "compile_aside", up_front)
    train(FROM_SECOND, tmp_path / "up_front", quiet=True)
    assert "evaluation compiled aside" not in _stages(tmp_path / "up_front")
    timings = ("time", "walltime", "sps", "_s")
    for a, b in zip(_rows(tmp_path / "up_front"), _rows(runs["from_second"]), strict=True):
        keep = [k for k in a if not k.endswith(timings)]
        assert _same({k: a[k] for k in keep}, {k: b[k] for k in keep})


def test_an_error_of_a_compile_aside_is_raised_where_it_is_waited_for() -> None:
    future = run_aside(lambda: 1 / 0, "failing")
    with pytest.raises(ZeroDivisionError):
        future.result(timeout=30)
    assert run_aside(lambda: 7, "fine").result(timeout=30) == 7
