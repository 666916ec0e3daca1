"""Results pages and the README's headline table, generated from ``benchmarks/results/``.

Every figure the docs and the README quote comes from a committed JSON file, through this
script; nothing is copied by hand. The docs build runs it (``docs/conf.py``), and
``tests/test_docs.py`` checks that the README's headline block is what it makes.

How it is organised, so that new result files need little or no work:

- ``result_kinds.RENDERERS``: one renderer per kind of result file, tried in order; a kind
  is told by the keys a file holds (a seeds run has ``seeds`` and ``summary``, a transfer run
  ``rows`` and ``policy``, ...). The last one, ``render_generic``, takes any file: its run
  metadata, a ``goals`` list, a ``rows`` table and a ``summary``. A file that is not a JSON
  object, or not valid JSON, is listed as skipped; it never stops the build.
- :data:`SECTIONS`: which page a file goes to, by its path under the results folder. A file
  that no section names lands on the "Other results" page, so a new folder shows up at once.
- ``headlines.HEADLINES``: the rows of the headline table (README and results index), each read
  from named files.

Usage::

    python docs/gen_results.py                # write docs/results/*.md and README's block
    python docs/gen_results.py --check        # exit 1 if README's block is out of date
    python docs/gen_results.py --results DIR --out DIR --readme FILE
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from headlines import BEGIN, END, headline_list, update_readme
from result_kinds import Json, provenance, renderer_for
from result_plots import draw
from result_titles import title, unique_titles

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
OUT = ROOT / "docs" / "results"
README = ROOT / "README.md"

__all__ = ["BEGIN", "END", "generate", "main", "update_readme"]

# ---------------------------------------------------------------------------------------------
# pages


@dataclass(frozen=True)
class Section:
    """One results page: the files (glob patterns under the results folder) it shows."""

    slug: str
    title: str
    intro: str
    patterns: tuple[str, ...]


SECTIONS: tuple[Section, ...] = (
    Section("seeds", "Training over seeds",
            "The presets as shipped, trained seed after seed by `mjx-arm bench seeds`.",
            ("seeds/*",)),
    Section("scaling", "Several GPUs",
            "Seeds one per GPU (`mjx-arm bench seeds --devices N`) and training over GPUs "
            "(`benchmarks/bench_scaling.py`), with the runs that crashed.",
            ("scaling/*",)),
    Section("transfer", "Transfer",
            "One exported policy in every engine, by `mjx-arm bench transfer`.",
            ("transfer/*", "contact/transfer/*", "lift/*")),
    Section("parity", "Engine parity",
            "The same inputs in C MuJoCo, MJX and PyBullet, by `mjx-arm bench parity`.",
            ("parity/*", "parity_gpu/*", "arms/parity_*/*")),
    Section("throughput", "Throughput and cold start",
            "Env and physics steps per second, and where a cold start's seconds go.",
            ("throughput/*", "sweep/*", "cold_start/*", "warp/mjx_throughput*",
             "warp/cold_start*", "arms/throughput_*")),
    Section("cpu", "CPU envs",
            "The Gymnasium envs on the CPU beside raw physics (`bench_cpu_envs.py`).",
            ("cpu/*",)),
    Section("arms", "Other arms",
            "Published arm URDFs through the pipeline: checks, training, transfer.",
            ("arms/*",)),
    Section("contact", "Contact and grasp",
            "PyBullet's contact calibration and the gripper's pick (`bench grasp`).",
            ("contact/*", "grasp/*")),
    Section("sim2real", "Sim-to-real chain",
            "Exported Lift policies through the deploy chain (position servo, latency, "
            "feed-forward stream) in C MuJoCo and PyBullet (`bench_deploy_chain.py`, "
            "`bench_lift_transfer.py`).", ("sim2real/*",)),
    Section("robustness", "Robustness",
            "Hostile URDFs and bad inputs: named errors, never a crash.",
            ("fuzz/*", "robustness/*")),
    Section("earlier", "Earlier training runs",
            "Single runs of older presets, kept for the record; not figures of the presets as "
            "shipped.", ("train/*", "warp/*", "solver4/*", "gentle/*")),
)  # fmt: skip
OTHER = Section("other", "Other results", "Result files no section names yet.", ("*",))


def section_of(rel: str) -> Section:
    """The section whose first matching pattern takes ``rel`` (a path under the results)."""
    for section in SECTIONS:
        if any(fnmatch.fnmatch(rel, p) for p in section.patterns):
            return section
    return OTHER


@dataclass(frozen=True)
class Result:
    """One result file: its path under the results folder and its data (None: skipped)."""

    rel: str
    data: Json | None
    reason: str = ""


def load_results(results: Path) -> list[Result]:
    """Every ``*.json`` under ``results``, sorted; unreadable ones carry the reason."""
    found = []
    for path in sorted(results.rglob("*.json")):
        rel = path.relative_to(results).as_posix()
        try:
            data = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            found.append(Result(rel, None, f"not readable JSON ({type(err).__name__})"))
            continue
        if not isinstance(data, dict):
            found.append(Result(rel, None, "not a JSON object"))
        elif "meta" not in data and renderer_for(data).name == "generic":
            found.append(Result(rel, None, "no run metadata and no known shape (a config?)"))
        else:
            found.append(Result(rel, data))
    return found


def render_result(result: Result, heading: str, results: Path, plots: Path | None) -> list[str]:
    """A file's part of its page: its title, path and provenance, its renderer's tables and
    the plot drawn from it (``plots``: the plots' folder; None draws none)."""
    assert result.data is not None
    renderer = renderer_for(result.data)
    lines = [f"## {heading}", "", f"`{result.rel}` (markdown twin beside it)", ""]
    lines += provenance(result.data.get("meta") or {})
    try:
        lines += renderer.render(result.data)
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as err:
        lines += [f"*Not rendered ({type(err).__name__}: {err}); see its markdown twin.*", ""]
    if plots is not None:
        path = draw(result.rel, results / result.rel, result.data, renderer.name, heading, plots)
        if path is not None:
            lines += [f"![Plot of {result.rel}]({_rel_link(path, plots.parent)})", ""]
    return lines


def _rel_link(target: Path, page_dir: Path) -> str:
    return Path(os.path.relpath(target.resolve(), page_dir.resolve())).as_posix()


def render_section(section: Section, found: list[Result], results: Path, out: Path,
                   draw_plots: bool = True) -> str:  # fmt: skip
    """The markdown of one section's page (plots drawn into ``out/plots``)."""
    lines = [f"# {section.title}", "", section.intro, ""]
    lines += [
        "Generated by `docs/gen_results.py` from the JSON file named under each heading "
        "(under `benchmarks/results/`); each file's markdown twin (`.md`) sits beside it, and "
        "each plot is drawn from its one JSON file.",
        "",
    ]
    titles = [title(r.rel, r.data or {}, renderer_for(r.data or {}).name) for r in found]
    headings = unique_titles(titles, [r.rel for r in found])
    plots = out / "plots" if draw_plots else None
    for result, heading in zip(found, headings, strict=True):
        lines += render_result(result, heading, results, plots)
    return "\n".join(lines).rstrip() + "\n"


def render_index(pages: dict[Section, list[Result]], skipped: list[Result], results: Path) -> str:
    """The results index: the headline table, the pages, and the files skipped."""
    lines = [
        "# Results",
        "",
        "Every figure in these pages is generated from the JSON that the benchmarks write "
        "under `benchmarks/results/` (`docs/gen_results.py`, run by every docs build), and "
        "every plot is drawn from one of those files. Each result names its file under its "
        "heading; each figure carries the date, device and package versions of its run. "
        "Where a figure changed over time, the JSON keeps the earlier runs.",
        "",
        "## Headline figures",
        "",
        *headline_list(results),
        "```{toctree}",
        ":maxdepth: 1",
        "",
        *[s.slug for s in pages],
        "```",
        "",
    ]
    if skipped:
        lines += ["## Files not rendered", ""]
        lines += [f"- `{r.rel}`: {r.reason}" for r in skipped] + [""]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# command line


def generate(results: Path, out: Path, draw_plots: bool = True) -> list[Path]:
    """Write the results pages into ``out`` (their plots into ``out/plots``, unless
    ``draw_plots`` is False); return the pages written."""
    found = load_results(results)
    pages: dict[Section, list[Result]] = {}
    for result in found:
        if result.data is not None:
            pages.setdefault(section_of(result.rel), []).append(result)
    order = [s for s in (*SECTIONS, OTHER) if s in pages]
    pages = {s: pages[s] for s in order}
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for section, results_in in pages.items():
        path = out / f"{section.slug}.md"
        _write(path, render_section(section, results_in, results, out, draw_plots))
        written.append(path)
    skipped = [r for r in found if r.data is None]
    index = out / "index.md"
    _write(index, render_index(pages, skipped, results))
    _remove_stale(out, [index, *written], draw_plots)
    return [index, *written]


def _remove_stale(out: Path, pages: list[Path], plots_too: bool) -> None:
    """Delete pages of sections that have no file any more (Sphinx would warn that no toctree
    holds them) and, when plots were drawn, plots that no page links."""
    for page in set(out.glob("*.md")) - set(pages):
        page.unlink()
    if plots_too and (out / "plots").is_dir():
        text = "\n".join(p.read_text() for p in pages)
        for plot in (out / "plots").glob("*.png"):
            if f"(plots/{plot.name})" not in text:
                plot.unlink()


def _write(path: Path, text: str) -> None:
    """Write only when the text changed (Sphinx then rebuilds only what changed)."""
    if not path.is_file() or path.read_text() != text:
        path.write_text(text)


def main(argv: list[str] | None = None) -> int:
    """Generate the pages and README's block; ``--check`` only compares the README."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=RESULTS)
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--readme", type=Path, default=README)
    parser.add_argument("--check", action="store_true", help="README's block is up to date")
    parser.add_argument("--no-plots", action="store_true", help="write the pages, draw no plot")
    args = parser.parse_args(argv)
    text = args.readme.read_text()
    fresh = update_readme(text, args.results)
    if args.check:
        if fresh != text:
            print(f"{args.readme}: headline block out of date; run docs/gen_results.py")
            return 1
        return 0
    written = generate(args.results, args.out, draw_plots=not args.no_plots)
    _write(args.readme, fresh)
    print(f"{len(written)} results pages in {args.out}; headline block of {args.readme}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
