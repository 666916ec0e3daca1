"""Learning curves (eval success and reward vs env steps and wall time) from run metrics CSVs.

python benchmarks/plot_curves.py RUN_DIR/metrics.csv [...] -o curves.png

(The docs draw the curves that ``benchmarks/results/train/*.json`` keep under ``curve``.)
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt


def read(path: Path) -> dict[str, list[float]]:
    """Columns of a metrics.csv as float lists (time made relative to the first row)."""
    with path.open() as f:
        rows = list(csv.DictReader(f))
    t0 = float(rows[0]["time"])
    keys = ("step", "time", "eval/episode_success", "eval/episode_reward")
    out = {k: [float(r[k]) for r in rows] for k in keys}
    out["time"] = [t - t0 for t in out["time"]]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("csv", nargs="+", type=Path)
    parser.add_argument("-o", "--output", type=Path, default=Path("curves.png"))
    args = parser.parse_args()
    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    for path in args.csv:
        data = read(path)
        label = path.stem
        axes[0].plot(data["step"], data["eval/episode_success"], marker="o", label=label)
        axes[1].plot(data["time"], data["eval/episode_success"], marker="o", label=label)
        axes[2].plot(data["step"], data["eval/episode_reward"], marker="o", label=label)
    axes[0].set(xlabel="env steps", ylabel="eval success rate", title="success vs steps")
    axes[1].set(
        xlabel="seconds since the first evaluation",
        ylabel="eval success rate",
        title="success vs wall time",
    )
    axes[2].set(xlabel="env steps", ylabel="eval episode reward", title="reward vs steps")
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.output, dpi=100)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
