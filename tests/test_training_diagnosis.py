"""The trap a failing Touch seed's last evaluation shows (benchmarks/training_diagnosis.py)."""

from __future__ import annotations

import csv
import json

from benchmarks.training_diagnosis import campaign, trap


def _eval(strike=0.0, touching=0.0, streak=0.0):
    return {"eval/episode_strike": strike, "eval/episode_touching": touching,
            "eval/episode_streak": streak}  # fmt: skip


def test_each_trap_from_its_figures():
    """Measured rows of the tuning seeds: strikes first, then how the tool meets the box."""
    assert trap(_eval(strike=0.56, touching=17.5)) == "striking"
    assert trap(_eval(touching=31.9, streak=0.125)) == "tapping"  # seed 1004, lr 3e-4
    assert trap(_eval(touching=30.0, streak=12.0)) == "resting"
    assert trap(_eval(touching=0.09)) == "stalled"
    assert trap(_eval(touching=3.0, streak=0.0)) == "other"


def _run(folder, seed, success, touching, streak):
    run = folder / f"touch-fast-seed{seed}"
    run.mkdir(parents=True)
    cols = ["step", "eval/episode_success", "eval/episode_touching", "eval/episode_streak",
            "eval/episode_strike", "eval/episode_distance", "eval/avg_episode_length",
            "training/kl_mean", "training/clip_fraction"]  # fmt: skip
    with (run / "metrics.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(cols)
        writer.writerow([0, 0.0, 0.0, 0.0, 0.0, 56.0, 150, "", ""])
        writer.writerow([1000, success, touching, streak, 0.0, 6.0, 150, 0.1, 0.3])
    train = {"schedule": {"kind": "constant"}, "normalizer": {"clip": 0.0}}
    (run / "config.json").write_text(json.dumps({"train": train}))


def test_a_campaign_counts_the_traps_of_its_failing_seeds(tmp_path):
    _run(tmp_path, 1, 0.99, 3.0, 2.0)
    _run(tmp_path, 2, 0.0, 31.9, 0.1)
    _run(tmp_path, 3, 0.0, 0.0, 0.0)
    result = campaign("test", tmp_path, 0.95)
    assert (result["solved"], result["count"]) == (1, 3)
    assert [s["trap"] for s in result["seeds"]] == [None, "tapping", "stalled"]
    assert result["traps"]["tapping"] == 1 and result["traps"]["stalled"] == 1
    assert abs(result["seeds"][1]["mean_distance_last"] - 0.04) < 1e-9
