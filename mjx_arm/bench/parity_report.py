"""The parity result as files: a markdown report and the JSON (and, asked for, three PNG plots)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from mjx_arm.bench.parity_config import DAMPING, JITTER_SCENARIOS
from mjx_arm.bench.results import fmt, markdown_table, save_results, verdict

NAME = "parity"
PLOTS = ("divergence", "press", "jitter")
# Times (s) of the divergence table's columns, besides the goal time and the end.
EXTRA_TIMES = (0.5,)


def _goal_text(goal: Any) -> str:
    if isinstance(goal, list | tuple):
        return f"{goal[0]:g}-{goal[1]:g} N"
    return f"<= {goal:.0e}".replace("e-0", "e-")


def _value_text(value: Any) -> str:
    if isinstance(value, list | tuple):
        return f"{value[0]:.1f}-{value[1]:.1f} N"
    return f"{value:.2e}"


def goals_table(result: dict[str, Any]) -> str:
    """Every goal: figure, goal, pass/MISS and the stated cause of a miss."""
    rows = [
        [
            g["check"],
            g["subject"],
            _value_text(g["value"]),
            _goal_text(g["goal"]),
            verdict(g["met"]),
            g["cause"] or "",
        ]
        for g in result["goals"]
    ]
    return markdown_table(["check", "pair / engine", "figure", "goal", "result", "cause"], rows)


def divergence_table(result: dict[str, Any]) -> str:
    """Median and 95th percentile of the joint divergence of each pair at a few times."""
    figures, config = result["figures"]["open_loop"], result["config"]
    time_s = np.asarray(figures["time_s"])
    times = sorted({*EXTRA_TIMES, config["goal_time"], float(time_s[-1])})
    times = [t for t in times if t <= time_s[-1] + 1e-9]
    index = [int(np.argmin(np.abs(time_s - t))) for t in times]
    headers = ["pair", *(f"{t:g} s: median / p95 (rad)" for t in times), "max (rad)"]
    rows = []
    for key, stats in figures["pairs"].items():
        cells = [f"{stats['median'][i]:.1e} / {stats['p95'][i]:.1e}" for i in index]
        rows.append([key, *cells, f"{stats['max']:.1e}"])
    return markdown_table(headers, rows)


def press_table(result: dict[str, Any]) -> str:
    """First contact, steady force and the gap to the reference engine, per engine."""
    press = result["figures"]["press"]
    rows = []
    for name, e in press["engines"].items():
        steady, first = np.asarray(e["steady_n"]), np.asarray(e["first_contact_s"])
        rows.append(
            [
                name,
                f"{first.min():.2f}-{first.max():.2f}",
                f"{steady.min():.1f}-{steady.max():.1f}",
                f"{np.median(steady):.1f}",
                f"{100 * e['rel_to_reference_max']:.1f}%",
            ]
        )
    headers = [
        "engine",
        "first contact (s)",
        "steady force (N)",
        "median (N)",
        f"max difference from {press['reference']}",
    ]
    return markdown_table(headers, rows)


def jitter_table(result: dict[str, Any], key: str = "acc_std_max") -> str:
    """One jitter figure per engine and scenario: damping as converted / zeroed."""
    rows = []
    for name, scenarios in result["figures"]["jitter"].items():
        cells = [
            f"{fmt(s['converted'][key], '.1e')} / {fmt(s['zeroed'][key], '.1e')}"
            for s in (scenarios[n] for n in JITTER_SCENARIOS)
        ]
        rows.append([name, *cells])
    return markdown_table(["engine", *JITTER_SCENARIOS], rows)


def markdown(result: dict[str, Any], meta: dict[str, Any], plots: bool = False) -> str:
    """The whole report (with ``plots``, linking the three PNGs beside it)."""
    config, figures = result["config"], result["figures"]
    ol = figures["open_loop"]
    device = meta["device"]
    parts = [
        "# Engine parity\n",
        f"Engines: {', '.join(result['engines'])}. Device: {device['kind']} "
        f"({device['cpu_model']}, {device['cores']} cores). Settings: `{NAME}.json` (config).\n",
        "## Goals\n",
        goals_table(result),
        f"## Forward kinematics ({config['fk_poses']} random poses)\n",
        markdown_table(
            ["pair", "max ee distance (m)"], [[k, f"{v:.1e}"] for k, v in figures["fk_m"].items()]
        ),
        f"## Open-loop joint divergence ({ol['sequences']} sequences, "
        f"{ol['sequences_with_contact']} of them touch the table in some engine)\n",
        "Largest joint-angle difference of the pair per sequence; median and 95th percentile "
        "over the sequences.\n",
        divergence_table(result),
        "Largest tared |F| in free motion (the sequences that touch nothing): "
        + ", ".join(f"{k} {v:.1e} N" for k, v in ol["free_motion_force_max_n"].items())
        + ".\n",
        f"## Pressing the box ({config['press_boxes']} positions, commands recorded in "
        "C MuJoCo and replayed)\n",
        f"Steady |F|: the mean of the last {config['press_average_steps']} control steps.\n",
        press_table(result),
        "## Jitter (damping as converted / zeroed)\n",
        f"Std of the joint acceleration (rad/s^2), largest joint, over the last "
        f"{config['jitter_window']:g} s of each run, read at every physics step:\n",
        jitter_table(result, "acc_std_max"),
        "RMS of the joint velocity above the control rate (rad/s), largest joint:\n",
        jitter_table(result, "hf_vel_rms_max"),
    ]
    if plots:
        parts.append("\n".join(f"![{p}]({NAME}_{p}.png)" for p in PLOTS) + "\n")
    return "\n".join(parts)


# --------------------------------------------------------------------------- plots


def plot_divergence(ax, result: dict[str, Any]) -> None:
    """Median (solid) and p95 (dashed) divergence of every pair over time, goals dotted."""
    figures, config = result["figures"]["open_loop"], result["config"]
    time_s = figures["time_s"]
    for i, (key, stats) in enumerate(figures["pairs"].items()):
        color = f"C{i}"
        ax.semilogy(time_s, stats["median"], color=color, label=f"{key} median")
        ax.semilogy(time_s, stats["p95"], color=color, ls="--", label=f"{key} p95")
    for goal in sorted({g["goal"] for g in result["goals"] if g["check"].startswith("joint")}):
        ax.axhline(goal, color="grey", ls=":", lw=1)
    ax.axvline(config["goal_time"], color="grey", ls=":", lw=1)
    ax.set(xlabel="time (s)", ylabel="joint divergence (rad)", title="open-loop divergence")
    ax.legend(fontsize="small")


def plot_press(ax, result: dict[str, Any]) -> None:
    """Tared |F| over time per engine: every box thin, the median bold; the band shaded."""
    press = result["figures"]["press"]
    for i, (name, e) in enumerate(press["engines"].items()):
        ax.plot(press["time_s"], np.asarray(e["force_n"]).T, color=f"C{i}", lw=0.5, alpha=0.5)
        ax.plot(press["time_s"], e["force_median_n"], color=f"C{i}", lw=2, label=name)
    band = next(g["goal"] for g in result["goals"] if g["check"].startswith("steady press"))
    ax.axhspan(*band, color="green", alpha=0.08, label="Touch success band")
    ax.set(xlabel="time (s)", ylabel="tared |F| (N)", title="pressing the box")
    ax.legend(fontsize="small")


def plot_jitter(axes, result: dict[str, Any]) -> None:
    """Acceleration spread per engine, damping as converted and zeroed, one panel a scenario
    (log scale; a run without any motion is marked 0 at the bottom)."""
    jitter = result["figures"]["jitter"]
    names = list(jitter)
    x = np.arange(len(names))
    for ax, scenario in zip(axes, JITTER_SCENARIOS, strict=True):
        for j, damping in enumerate(DAMPING):
            values = np.array([jitter[n][scenario][damping]["acc_std_max"] for n in names])
            ax.bar(x + 0.4 * j, values, width=0.4, color=f"C{j}", label=f"damping {damping}")
            for xi in x[values == 0.0]:
                ax.annotate("0", (xi + 0.4 * j, 0), xycoords=("data", "axes fraction"), ha="center")
        ax.set_xticks(x + 0.2, names, fontsize="small")
        ax.set(title=scenario)
    axes[-1].set_yscale("log")  # shared: the press panel always has data to scale
    axes[0].set(ylabel="joint acceleration std (rad/s^2)")
    axes[0].legend(fontsize="small")


def save_plots(result: dict[str, Any], folder: Path) -> list[Path]:
    """The three PNGs (matplotlib's Agg backend)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    for name in PLOTS:
        if name == "jitter":
            fig, axes = plt.subplots(1, len(JITTER_SCENARIOS), figsize=(14, 4), sharey=True)
            plot_jitter(axes, result)
        else:
            fig, ax = plt.subplots(figsize=(8, 5))
            (plot_divergence if name == "divergence" else plot_press)(ax, result)
        fig.tight_layout()
        paths.append(folder / f"{NAME}_{name}.png")
        fig.savefig(paths[-1], dpi=110)
        plt.close(fig)
    return paths


def write_report(
    result: dict[str, Any], meta: dict[str, Any], folder: str | Path, png: bool = False
) -> list[Path]:
    """Write ``parity.md`` and ``parity.json`` (with ``png``, the three PNGs too) into
    ``folder``; returns the paths."""
    folder = Path(folder)
    text = markdown(result, meta, png)
    paths = list(save_results(NAME, {"meta": meta, **result}, text, folder))
    return paths + (save_plots(result, folder) if png else [])
