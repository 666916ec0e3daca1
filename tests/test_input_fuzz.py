"""The command line against generated inputs (:mod:`input_fuzz`): every subcommand's arguments
and mutated policy files, arm files, configs, run directories and trajectories, run in process
through ``mjx_arm.cli.main``.

A case passes when it exits 0, or 2 with one ``error:`` line, or reaches the work its command
would start (stopped there: no training, no MJX); a traceback, another exit code, a hang or a
spoiled good output fails it. :data:`FUZZ_EXAMPLES` cases take about 20 s on a 2-core CPU
(benchmarks/bench_input_fuzz.py runs 2,000 and more).
"""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest
from hypothesis import HealthCheck, Phase, given, settings

from input_fuzz.cases import CASES, Case, In, Out, cases
from input_fuzz.corpus import Corpus, build
from input_fuzz.harness import GOOD, Outcome, run_case, tally

FUZZ_EXAMPLES = 500
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


def test_generated_command_lines_exit_cleanly(corpus: Corpus, cases_dir: Path) -> None:
    outcomes: list[Outcome] = []

    @settings(
        max_examples=FUZZ_EXAMPLES,
        phases=[Phase.generate],
        derandomize=True,
        database=None,
        deadline=None,
        suppress_health_check=list(HealthCheck),
    )
    @given(case=cases())
    def check(case: Case) -> None:
        outcome = _run(case, corpus, cases_dir)
        outcomes.append(outcome)
        assert outcome.status in GOOD, _explain(outcome)

    check()
    counts = tally(outcomes)
    assert counts["all"]["cases"] == FUZZ_EXAMPLES
    assert set(counts) - {"all"} == set(CASES), "every subcommand was tried"
    for status in GOOD:  # the inputs reach every outcome: clean exits, named errors, work
        assert counts["all"][status] > 0, counts["all"]


GOOD_CASES = {
    "arm": (["arm", In("arm_file", "good", 0), "-o", Out(".toml", True)], "ok"),
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


def test_the_harness_sees_a_traceback_and_a_spoiled_output(
    corpus: Corpus, cases_dir: Path, monkeypatch
) -> None:
    """The judge itself: a bug in a command is a traceback; a failing command that overwrites
    its output is a lost output."""
    import mjx_arm.policy.export as export
    from mjx_arm.train.checkpoints import CheckpointError

    def crash(*_args, **_kwargs):
        raise RuntimeError("a bug")

    monkeypatch.setattr(export, "load_run", crash)
    case = Case("export", ["export", In("run_dir", "good", 0), "-o", Out(".npz", True)])
    assert _run(case, corpus, cases_dir).status == "traceback"

    def spoil(run_dir, output, step=None):
        Path(output).write_bytes(b"half a file")
        raise CheckpointError("damaged")

    monkeypatch.setattr(export, "export_run", spoil)
    assert _run(case, corpus, cases_dir).status == "lost"
