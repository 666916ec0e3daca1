"""Generated command lines against ``mjx-arm``: every subcommand, its numeric and named
arguments, and mutated policy files, arm files, configs, run directories and trajectories.

Hypothesis generates the cases (:mod:`input_fuzz.cases`) from good inputs built without
training (:mod:`input_fuzz.corpus`): each file argument is the good file, a mutation of it
(:mod:`input_fuzz.mutate`: truncated, flipped bytes, deleted keys, values of the wrong type or
out of range, NaN weights, shapes that do not fit, a newer contract version, a damaged
checkpoint), a missing path or another kind's file. Each case runs in process through
``mjx_arm.cli.main`` (:mod:`input_fuzz.harness`) with its outputs seeded with good files. A case
passes when it exits 0, or 2 with an ``error:`` line, or reaches the command's long work (stopped
there: training, MJX, benchmarks, long evaluations); it fails on a traceback (or another exit
code), exit code 2 without an ``error:`` line, more than 30 s, or a good output changed by a
failing command or left broken.

Run from the repository root: ``python benchmarks/bench_input_fuzz.py --cases 3000``.
Results: ``benchmarks/results/input_fuzz.{json,md}``.
"""

from __future__ import annotations

import argparse
import collections
import itertools
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import environment_metadata, markdown_table, save_results

NAME = "input_fuzz"
COLUMNS = ("cases", "ok", "named", "work", "traceback", "unnamed", "hang", "lost")
HEADERS = ("command", "cases", "exit 0", "named errors", "work reached", "tracebacks",
           "unnamed", "hangs > 30 s", "outputs lost", "median ms", "max s")  # fmt: skip


def table_rows(counts: dict, seconds: dict[str, list[float]]) -> list[list[str]]:
    """One row per command, then ``all``."""
    rows = []
    for command, row in counts.items():
        cells = [str(int(row[c])) for c in COLUMNS]
        median = 1e3 * statistics.median(seconds[command])
        name = f"**{command}**" if command == "all" else command
        rows.append([name, *cells, f"{median:.0f}", f"{row['max_s']:.2f}"])
    return rows


def run(count: int, seed: int, folder: Path, log) -> tuple[list, collections.Counter]:
    """Generate and run ``count`` cases; the outcomes and the file slots' kinds and modes."""
    from hypothesis import HealthCheck, Phase, given, settings
    from hypothesis import seed as hypothesis_seed

    from input_fuzz.cases import In, cases
    from input_fuzz.corpus import build
    from input_fuzz.harness import GOOD, run_case

    corpus = build(folder / "corpus")
    outcomes, files = [], collections.Counter()
    counter = itertools.count()

    @hypothesis_seed(seed)
    @settings(
        max_examples=count,
        phases=[Phase.generate],
        database=None,
        deadline=None,
        suppress_health_check=list(HealthCheck),
    )
    @given(case=cases())
    def one(case) -> None:
        files.update(f"{t.kind} {t.mode}" for t in case.argv if isinstance(t, In))
        outcome = run_case(case, corpus, folder / f"case{next(counter)}")
        outcomes.append(outcome)
        if outcome.status not in GOOD:
            log(f"{outcome.status}: mjx-arm {' '.join(outcome.argv)}\n{outcome.detail}")
        if len(outcomes) % 250 == 0:
            log(f"{len(outcomes)} cases")

    one()
    return outcomes, files


def examples(outcomes, per_command: int = 3) -> dict[str, list[dict]]:
    """The first named errors of each command: what the user reads."""
    found: dict[str, list[dict]] = {}
    for o in outcomes:
        picked = found.setdefault(o.command, [])
        if o.status == "named" and len(picked) < per_command:
            picked.append({"argv": o.argv, "error": o.detail})
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=3000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--name", default=NAME)
    parser.add_argument("--results-dir", type=Path, default=None)
    args = parser.parse_args()

    from input_fuzz.harness import HANG_SECONDS, tally

    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="input_fuzz_") as folder:
        outcomes, files = run(args.cases, args.seed, Path(folder), lambda t: print(t, flush=True))
    wall = time.perf_counter() - start
    counts = tally(outcomes)
    seconds = collections.defaultdict(list)
    for o in outcomes:
        seconds[o.command].append(o.seconds)
        seconds["all"].append(o.seconds)
    table = markdown_table(HEADERS, table_rows(counts, seconds))
    total = counts["all"]
    summary = (
        f"{int(total['cases'])} inputs in {wall:.0f} s: {int(total['traceback'])} tracebacks, "
        f"{int(total['hang'])} hangs over {HANG_SECONDS:.0f} s, {int(total['lost'])} good "
        f"outputs lost, {int(total['unnamed'])} exit-2 without an error line"
    )
    print(table)
    print(summary)
    payload = {
        "meta": environment_metadata(),
        "cases": args.cases,
        "seed": args.seed,
        "hang_seconds": HANG_SECONDS,
        "wall_seconds": wall,
        "summary": summary,
        "by_command": counts,
        "file_arguments": dict(sorted(files.items())),
        "failures": [vars(o) for o in outcomes if o.status not in ("ok", "named", "work")],
        "named_error_examples": examples(outcomes),
    }
    save_results(args.name, payload, f"{table.rstrip()}\n\n{summary}\n", args.results_dir)


if __name__ == "__main__":
    main()
