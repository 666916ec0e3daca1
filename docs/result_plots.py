"""Each result's plot, drawn from its JSON by the docs build (``gen_results.py``).

A plot shows only what its one JSON holds; :data:`DRAWINGS` has one drawing per kind of result
(the kinds of ``result_kinds.RENDERERS``). Kinds with nothing to draw (fuzz counts, a single
evaluation) get none. Plots go to ``<pages>/plots/`` and are drawn again only when their JSON or
the drawing or titles changed, so a docs build redraws only what is new.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Callable
from pathlib import Path
from typing import Any

from matplotlib.figure import Figure  # saved through Agg, no pyplot and no display

Json = dict[str, Any]
DPI = 80
TITLE_WIDTH = 60  # characters a line of a plot's title holds at the figure widths below


def _figure(panels: int, title: str, height: float = 3.4) -> tuple[Figure, list[Any]]:
    """A figure of ``panels`` side by side (at most 4 a row), its title wrapped to fit."""
    cols = min(panels, 4)
    rows = math.ceil(panels / cols)
    fig = Figure(figsize=(max(4.2 * cols, 6.0), height * rows + 0.6))
    axes = [fig.add_subplot(rows, cols, i + 1) for i in range(panels)]
    wrapped = textwrap.fill(title, TITLE_WIDTH * max(cols, 2) // 2)
    fig.suptitle(wrapped, fontsize=10)
    return fig, axes


def _wrap(text: str, width: int = 30) -> str:
    return textwrap.fill(text, width)


def draw_seeds(data: Json, title: str) -> Figure | None:
    """Each seed's evaluation success against seconds from its start and env steps."""
    seeds = [s for s in data.get("seeds", []) if s.get("curve")]
    if not seeds:
        return None
    threshold = (data.get("summary") or {}).get("threshold")
    fig, (by_time, by_step) = _figure(2, title)
    for s in seeds:
        t, steps, success = zip(*s["curve"], strict=True)
        by_time.plot(t, success, marker=".", label=f"seed {s.get('seed')}")
        by_step.plot([x / 1e6 for x in steps], success, marker=".")
    for ax, label in ((by_time, "seconds from the seed's start"), (by_step, "env steps (M)")):
        if threshold is not None:
            ax.axhline(threshold, color="grey", ls="--", lw=1)
        ax.set(xlabel=label, ylim=(-0.03, 1.03))
        ax.grid(alpha=0.3)
    by_time.set_ylabel("evaluation success")
    by_time.legend(fontsize=7, ncol=2)
    return fig


def draw_train(data: Json, title: str) -> Figure | None:
    """Each run's evaluation success against env steps and seconds, and its reward."""
    rows = [r for r in data.get("rows", []) if isinstance(r.get("curve"), dict)]
    if not rows:
        return None
    fig, (success, by_time, reward) = _figure(3, title)
    for r in rows:
        c, label = r["curve"], str(r.get("task", "?"))
        success.plot(c["env_steps"], c["success"], marker="o", label=label)
        by_time.plot(c["seconds"], c["success"], marker="o")
        reward.plot(c["env_steps"], c["reward"], marker="o")
    success.set(xlabel="env steps", ylabel="evaluation success")
    by_time.set(xlabel="seconds since the first evaluation", ylabel="evaluation success")
    reward.set(xlabel="env steps", ylabel="evaluation episode reward")
    for ax in (success, by_time, reward):
        ax.grid(alpha=0.3)
    success.legend(fontsize=8)
    return fig


def _ci_err(rows: list[Json]) -> list[list[float]]:
    low = [max(r["success_rate"] - r["success_ci95"][0], 0.0) for r in rows]
    high = [max(r["success_ci95"][1] - r["success_rate"], 0.0) for r in rows]
    return [low, high]


def draw_transfer(data: Json, title: str) -> Figure | None:
    """Success (Wilson 95 % interval) and mean peak contact force per engine."""
    rows = [r for r in data["rows"] if r.get("success_ci95")]
    if not rows:
        return None
    config = data.get("config") or {}
    labels = [_wrap(str(r.get("label", r.get("key"))), 14) for r in rows]
    fig, (left, right) = _figure(2, title)
    left.bar(labels, [r["success_rate"] for r in rows], yerr=_ci_err(rows), capsize=4)
    right.bar(labels, [r.get("mean_peak_contact_force") or 0.0 for r in rows], color="C1")
    if config.get("goal_success") is not None:
        left.axhline(config["goal_success"], color="grey", ls=":")
    if config.get("goal_peak_force") is not None:
        right.axhline(config["goal_peak_force"], color="grey", ls=":")
    left.set(ylim=(0, 1.05), ylabel="success (95% CI)")
    right.set(ylabel="mean peak contact force (N)")
    for ax in (left, right):
        ax.tick_params(axis="x", labelsize=7)
    return fig


def draw_robustness(data: Json, title: str) -> Figure:
    """Success against each perturbation's value (stated range shaded), then the joint draw."""
    perts = data["perturbations"]
    summary = data.get("summary") or {}
    fig, axes = _figure(len(perts) + 1, title, height=2.6)
    for ax, p in zip(axes, perts, strict=False):
        rows = [r for r in data["rows"] if r["perturbation"] == p["name"]]
        ax.axvspan(*p["stated"], color="C2", alpha=0.12)
        ax.errorbar([r["value"] for r in rows], [r["success_rate"] for r in rows],
                    yerr=_ci_err(rows), marker="o", capsize=3)  # fmt: skip
        ax.axhline(summary.get("goal_point", 0.9), color="grey", ls=":")
        ax.set(ylim=(0, 1.05), xlabel=p.get("unit", ""))
        ax.set_title(p["name"], fontsize=9)
    names = {p["name"] for p in perts}
    joint = [r for r in data["rows"] if r["perturbation"] not in names]
    ax = axes[len(perts)]
    if joint:
        ax.bar(["all at once"], [joint[0]["success_rate"]], yerr=_ci_err(joint[:1]), capsize=4,
               color="C1")  # fmt: skip
    ax.axhline(summary.get("goal_joint", 0.85), color="grey", ls=":")
    ax.set(ylim=(0, 1.05))
    ax.set_title("joint draw", fontsize=9)
    axes[0].set_ylabel("success")
    return fig


def draw_failures(data: Json, title: str) -> Figure:
    """Per value of the perturbation: failures, of them strikes."""
    rows = data["rows"]
    values = [str(r["value"]) for r in rows]
    strikes = [r["strikes"] for r in rows]
    other = [r["failures"] - r["strikes"] for r in rows]
    fig, (ax,) = _figure(1, title)
    ax.bar(values, strikes, label="strikes")
    ax.bar(values, other, bottom=strikes, label="other failures", color="C1")
    ax.set(xlabel=str(rows[0].get("perturbation", "value")), ylabel="failed episodes")
    ax.legend(fontsize=8)
    return fig


def draw_throughput(data: Json, title: str) -> Figure | None:
    """Control steps per second against the number of envs, one line per implementation."""
    rows = [r for r in data["rows"] if r.get("env_control_steps_per_s")]
    if not rows:
        return None
    fig, (ax,) = _figure(1, title)
    impls = sorted({str(r.get("impl") or "default") for r in rows})
    for impl in impls:
        mine = sorted((r for r in rows if str(r.get("impl") or "default") == impl),
                      key=lambda r: r["batch"])  # fmt: skip
        ax.plot([r["batch"] for r in mine], [r["env_control_steps_per_s"] for r in mine],
                marker="o", label=impl)  # fmt: skip
    ax.set(xscale="log", yscale="log", xlabel="envs", ylabel="control steps/s")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def draw_parity(data: Json, title: str) -> Figure:
    """Open-loop divergence over time, the tared press force, and the acceleration spread."""
    figures = data["figures"]
    fig, (div, press, jitter) = _figure(3, title)
    loop = figures["open_loop"]
    for i, (key, stats) in enumerate(loop["pairs"].items()):
        div.semilogy(loop["time_s"], stats["median"], color=f"C{i}", label=f"{key} median")
        div.semilogy(loop["time_s"], stats["p95"], color=f"C{i}", ls="--")
    div.set(xlabel="time (s)", ylabel="joint divergence (rad)")
    div.legend(fontsize=6)
    p = figures["press"]
    for i, (name, e) in enumerate(p["engines"].items()):
        press.plot(p["time_s"], e["force_median_n"], color=f"C{i}", lw=2, label=name)
    press.set(xlabel="time (s)", ylabel="tared |F|, median of boxes (N)")
    press.legend(fontsize=7)
    groups = [(engine, scenario, by) for engine, scenarios in figures["jitter"].items()
              for scenario, by in scenarios.items()]  # fmt: skip
    dampings = sorted({d for *_, by in groups for d in by})
    for j, damping in enumerate(dampings):
        xs = [k + 0.4 * j for k in range(len(groups))]
        values = [max(by.get(damping, {}).get("acc_std_max") or 0.0, 1e-9) for *_, by in groups]
        jitter.bar(xs, values, width=0.4, label=f"damping {damping}")
    jitter.set_xticks([k + 0.2 for k in range(len(groups))],
                      [f"{e}\n{s}" for e, s, _ in groups], fontsize=6, rotation=90)  # fmt: skip
    jitter.set(yscale="log", ylabel="joint acceleration std (rad/s²)")
    jitter.legend(fontsize=7)
    return fig


DRAWINGS: dict[str, Callable[[Json, str], Figure | None]] = {
    "seeds": draw_seeds,
    "train": draw_train,
    "transfer": draw_transfer,
    "robustness": draw_robustness,
    "failures": draw_failures,
    "throughput": draw_throughput,
    "parity": draw_parity,
}


def plot_path(rel: str, plots: Path) -> Path:
    """Where the plot of the result at ``rel`` (its path under the results) goes."""
    return plots / (rel.removesuffix(".json").replace("/", "__") + ".png")


def draw(rel: str, source: Path, data: Json, kind: str, title: str, plots: Path) -> Path | None:
    """The plot of one result (``source``: its JSON file), drawn if missing or out of date;
    None for a kind without a drawing or a file with nothing to draw."""
    drawing = DRAWINGS.get(kind)
    if drawing is None:
        return None
    path = plot_path(rel, plots)
    code = (Path(__file__), Path(__file__).with_name("result_titles.py"))
    newest = max(source.stat().st_mtime, *(p.stat().st_mtime for p in code))
    if path.is_file() and path.stat().st_mtime >= newest:
        return path
    try:
        fig = drawing(data, title.replace("`", ""))
    except (KeyError, TypeError, ValueError, IndexError):
        return None
    if fig is None:
        return None
    plots.mkdir(parents=True, exist_ok=True)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    fig.savefig(path, dpi=DPI)
    return path
