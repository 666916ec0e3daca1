"""The docs: the README's headline block and the results pages come from the benchmark JSON
(``docs/gen_results.py``), and the site builds with warnings as errors."""

from __future__ import annotations

import importlib.util
import json
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


def _load(name: str):
    """Import ``docs/NAME.py`` (the docs folder is not a package)."""
    spec = importlib.util.spec_from_file_location(f"docs_{name}", DOCS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


gen = _load("gen_results")


def _results_copy(tmp_path: Path) -> Path:
    """A small copy of the committed results: the seeds and transfer files the headline reads,
    and the CPU envs' file."""
    src, dst = gen.RESULTS, tmp_path / "results"
    for rel in ("seeds", "contact/transfer", "warp", "parity", "cpu", "fuzz"):
        shutil.copytree(src / rel, dst / rel, ignore=shutil.ignore_patterns("*.npz", "*.mp4"))
    return dst


def test_readme_headline_block_is_what_the_script_makes():
    text = (ROOT / "README.md").read_text()
    assert gen.BEGIN in text and gen.END in text
    assert gen.update_readme(text, gen.RESULTS) == text, "run: python docs/gen_results.py"
    assert gen.main(["--check"]) == 0


def test_readme_is_one_page():
    assert len((ROOT / "README.md").read_text().splitlines()) <= 250


def test_changing_one_json_value_changes_the_page_and_the_readme(tmp_path):
    results = _results_copy(tmp_path)
    out = tmp_path / "pages"
    readme = tmp_path / "README.md"
    readme.write_text(f"intro\n{gen.BEGIN}\n{gen.END}\nrest\n")
    argv = ["--results", str(results), "--out", str(out), "--readme", str(readme), "--no-plots"]
    assert gen.main(argv) == 0
    page, block = (out / "seeds.md").read_text(), readme.read_text()
    reach = "20 of 20 seeds at 0.95 (95% interval 0.84-1.00), 0 collapsed; median 26.0 s warm"
    assert reach in block
    assert "| 20 of 20 |" in page

    file = results / "seeds" / "fresh" / "seeds_reach_fast_fresh.json"
    data = json.loads(file.read_text())
    data["summary"]["solved"] = 7
    data["summary"]["time_to_threshold_warm"]["median"] = 51.25
    file.write_text(json.dumps(data))
    assert gen.main(argv) == 0
    changed = "7 of 20 seeds at 0.95 (95% interval 0.84-1.00), 0 collapsed; median 51.2 s"
    assert changed in readme.read_text()
    assert "| 7 of 20 | 51.2 s (" in (out / "seeds.md").read_text()
    assert readme.read_text().startswith("intro\n") and readme.read_text().endswith("rest\n")
    assert gen.main(["--results", str(results), "--readme", str(readme), "--check"]) == 0


def test_every_figure_names_its_date_device_and_versions(tmp_path):
    results = _results_copy(tmp_path)
    gen.generate(results, tmp_path / "pages", draw_plots=False)
    page = (tmp_path / "pages" / "seeds.md").read_text()
    # the heading, then its file (a heading other files share also names its file's path)
    heading = r"## Touch, `--preset fast`, 10 seeds( \(seeds/seeds_touch_fast\))?\n\n"
    assert re.search(heading + r"`seeds/seeds_touch_fast\.json`", page)
    assert "Measured **2026-11-23** · NVIDIA H200" in page
    assert "mujoco-mjx 3.17.0" in page and "jax 0.11.2" in page


def test_unknown_and_broken_files_are_skipped_gracefully(tmp_path):
    results = _results_copy(tmp_path)
    (results / "robustness").mkdir()
    meta = json.loads((results / "cpu" / "cpu_envs.json").read_text())["meta"]
    new_kind = {"meta": meta, "rows": [{"case": "a", "value": 1.5}], "summary": "one new kind"}
    (results / "robustness" / "new_kind.json").write_text(json.dumps(new_kind))
    (results / "brand_new").mkdir()
    (results / "brand_new" / "x.json").write_text(json.dumps({"meta": meta, "odd": {"a": 1}}))
    (results / "broken.json").write_text("{not json")
    (results / "a_list.json").write_text("[1, 2]")
    written = gen.generate(results, tmp_path / "pages", draw_plots=False)
    names = {p.name for p in written}
    assert {"index.md", "robustness.md", "other.md", "seeds.md"} <= names
    assert "| a | 1.5 |" in (tmp_path / "pages" / "robustness.md").read_text()
    assert "`brand_new/x.json`" in (tmp_path / "pages" / "other.md").read_text()
    index = (tmp_path / "pages" / "index.md").read_text()
    assert "`broken.json`: not readable JSON" in index
    assert "`a_list.json`: not a JSON object" in index


def test_every_committed_result_file_is_rendered_or_listed(tmp_path):
    written = gen.generate(gen.RESULTS, tmp_path / "pages", draw_plots=False)
    text = "\n".join(p.read_text() for p in written)
    for path in gen.RESULTS.rglob("*.json"):
        assert f"`{path.relative_to(gen.RESULTS).as_posix()}`" in text


def test_results_are_in_topic_folders_with_no_loose_files_at_the_top():
    """Rule 1 of benchmarks/README.md: ``<topic>/<name>.json|md``, nothing beside the topics."""
    topics = [p for p in gen.RESULTS.iterdir() if p.is_dir()]
    assert len(topics) > 10
    assert [p.name for p in gen.RESULTS.iterdir() if not p.is_dir()] == []


def test_each_plot_is_drawn_from_its_one_result(tmp_path):
    """Every plot on a page is drawn from the JSON under whose heading it sits: the seeds runs
    named alike (``seeds_touch_fast`` and ``seeds_touch_fast_cold_seed10``) get one plot each."""
    src, results = gen.RESULTS, tmp_path / "results"
    shutil.copytree(src / "seeds", results / "seeds")
    out = tmp_path / "pages"
    gen.generate(results, out)
    page = (out / "seeds.md").read_text()
    links = re.findall(r"!\[Plot of ([^\]]+)\]\((plots/[^)]+)\)", page)
    assert {rel for rel, _ in links} == {p.relative_to(results).as_posix()
                                         for p in results.rglob("*.json")}  # fmt: skip
    assert len({link for _, link in links}) == len(links)  # no plot shown twice
    assert sorted(p.name for p in (out / "plots").iterdir()) == sorted(
        Path(link).name for _, link in links
    )
    for section in page.split("\n## ")[1:]:  # each plot under its own file's heading
        (rel,) = re.findall(r"^`([^`]+\.json)`", section, flags=re.M)
        assert re.findall(r"!\[Plot of ([^\]]+)\]", section) == [rel]


def test_pages_read_as_results(tmp_path):
    """Failure counts get their own table, a figure the run could not make reads as a dash,
    and the index lists the headline figures with their sources."""
    results = _results_copy(tmp_path)
    (results / "robustness").mkdir()
    for path in gen.RESULTS.glob("robustness/failures_*.json"):
        shutil.copy(path, results / "robustness" / path.name)
    written = gen.generate(results, tmp_path / "pages", draw_plots=False)
    robustness = (tmp_path / "pages" / "robustness.md").read_text()
    assert "| value | success | episodes | failures | of them strikes |" in robustness
    assert "95% CI" not in robustness and "task ?." not in robustness
    for page in written:
        assert "| nan |" not in page.read_text() and " nan |" not in page.read_text()
    index = (tmp_path / "pages" / "index.md").read_text()
    assert "source `seeds/fresh/seeds_reach_fast_fresh.json`" in index


def test_a_page_whose_files_are_gone_is_removed(tmp_path):
    """A section left without files loses its page (no toctree would hold it)."""
    results = _results_copy(tmp_path)
    meta = json.loads((results / "cpu" / "cpu_envs.json").read_text())["meta"]
    (results / "brand_new").mkdir()
    (results / "brand_new" / "x.json").write_text(json.dumps({"meta": meta, "odd": {"a": 1}}))
    pages = tmp_path / "pages"
    assert pages / "other.md" in gen.generate(results, pages, draw_plots=False)
    shutil.rmtree(results / "brand_new")
    written = gen.generate(results, pages, draw_plots=False)
    assert not (pages / "other.md").exists()
    assert sorted(pages.glob("*.md")) == sorted(written)


@pytest.mark.slow
def test_docs_build_with_warnings_as_errors(tmp_path):
    """The whole site, offline, warnings as errors (a broken link or a missing page fails)."""
    start = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
         "-d", str(tmp_path / "doctrees"), str(DOCS), str(tmp_path / "html")],
        capture_output=True, text=True, cwd=ROOT, check=False,
    )  # fmt: skip
    seconds = time.perf_counter() - start
    assert proc.returncode == 0, proc.stderr[-4000:]
    pages = list((tmp_path / "html").rglob("*.html"))
    assert len(pages) >= 30, [p.name for p in pages]
    assert (tmp_path / "html" / "results" / "seeds.html").is_file()
    assert (tmp_path / "html" / "api" / "task.html").is_file()
    print(f"docs: {len(pages)} pages in {seconds:.1f} s")
