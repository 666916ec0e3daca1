"""The seeds benchmark's report: NAME.json, NAME.md and the success curves (NAME.png)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from mjx_arm.bench.results import save_results
from mjx_arm.bench.seeds_config import SeedRun, SeedsConfig
from mjx_arm.bench.seeds_summary import seeds_table, summarize


def plot_curves(runs: list[SeedRun], threshold: float, title: str, path: Path) -> Path:
    """Each seed's success against wall time (left) and env steps (right), as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (by_time, by_step) = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for run in runs:
        t, s, v = zip(*run.curve, strict=True) if run.curve else ((), (), ())
        by_time.plot(t, v, marker=".", label=f"seed {run.seed}")
        by_step.plot(np.asarray(s) / 1e6, v, marker=".")
    for ax, label in ((by_time, "seconds from the seed's start"), (by_step, "env steps (M)")):
        ax.axhline(threshold, color="grey", linestyle="--", linewidth=1)
        ax.set_xlabel(label)
        ax.grid(alpha=0.3)
    by_time.set_ylabel("evaluation success")
    by_time.legend(fontsize=7, ncol=2)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_report(
    config: SeedsConfig,
    runs: list[SeedRun],
    configs: list[dict[str, Any]],
    meta: dict[str, Any],
    out: Path,
    name: str,
    overrides: tuple[str, ...] = (),
    wall_s: float | None = None,
    png: bool = False,
    pending: int = 0,
) -> list[Path]:
    """Write NAME.json and NAME.md (and with ``png``, NAME.png) into ``out``; return their paths.

    ``wall_s``: the whole benchmark's wall time (recorded with the GPUs the seeds ran on).
    ``pending``: seeds still training or queued (a report written while the benchmark runs,
    so that one stopped early keeps its finished seeds), or left out by a SIGTERM; recorded
    as ``pending_seeds``."""
    summary = summarize(runs, config.threshold)
    if wall_s is not None:
        summary["wall_s"] = wall_s
        summary["gpus"] = sorted({r.gpu for r in runs if r.gpu})
    table = seeds_table(runs, summary)
    changed = f", with {' '.join(overrides)}" if overrides else " as shipped"
    title = f"{config.task}, preset {config.preset}{changed}, {meta['device']['kind']}"
    if config.gpus_per_seed > 1:
        title += f", {config.gpus_per_seed} GPUs per seed"
    if config.server:
        title += ", --server (envs and programs kept from seed to seed)"
    if pending:
        title += f" ({len(runs)} seeds finished, {pending} not: still to come or stopped)"
    payload = {
        "meta": meta,
        "settings": dataclasses.asdict(config),
        "overrides": list(overrides),
        "pending_seeds": pending,
        "summary": summary,
        "seeds": [dataclasses.asdict(r) for r in runs],
        "configs": configs,
    }
    paths = list(save_results(name, payload, f"# Seeds: {title}\n\n{table}", out))
    if png:
        paths.append(plot_curves(runs, config.threshold, title, out / f"{name}.png"))
    return paths
