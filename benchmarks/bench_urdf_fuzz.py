"""Hostile and broken URDFs: what the validator and the converter do with seeded mutations.

Valid URDFs (the shipped arm, pybullet_data's Franka Panda and KUKA iiwa) are mutated
(:mod:`urdf_fuzz.mutate`: deleted and duplicated elements, NaN, negative, zero and huge
numbers, broken and outside references, cycles, wrong types, deep nesting, truncation, bad
encodings, very large files, entity expansion and external entities). Every mutant goes through
``validate`` (all engines, native loads included), ``to_mjcf``, ``mjx-arm validate`` and
``mjx-arm convert`` in a worker process (:mod:`urdf_fuzz.harness`), which survives native
crashes and hangs. A mutant counts as a crash when any of the four crashed, a hang when any took
more than 5 s, a named error when one reported named errors, else a pass; outside reads count
files opened outside the URDF's folder.

Run from the repository root: ``python benchmarks/bench_urdf_fuzz.py --mutations 2000``.
Results: ``benchmarks/results/fuzz/urdf_fuzz.{json,md}``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import RESULTS_DIR, environment_metadata, markdown_table, save_results

NAME = "urdf_fuzz"
COLUMNS = ("tried", "crash", "hang", "named_error", "pass", "outside_reads", "max_seconds")
HEADERS = ("kind", "tried", "crashes", "hangs", "named errors", "passes", "outside reads", "max s")


def table_rows(tally: dict[str, dict[str, float]]) -> list[list[str]]:
    """One row per mutation kind, then ``all``."""
    rows = []
    for kind, row in tally.items():
        cells = [str(int(row[c])) for c in COLUMNS[:-1]]
        rows.append([f"**{kind}**" if kind == "all" else kind, *cells, f"{row[COLUMNS[-1]]:.2f}"])
    return rows


def outcome_record(outcome) -> dict:
    """A JSON-ready record of one mutant (the operations' statuses and times)."""
    return {
        "index": outcome.index,
        "kind": outcome.kind,
        "base": outcome.base,
        "description": outcome.description,
        "bytes": outcome.size,
        "status": outcome.status,
        "outside": list(outcome.outside),
        "ops": {r.op: {"status": r.status, "seconds": round(r.seconds, 4)} for r in outcome.ops},
        "detail": next((r.detail for r in outcome.ops if r.status != "pass"), ""),
    }


def examples(outcomes, per_kind: int = 3) -> dict[str, list[dict]]:
    """The first ``per_kind`` mutants of each kind that got a named error: what the tools said."""
    found: dict[str, list[dict]] = {}
    for o in outcomes:
        picked = found.setdefault(o.kind, [])
        if o.status == "named_error" and len(picked) < per_kind:
            picked.append(outcome_record(o))
    return found


def op_seconds(outcomes) -> dict[str, dict[str, float]]:
    """Median and largest seconds of each operation over all mutants."""
    times: dict[str, list[float]] = {}
    for o in outcomes:
        for r in o.ops:
            times.setdefault(r.op, []).append(r.seconds)
    return {op: {"median": statistics.median(t), "max": max(t)} for op, t in times.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mutations", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--name", default=NAME)
    parser.add_argument("--results-dir", type=Path, default=RESULTS_DIR / "fuzz")
    args = parser.parse_args()

    from urdf_fuzz.harness import HANG_SECONDS, OPS, default_bases, run_fuzz, tally

    def progress(outcome) -> None:
        if outcome.status in ("crash", "hang") or outcome.outside:
            print(f"{outcome.index} {outcome.kind} {outcome.base}: {outcome.status} "
                  f"{outcome.description[:80]} {outcome.outside}", flush=True)  # fmt: skip

    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        outcomes = run_fuzz(args.mutations, args.seed, Path(folder), progress=progress)
    seconds = time.perf_counter() - start
    counts = tally(outcomes)
    table = markdown_table(HEADERS, table_rows(counts))
    print(table)
    each_ms = seconds / max(len(outcomes), 1) * 1e3
    print(f"{len(outcomes)} mutants in {seconds:.0f} s ({each_ms:.0f} ms each)")
    payload = {
        "meta": environment_metadata(),
        "mutations": args.mutations,
        "seed": args.seed,
        "bases": {name: str(path) for name, path in default_bases().items()},
        "operations": list(OPS),
        "hang_seconds": HANG_SECONDS,
        "wall_seconds": seconds,
        "by_kind": counts,
        "op_seconds": op_seconds(outcomes),
        "failures": [outcome_record(o) for o in outcomes if o.status in ("crash", "hang")],
        "outside_reads": [outcome_record(o) for o in outcomes if o.outside],
        "named_error_examples": examples(outcomes),
    }
    save_results(args.name, payload, table, args.results_dir)


if __name__ == "__main__":
    main()
