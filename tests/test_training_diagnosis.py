"""The trap a failing Touch seed's last evaluation shows (benchmarks/training_diagnosis.py)."""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import pytest

from benchmarks.training_diagnosis import EARLY_STEPS, campaign, early_drift, trap


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


def _run(folder, seed, success, touching, streak, budget=None):
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
    if budget is not None:
        train["num_timesteps"] = budget
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


def test_a_brief_line_per_seed_run(tmp_path):
    """``campaign_brief``: a solved seed gives the steps of its first evaluation at the
    threshold, a failing one its trap; a run that ended before its budget unsolved is
    "stopped", and a campaign leaves it out of its counts."""
    from benchmarks.campaign_brief import brief

    _run(tmp_path, 1, 0.99, 3.0, 2.0)
    _run(tmp_path, 2, 0.0, 31.9, 0.1)
    _run(tmp_path, 3, 0.0, 31.9, 0.1, budget=1000)  # its budget spent: unsolved
    _run(tmp_path, 4, 0.5, 31.9, 0.1, budget=30_000_000)  # a deadline stopped it at 1000 steps
    line, state = brief(tmp_path / "touch-fast-seed1", 0.95)
    assert state == "solved" and line.endswith("best 0.990 last 0.990 solved at 0.0M steps")
    line, state = brief(tmp_path / "touch-fast-seed2", 0.95)
    assert state == "unsolved" and line.endswith("(tapping)")
    assert brief(tmp_path / "touch-fast-seed3", 0.95)[1] == "unsolved"
    line, state = brief(tmp_path / "touch-fast-seed4", 0.95)
    assert state == "stopped" and line.endswith("before its budget (so far tapping)")
    result = campaign("test", tmp_path, 0.95)
    assert (result["solved"], result["count"], result["stopped"]) == (1, 3, [4])


def test_the_contact_reflex_of_a_tapping_episode():
    """``touch_contact_reflex.reflex``: a press answered by a full-speed retract (3 of 6
    joints at |a| >= 0.9 on the next step) counts as a retract; a held press does not."""
    import numpy as np

    from benchmarks.touch_contact_reflex import reflex

    forces = np.array([0.0, 44.0, 0.0, 0.0, 42.0, 0.0, 20.0, 21.0, 0.0])
    actions = np.zeros((9, 6))
    actions[2, :4] = [-0.7, -1.0, 1.0, -1.0]  # the step after the first press
    actions[5, :3] = [-1.0, 1.0, 0.95]  # and after the second
    got = reflex(forces, actions, (1.0, 50.0))
    assert got["contact_steps"] == 4 and got["in_band_steps"] == 4
    assert got["in_band_pairs"] == 1 and got["retracts"] == 2
    assert got["retract_forces"] == [44.0, 42.0] and got["contact_gap_median"] == 2.0


def test_logged_times_of_a_stopped_seeds_benchmark():
    """``seeds_from_runs``: the finished seeds of a bench log and their times to the
    threshold; a seed still training has no line."""
    from benchmarks.seeds_from_runs import logged_times

    log = (
        "seed 7100: training touch / fast on GPU 0\n"
        "seed 7100: final 0.997, best 0.997, 0.95 at 96.0 s, wall 101.0 s, compile 9.6 s\n"
        "seed 7101: training touch / fast on GPU 0\n"
        "seed 7101: final 0.026, best 0.026, 0.95 at not reached, wall 103.0 s, compile 5.6 s\n"
        "seed 7102: training touch / fast on GPU 0\n"
    )
    assert logged_times(log) == {7100: 96.0, 7101: None}


def test_an_impact_is_a_first_contact_and_its_closing_speed():
    """``touch_contact_reflex.impacts``: each contact after a step without one, with the
    speed at which the distance shrank over the step before (m/s)."""
    import numpy as np

    from benchmarks.touch_contact_reflex import impacts

    forces = np.array([0.0, 0.0, 0.0, 40.0, 30.0, 0.0, 0.0, 20.0])
    distances = np.array([0.10, 0.08, 0.05, 0.04, 0.04, 0.05, 0.045, 0.04])
    got = impacts(forces, distances, 1.0, 0.5)
    assert [round(v, 6) for v, _ in got] == [0.06, 0.01] and [f for _, f in got] == [40.0, 20.0]


def test_the_early_drift_reads_only_the_first_steps():
    """``early_drift``: the smallest and largest std and the largest mean of the epochs up to
    EARLY_STEPS; later epochs (a mean of 500 at twice that) do not count."""
    row = {"training/policy_dist_min_std": 0.5, "training/policy_dist_max_std": 2.0,
           "training/policy_dist_max_loc": 1.0}  # fmt: skip
    rows = [
        {"step": 1e6, **row},
        {"step": EARLY_STEPS, **row, "training/policy_dist_min_std": 0.002,
         "training/policy_dist_max_loc": 40.0},
        {"step": 2 * EARLY_STEPS, **row, "training/policy_dist_max_loc": 500.0},
    ]  # fmt: skip
    assert early_drift(rows) == {"early_std_min": 0.002, "early_std_max": 2.0,
                                 "early_mean_max": 40.0}  # fmt: skip


def _seeds_report(seeds: list[int], solved_at: float | None, date: str) -> dict:
    """A seeds report as ``bench seeds`` writes it, one record per seed (its summary unread)."""
    from mjx_arm.bench.seeds_config import SeedRun

    runs = [
        SeedRun(seed, 1.0, 1.0, 100 if solved_at else None, solved_at, 200, 30.0, 4.0, 1e5,
                [(10.0, 0, 0.0), (solved_at or 20.0, 100, 1.0 if solved_at else 0.0)])
        for seed in seeds
    ]  # fmt: skip
    settings = {"task": "reach", "preset": "fast", "seeds": "", "backend": "auto",
                "threshold": 0.95, "devices": 0, "arm": "", "deterministic": False}  # fmt: skip
    return {
        "meta": {"date": date, "git_commit": date[-2:], "device": {"kind": "gpu"}},
        "settings": settings,
        "overrides": [],
        "seeds": [dataclasses.asdict(r) for r in runs],
        "configs": [{"seed": s} for s in seeds],
    }


def test_seeds_reports_of_two_calls_merge_into_one(tmp_path):
    """``merge_seeds_reports``: the seeds of both reports in seed order with their configs,
    one summary over all of them, the newest machine record and each input named; a seed in
    both reports, or another threshold, is refused."""
    from benchmarks.merge_seeds_reports import merge
    from mjx_arm.bench.seeds_report import write_report

    first = _seeds_report([7301, 7300], 20.0, "2026-11-29T01")
    second = _seeds_report([7302], None, "2026-11-29T05")
    config, runs, configs, meta = merge([first, second], ["a.json", "b.json"])
    assert [r.seed for r in runs] == [7300, 7301, 7302] and config.seeds == "7300,7301,7302"
    assert [c["seed"] for c in configs] == [7300, 7301, 7302]
    # each input's first seed started with that call's empty caches
    assert {r.seed: r.warm for r in runs} == {7301: False, 7300: True, 7302: False}
    assert meta["git_commit"] == "05"
    assert [m["seeds"] for m in meta["merged_from"]] == [[7301, 7300], [7302]]
    write_report(config, runs, configs, meta, tmp_path, "merged")
    summary = json.loads((tmp_path / "merged.json").read_text())["summary"]
    assert (summary["solved"], summary["seeds"]) == (2, 3)
    with pytest.raises(ValueError, match="seed 7301 is in two reports"):
        merge([first, first], ["a.json", "c.json"])
    other = {**second, "settings": {**second["settings"], "threshold": 0.9}}
    with pytest.raises(ValueError, match="threshold"):
        merge([first, other], ["a.json", "d.json"])
    # a report from before --gpus-per-seed counts as one GPU per seed; two per seed differs
    assert "gpus_per_seed" not in first["settings"]
    assert merge([first, {**second, "settings": {**second["settings"], "gpus_per_seed": 1}}],
                 ["a.json", "e.json"])[0].gpus_per_seed == 1  # fmt: skip
    two = {**second, "settings": {**second["settings"], "gpus_per_seed": 2}}
    with pytest.raises(ValueError, match="gpus_per_seed 2, not 1"):
        merge([first, two], ["a.json", "f.json"])


def test_a_merge_leaves_out_the_seeds_a_sigterm_ended(tmp_path):
    """A seed whose process a deadline's SIGTERM ended (listed as failed, exit code -15, by
    reports written before the rule) is left out of the merged report and counted with the
    inputs' own pending seeds; a seed that failed of itself still counts as not solved."""
    from benchmarks.merge_seeds_reports import main

    first = _seeds_report([8700, 8701, 8702], 20.0, "2026-11-30T01")
    first["seeds"][1] |= {"error": "exit code -15: run directory: /w/lift-fast-seed8701"}
    first["seeds"][2] |= {"error": "exit code 1: RuntimeError: out of memory"}
    first["seeds"][2] |= {"steps_to_threshold": None, "time_to_threshold": None}
    first["pending_seeds"] = 2
    second = _seeds_report([8703], 30.0, "2026-11-30T05")
    second["seeds"][0] |= {"error": "exit code 143: stopped"}
    paths = [tmp_path / "a.json", tmp_path / "b.json"]
    for path, report in zip(paths, (first, second), strict=True):
        path.write_text(json.dumps(report))
    assert main([*map(str, paths), "--name", "m", "--out", str(tmp_path)]) == 0
    merged = json.loads((tmp_path / "m.json").read_text())
    assert [s["seed"] for s in merged["seeds"]] == [8700, 8702]
    assert (merged["summary"]["solved"], merged["summary"]["seeds"]) == (1, 2)
    assert merged["pending_seeds"] == 4  # 8701, 8703 and the first input's two
    assert [m["left_out"] for m in merged["meta"]["merged_from"]] == [[8701], [8703]]


def test_the_normalisers_share_of_the_kl_is_read_where_logged():
    """``normaliser_share``: largest and median KL before each update's first gradient step and
    the median clip fraction there; NaN for runs from before the columns existed."""
    import math

    from benchmarks.training_diagnosis import normaliser_share

    kl, clip = "training/kl_before_update", "training/clip_fraction_before_update"
    rows = [
        {"step": 1e6, kl: 0.02, clip: 0.1},
        {"step": 2e6, kl: 2.4e5, clip: 0.4},
        {"step": 3e6, kl: 6.8, clip: 0.2},
    ]
    assert normaliser_share(rows) == {
        "kl_before_update_max": 2.4e5,
        "kl_before_update_median": 6.8,
        "clip_fraction_before_update_median": 0.2,
    }
    assert all(math.isnan(v) for v in normaliser_share([{"step": 1e6}]).values())


def test_the_course_of_success_over_a_run():
    """``success_course``: the first evaluation at 0.05 or more is where a seed started, and a
    drop of 0.3 or more from one evaluation to the next is a fall (0.94 -> 0.53 is one; 0.53 ->
    0.81 and 0.06 -> 0.0 are not)."""
    from benchmarks.training_diagnosis import success_course

    values = [0.0, 0.02, 0.06, 0.0, 0.94, 0.53, 0.81, 0.2, 0.95]
    rows = [{"step": 1000.0 * i, "eval/episode_success": v} for i, v in enumerate(values)]
    rows.insert(3, {"step": 2500.0})  # a training row without an evaluation
    got = success_course(rows)
    assert got["first_success_step"] == 2000 and got["falls"] == 2
    assert got["success_curve"] == values and got["curve_steps"][-1] == 8000
    assert success_course(rows[:2])["first_success_step"] is None


def test_the_richest_evaluation_beside_the_most_successful():
    """``richest_evaluation``: the evaluation of the highest return and the one of the best
    success, with their readings over the band and touching steps; training rows without an
    evaluation are skipped, and a run without one gives None."""
    from benchmarks.training_diagnosis import richest_evaluation

    def row(step, success, ret, over, touching):
        return {"step": step, "eval/episode_success": success, "eval/episode_reward": ret,
                "eval/episode_overforce": over, "eval/episode_touching": touching,
                "eval/episode_streak": touching - 1.0}  # fmt: skip

    rows = [row(0.0, 0.0, -1400.0, 0.0, 0.0), row(1e6, 0.92, 840.0, 0.0, 3.0),
            {"step": 1.5e6}, row(2e6, 0.13, 5150.0, 1.6, 81.0)]  # fmt: skip
    got = richest_evaluation(rows)
    assert got["richest"]["step"] == 2_000_000 and got["richest"]["overforce"] == 1.6
    assert got["most_successful"] == {"step": 1_000_000, "success": 0.92, "episode_return": 840.0,
                                      "overforce": 0.0, "touching": 3.0, "streak": 2.0}  # fmt: skip
    assert richest_evaluation([{"step": 0.0}]) == {"richest": None, "most_successful": None}


def test_a_brief_reads_the_evaluated_rows_alone(tmp_path):
    """Epochs before ``eval_from_step`` log training figures alone: a run stopped before its
    first evaluation has "no evaluation yet", and one stopped after an unevaluated epoch
    reads its best, last and trap from the evaluated rows, in the brief and the diagnosis."""
    from benchmarks.campaign_brief import brief
    from benchmarks.training_diagnosis import seed_record

    _run(tmp_path, 1, 0.5, 31.9, 0.1, budget=30_000_000)
    path = tmp_path / "touch-fast-seed1" / "metrics.csv"
    lines = path.read_text().splitlines()
    unevaluated = "2000,,,,,,,0.1,0.3"
    path.write_text("\n".join([*lines, unevaluated]) + "\n")
    line, state = brief(tmp_path / "touch-fast-seed1", 0.95)
    assert state == "stopped" and "best 0.500 last 0.500 stopped at 0.0M steps" in line
    assert line.endswith("(so far tapping)")
    record = seed_record(tmp_path / "touch-fast-seed1", 0.95)  # the diagnosis reads them too
    assert (record["trap"], record["touching_last"], record["last_step"]) == ("tapping", 31.9, 2000)
    assert record["best_success"] == record["last_success"] == 0.5 and record["stopped"]
    path.write_text("\n".join([lines[0], unevaluated]) + "\n")
    line, state = brief(tmp_path / "touch-fast-seed1", 0.95)
    assert state == "stopped"
    assert line.endswith("/touch-fast-seed1: no evaluation yet (stopped at 0.0M steps)")


def test_a_brief_counts_each_run_solved_where_its_task_is(tmp_path):
    """Without --threshold, ``campaign_brief`` takes each run's task from its config: a Lift
    run at 0.92 counts as solved (Lift's 0.9), a Touch run at 0.92 does not (0.95)."""
    from benchmarks.campaign_brief import run_threshold

    for task, seed in (("lift", 1), ("touch", 2)):
        _run(tmp_path, seed, 0.92, 3.0, 2.0)
        config = tmp_path / f"touch-fast-seed{seed}" / "config.json"
        data = json.loads(config.read_text())
        config.write_text(json.dumps({"train": {**data["train"], "task": task}}))
    assert run_threshold(tmp_path / "touch-fast-seed1", None) == 0.9
    assert run_threshold(tmp_path / "touch-fast-seed2", None) == 0.95
    assert run_threshold(tmp_path / "touch-fast-seed2", 0.5) == 0.5
    assert run_threshold(tmp_path / "nowhere", None) == 0.95


def test_eval_from_step_is_chosen_one_epoch_short_of_the_earliest_tuning_solve():
    """``choose_eval_from_step``: with epochs every 1.06M steps and the earliest solve at the
    sixth, the fifth stays evaluated and the value is the roundest step after the fourth; the
    shipped Touch value comes out of its tuning report; fresh seeds are refused."""
    from benchmarks.choose_eval_from_step import _curves, choose, main, round_step

    assert round_step(4_259_840, 5_324_800) == 5_000_000
    assert round_step(1_000_000, 1_146_880) == 1_100_000  # one digit would not pass the low end
    assert round_step(0, 573_440) == 500_000
    epoch = 1_064_960
    early = [(i * epoch, 0.0) for i in range(5)] + [(5 * epoch, 0.4), (6 * epoch, 0.96)]
    late = [(i * epoch, 0.01) for i in range(9)] + [(9 * epoch, 0.99)]
    got = choose({1000: early, 1001: late}, 0.95)
    assert (got["eval_from_step"], got["first_kept_evaluation"]) == (5_000_000, 5 * epoch)
    assert got["best_success_before_it"] == 0.01 and got["evaluations_skipped_per_run"] == 5
    seeds = Path(__file__).parent.parent / "benchmarks" / "results" / "seeds"
    report = seeds / "tuning" / "seeds_touch_fast_tuning_nopay.json"
    assert choose(*_curves([json.loads(report.read_text())]))["eval_from_step"] == 5_000_000
    fresh = seeds / "fresh" / "seeds_touch_fast_fresh_8036.json"
    with pytest.raises(SystemExit, match="not a tuning seed"):
        main([str(fresh)])


def _gate_run(folder: Path, seed: int, rows: list[tuple[int, float, float]]) -> Path:
    """A run directory of ``seed`` whose evaluations are ``(step, success, training rate)``
    (step 0: the initial policy, no training rate), each taking 1.5 s."""
    folder.mkdir(parents=True)
    train = {"seed": seed, "stop_at_success": 0.9}
    (folder / "config.json").write_text(json.dumps({"train": train}))
    lines = ["step,eval/episode_success,training/episode_success,eval/epoch_eval_time"]
    lines += [f"{s},{x},{'' if s == 0 else r},1.5" for s, x, r in rows]
    (folder / "metrics.csv").write_text("\n".join(lines) + "\n")
    return folder


def test_eval_gate_is_half_the_lowest_training_rate_at_a_tuning_solve(tmp_path: Path) -> None:
    """``choose_eval_gate``: seed 1000 solved where its training episodes succeeded at 0.5,
    1001 at 0.37, so the gate is 0.18; the evaluations under it before each solve (the initial
    policy's included) are the ones skipped. A fresh seed is refused."""
    from benchmarks.choose_eval_gate import choose, main, read_run, run_dirs

    runs = tmp_path / "runs"
    _gate_run(runs / "a", 1000, [(0, 0, 0), (1, 0.0, 0.02), (2, 0.3, 0.2), (3, 0.92, 0.5)])
    rows = [(0, 0, 0), (1, 0.0, 0.0), (2, 0.0, 0.1), (3, 0.1, 0.17), (4, 0.95, 0.37)]
    _gate_run(runs / "b", 1001, rows)
    seed, threshold, evaluations = read_run(runs / "b")
    assert (seed, threshold, len(evaluations)) == (1001, 0.9, 5)
    assert evaluations[0].rate != evaluations[0].rate and evaluations[-1].rate == 0.37  # NaN
    got = choose({read_run(p)[0]: read_run(p)[2] for p in run_dirs([runs])}, 0.9)
    assert got["eval_gate"] == 0.18 and got["lowest_rate_at_a_solve"] == 0.37
    # 1000 skips the initial policy and step 1 (2 evaluations), 1001 the initial policy and
    # steps 1-3: a median of 3 evaluations, 4.5 s
    assert got["evaluations_skipped_per_solved_run"] == 3
    assert got["seconds_saved_per_solved_run"] == 4.5
    # from step 2 on, 1000 skips nothing (its step 2 trained at 0.2) and 1001 steps 2 and 3
    later = choose({read_run(p)[0]: read_run(p)[2] for p in run_dirs([runs])}, 0.9, 2)
    assert later["eval_gate"] == 0.18 and later["evaluations_skipped_per_solved_run"] == 1
    assert later["seconds_saved_per_solved_run"] == 1.5
    assert main([str(runs), "--out", str(tmp_path / "out"), "--name", "gate"]) == 0
    saved = json.loads((tmp_path / "out" / "gate.json").read_text())
    assert saved["choice"]["eval_gate"] == 0.18 and len(saved["runs"]["1001"]) == 5
    assert saved["runs"]["1000"][3] == {"step": 3, "success": 0.92, "rate": 0.5, "seconds": 1.5}
    _gate_run(tmp_path / "fresh" / "c", 8600, rows)
    with pytest.raises(SystemExit, match="not a tuning seed"):
        main([str(tmp_path / "fresh")])


def _lift_run(folder: Path, seed: int, rows: list[tuple[float, float, float, float]]) -> None:
    """A Lift run directory whose evaluations are ``(success, strike share, height sum, grasp
    sum)`` over 40-step episodes, one per million steps."""
    run = folder / f"lift-fast-seed{seed}"
    run.mkdir(parents=True)
    (run / "config.json").write_text(json.dumps({"train": {"seed": seed}}))
    names = ["step", "eval/episode_success", "eval/episode_strike", "eval/episode_lift_height",
             "eval/episode_grasp", "eval/avg_episode_length", "training/approx_kl"]  # fmt: skip
    lines = [",".join(names)]
    lines += [f"{i * 10**6},{s},{k},{h},{g},40,0.5" for i, (s, k, h, g) in enumerate(rows, 1)]
    (run / "metrics.csv").write_text("\n".join(lines) + "\n")


def test_lift_falls_are_found_and_told_apart(tmp_path: Path) -> None:
    """``lift_falls``: a drop of 0.3 or more from 0.3 or more is a fall. One whose strike
    share rose by 0.2 is a strike; one whose cube rode higher with half the grasp, a lift
    without grasp; a smaller drop, or one from under 0.3, is none."""
    from benchmarks.lift_falls import campaign, main, summary

    _lift_run(tmp_path / "a", 1000, [(0.2, 0.0, 0, 0), (0.0, 0.0, 0, 0), (0.8, 0.1, 4, 16),
                                     (0.2, 0.6, 1, 4), (0.9, 0.0, 4, 16)])  # fmt: skip
    _lift_run(tmp_path / "a", 1001, [(0.7, 0.1, 4, 16), (0.3, 0.1, 12, 4), (0.5, 0.1, 4, 16),
                                     (0.3, 0.1, 4, 16)])  # fmt: skip
    got = campaign("a", [tmp_path / "a"])
    assert got["runs"] == 2 and [f["step"] for f in got["falls"][1000]] == [4 * 10**6]
    strike, lifted = got["falls"][1000][0], got["falls"][1001][0]
    assert strike["kind"] == "strike" and strike["before"]["grasp"] == 0.4
    assert lifted["kind"] == "lift without grasp" and lifted["after"]["height"] == 0.3
    assert len(got["falls"][1001]) == 1  # 0.5 -> 0.3 is under the fall's 0.3
    counts = summary([got])
    assert counts == {"runs": 2, "runs_with_a_fall": 2, "falls": 2,
                      "kinds": {"strike": 1, "lift without grasp": 1, "other": 0}}  # fmt: skip
    assert main(["--campaign", f"a={tmp_path / 'a'}", "--out", str(tmp_path), "--name", "f"]) == 0
    assert json.loads((tmp_path / "f.json").read_text())["summary"] == counts
