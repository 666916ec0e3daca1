"""Generated command lines against ``mjx-arm``, run in worker processes under a memory cap:
every subcommand, its arguments, and every kind of input file good, mutated, hostile or special.

Hypothesis generates the cases (:mod:`input_fuzz.cases`) from good inputs built without
training (:mod:`input_fuzz.corpus`): each file argument is the good file, a generic mutation
(:mod:`input_fuzz.mutate`: truncated, flipped bytes, deleted keys, values of the wrong type), a
structure-aware hostile one (:mod:`input_fuzz.hostile`: ``.npz`` members declaring 2^40
elements, zip bombs of 3 GiB, pickles, wrong dtypes, 3e38/NaN weights; ONNX graphs with a double
input, the wrong rank, a 2^36-element allocation at run time, NaN outputs, thousands of MatMul
nodes on a big weight, 300,000 Identity nodes, sparse initializers of 2^40 elements, model-local
functions, duplicate outputs, metadata with an unknown task, a string ctrl_dt or unknown
observation keys; damaged ``resume.npz``/``env_state.npz``/orbax folders, config.json with
strings for numbers, metrics.csv with a 200,000-character field, bytes that are not UTF-8, no
step column or a folder in its place, ``step_abc`` folders, a read-only run left with
``.old-step_N`` (:mod:`input_fuzz.hostile_run`); configs and arm files with wrong types, huge
numbers, deep nesting; URDFs with names of 255 to 100,000 characters, non-ASCII names, chains
of 500+ joints, huge mesh references; URDFs with OBJ, STL, Collada, glTF or ``.zae`` meshes
whose side files are special or lead out of the folder, ``.zae`` bombs, members and traversal
names, CR-only OBJs, face indices of 99999999, 4,000-character and ``file://`` mesh paths,
texture headers of 10^10 pixels (:mod:`input_fuzz.hostile_mesh`)), a special file in its place
or in a run directory's (a FIFO, ``/dev/zero``, ``/dev/urandom``, a socket, a folder, a link out
of the folder, dangling or in a loop: :mod:`input_fuzz.special`), a missing path or another
kind's file. Output paths are named beside the inputs, by 250-byte names, deep under an absent
folder of ``/``, or as a user's folder of their own config.json and metrics.csv. Some ``bench
parity`` cases (25 of 8,000) are whole quick parity runs without ``--out``. Each case runs through
``mjx_arm.cli.main`` in a worker (:mod:`input_fuzz.pool`) whose address space is capped and
that runs without root's permission override.

A case passes when it exits 0, or 2 with an ``error:`` line of at most 300 characters, or
reaches the command's long work (stopped there); it fails on a traceback, exit 2 without an
error line, an error line over 300 characters (``long``), running out of memory under the cap
(``memory``), the worker dying (``crash``), more than 30 s, a good output spoiled, a file
changed, removed or added outside its named outputs (its inputs, a user's file beside its
outputs, ``benchmarks/results/``: ``outside``), or a peak RSS over 1.5 GB (``rss``).

Run from the repository root: ``python benchmarks/bench_input_fuzz.py --cases 8000``.
Results: ``benchmarks/results/fuzz/input_fuzz.{json,md}``.
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

NAME = "input_fuzz"
STATUS_HEADERS = {
    "ok": "exit 0",
    "named": "named errors",
    "work": "work reached",
    "traceback": "tracebacks",
    "unnamed": "unnamed",
    "hang": "hangs > 30 s",
    "lost": "outputs lost",
    "outside": "files changed outside the outputs",
    "long": "error lines > 300",
    "memory": "out of memory",
    "crash": "worker crashed",
    "rss": "peak RSS > 1.5 GB",
}
MAX_EXAMPLES = 20


def generate(count: int, seed: int) -> list:
    """``count`` cases drawn by Hypothesis (seeded: the same list each run)."""
    from hypothesis import HealthCheck, Phase, given, settings
    from hypothesis import seed as hypothesis_seed

    from input_fuzz.cases import cases

    drawn: list = []

    @hypothesis_seed(seed)
    @settings(
        max_examples=count,
        phases=[Phase.generate],
        database=None,
        deadline=None,
        suppress_health_check=list(HealthCheck),
    )
    @given(case=cases())
    def draw(case) -> None:
        drawn.append(case)

    draw()
    return drawn


def run(args, folder: Path, log) -> tuple[list, dict]:
    """Run the generated cases in the pool; the outcomes and the pool's figures."""
    from input_fuzz.corpus import build
    from input_fuzz.harness import GOOD
    from input_fuzz.pool import Pool

    drawn = generate(args.cases, args.seed)
    corpus = build(folder / "corpus")
    outcomes = []
    stop = time.perf_counter() + (args.budget or float("inf"))
    jobs = (
        (case, folder / f"case{i}")
        for i, case in enumerate(drawn)
        if time.perf_counter() < stop  # past the budget: the rest is not run (and reported)
    )
    with Pool(corpus, args.workers) as pool:
        for outcome in pool.run(jobs):
            outcomes.append(outcome)
            if outcome.status not in GOOD:
                log(f"{outcome.status}: mjx-arm {' '.join(outcome.argv)}\n{outcome.detail[-600:]}")
            if len(outcomes) % 250 == 0:
                log(f"{len(outcomes)} cases")
    figures = {"workers": args.workers, "worker_restarts": pool.restarts}
    return outcomes, {**figures, "cap_bytes": pool.cap, "cap_limit": pool.limit}


def file_kinds(outcome) -> list[str]:
    """Rows of the per-file-kind table a case counts in: each input's kind and mode."""
    return [" ".join(label.split()[:2]) for label in outcome.inputs]


def hostile_kinds(outcome) -> list[str]:
    """Rows of the per-mutation table: each hostile input's kind and mutation, and each
    special input's kind and what is special (``special part=how``)."""
    parts = [label.split() for label in outcome.inputs]
    rows = [" ".join([p[0], *p[2:]]) for p in parts if len(p) > 2 and p[1] == "hostile"]
    return rows + [" ".join(p) for p in parts if len(p) > 2 and p[1] == "special"]


def output_kinds(outcome) -> list[str]:
    """Rows of the per-output table: how each output path of the case was named."""
    return [f"output {name}" for name in outcome.outputs] or ["no output path"]


def table(rows: dict, outcomes: list, key, first: str) -> str:
    """A markdown table of ``rows`` (:func:`input_fuzz.harness.tally`) with the median and max
    peak RSS of the outcomes each row counts."""
    rss: dict[str, list[float]] = {}
    for o in outcomes:
        for name in [*dict.fromkeys(key(o)), "all"]:
            rss.setdefault(name, []).append(o.peak_rss_mb)
    headers = (first, "cases", *STATUS_HEADERS.values(), "longest error", "max s", "RSS MB med/max")
    lines = []
    for name, row in rows.items():
        cells = [str(int(row[c])) for c in ("cases", *STATUS_HEADERS)]
        memory = f"{statistics.median(rss[name]):.0f}/{row['max_rss_mb']:.0f}"
        label = f"**{name}**" if name == "all" else name
        lines.append([label, *cells, str(row["longest_error"]), f"{row['max_s']:.2f}", memory])
    return markdown_table(headers, lines)


def longest_errors(outcomes: list) -> dict[str, dict]:
    """Per command: the longest ``error:`` line (its length, the first 400 characters)."""
    found: dict[str, dict] = {}
    for o in outcomes:
        best = found.get(o.command, {"chars": -1})
        if o.error_chars > best["chars"]:
            found[o.command] = {"chars": o.error_chars, "line": o.error_line, "argv": o.argv}
    return dict(sorted(found.items()))


def failures(outcomes: list) -> list[dict]:
    """At most :data:`MAX_EXAMPLES` failing cases, spread over the statuses."""
    from input_fuzz.harness import GOOD

    bad = [o for o in outcomes if o.status not in GOOD]
    picked, seen = [], {}
    for o in bad:
        if seen.get(o.status, 0) < MAX_EXAMPLES // 4 and len(picked) < MAX_EXAMPLES:
            seen[o.status] = seen.get(o.status, 0) + 1
            picked.append({
                "status": o.status,
                "argv": o.argv,
                "inputs": o.inputs,
                "detail": o.detail[-500:],
            })  # fmt: skip
    return picked


def slowest(outcomes: list, count: int = 10) -> list[dict]:
    """The ``count`` slowest cases: seconds, status, argv and inputs."""
    ranked = sorted(outcomes, key=lambda o: -o.seconds)[:count]
    return [{"seconds": round(o.seconds, 2), "status": o.status, "argv": [a[-200:] for a in o.argv],
             "inputs": o.inputs} for o in ranked]  # fmt: skip


def passing_address_space(outcomes: list) -> float:
    """The largest peak address space (MB) of a worker after a passing case: what a normal
    case needs under the cap (a case the cap stopped reaches the cap itself)."""
    from input_fuzz.harness import GOOD

    return max((o.peak_vm_mb for o in outcomes if o.status in GOOD), default=0.0)


def external_changes(outcomes: list) -> list[dict]:
    """Cases during which another process changed benchmarks/results (not counted)."""
    return [{"argv": o.argv, "changes": o.external} for o in outcomes if o.external]


def summary_text(total: dict, wall: float, figures: dict, outcomes: list) -> str:
    rss = [o.peak_rss_mb for o in outcomes]
    vm = passing_address_space(outcomes)
    counts = ", ".join(f"{int(total[s])} {STATUS_HEADERS[s]}" for s in STATUS_HEADERS)
    external = len(external_changes(outcomes))
    return (
        f"{int(total['cases'])} cases in {wall:.0f} s on {figures['workers']} workers "
        f"({figures['worker_restarts']} restarted): {counts}. Each worker's "
        f"{figures['cap_limit']} capped at {figures['cap_bytes'] / 2**30:.0f} GiB (the largest "
        f"address space a passing case left, imports included: {vm / 1024:.2f} GiB); peak RSS "
        f"per case (the worker's, imports included) median {statistics.median(rss):.0f} MB, max "
        f"{max(rss):.0f} MB; longest error line {int(total['longest_error'])} characters. "
        f"{external} cases ran while another process wrote benchmarks/results (the case's "
        "process wrote nothing there: not counted)."
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=8000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--budget", type=float, default=None, help="seconds; stop then")
    parser.add_argument("--name", default=NAME)
    parser.add_argument("--results-dir", type=Path, default=RESULTS_DIR / "fuzz")
    args = parser.parse_args()

    from input_fuzz.harness import RSS_LIMIT_MB, tally

    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="input_fuzz_") as folder:
        outcomes, figures = run(args, Path(folder), lambda t: print(t, flush=True))
    wall = time.perf_counter() - start
    by_command, by_kind = tally(outcomes), tally(outcomes, file_kinds)
    by_hostile = tally(outcomes, hostile_kinds)
    by_output = tally(outcomes, output_kinds)
    summary = summary_text(by_command["all"], wall, figures, outcomes)
    text = "\n\n".join([
        "## Per command\n\n" + table(by_command, outcomes, lambda o: [o.command], "command"),
        "## Per input file (kind, how made)\n\n" + table(by_kind, outcomes, file_kinds, "input"),
        "## Per hostile mutation and special file\n\n"
        + table(by_hostile, outcomes, hostile_kinds, "mutation"),
        "## Per output path (how named)\n\n" + table(by_output, outcomes, output_kinds, "output"),
        summary,
    ])  # fmt: skip
    print(text)
    payload = {
        "meta": environment_metadata(),
        "cases": len(outcomes),
        "cases_asked": args.cases,
        "seed": args.seed,
        "wall_seconds": wall,
        **figures,
        "summary": summary,
        "peak_rss_mb": {
            "median": statistics.median(o.peak_rss_mb for o in outcomes),
            "max": max(o.peak_rss_mb for o in outcomes),
        },
        "peak_address_space_mb": {
            "passing_cases": passing_address_space(outcomes),
            "all_cases": max(o.peak_vm_mb for o in outcomes),
        },
        "by_command": by_command,
        "by_input": by_kind,
        "by_hostile_mutation": by_hostile,
        "by_output": by_output,
        "rss_limit_mb": RSS_LIMIT_MB,
        "longest_error_line": longest_errors(outcomes),
        "failures": failures(outcomes),
        "slowest": slowest(outcomes),
        "external_changes": external_changes(outcomes),
    }
    save_results(args.name, payload, text + "\n", args.results_dir)


if __name__ == "__main__":
    main()
