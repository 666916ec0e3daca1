"""The headline figures: the README's table and the top of the results index.

Each :class:`Headline` reads named result files and gives one row (figure, value, sources);
the device and date come from the first source's ``meta``. A row whose files are gone or
changed shape is left out, not an error, so renaming a result file never breaks the build.
"""

from __future__ import annotations

import json
import statistics
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from result_kinds import Json, date, device, fmt, secs

BEGIN = "<!-- headline:begin (made by docs/gen_results.py from benchmarks/results; do not edit) -->"
END = "<!-- headline:end -->"


@dataclass(frozen=True)
class Headline:
    """One headline row: ``read(load)`` gives (figure, value, source files); ``load(rel)``
    reads a result file."""

    read: Callable[[Callable[[str], Json]], tuple[str, str, list[str]]]


# Rows whose Touch `fast` figures were measured before that preset's fixed wrench scale
# (normalizer.force_scale, commit 2b611b0) and its end of press pay after a reading over the band
# (task.pay_after_overforce, commit 0988846) changed how Touch trains.
BEFORE_TOUCH_CHANGES = (
    " (its Touch `fast` training predates the preset's fixed wrench scale and press pay rule of "
    "2b611b0 and 0988846)"
)


def _before_touch_changes(row: Headline) -> Headline:
    """``row`` with :data:`BEFORE_TOUCH_CHANGES` after its figure."""

    def read(load: Callable[[str], Json]) -> tuple[str, str, list[str]]:
        figure, value, rels = row.read(load)
        return figure + BEFORE_TOUCH_CHANGES, value, rels

    return Headline(read)


def _seeds_row(task: str, rel: str, what: str, warm: bool | None = True) -> Headline:
    """A seeds run: seeds solved and the median time, of the warm seeds (started after a seed
    had ended: the others paid for empty caches) or of all; ``warm=None``: no time (runs that
    shared a GPU)."""

    def read(load: Callable[[str], Json]) -> tuple[str, str, list[str]]:
        s = load(rel)["summary"]
        ci = s.get("fraction_solved_ci95")
        ci = f" (95% interval {ci[0]:.2f}-{ci[1]:.2f})" if ci else ""
        value = f"{s['solved']} of {s['seeds']} seeds at {fmt(s['threshold'])}{ci}"
        if "collapsed" in s:
            value += f", {len(s['collapsed'])} collapsed"
        if warm is not None:
            key = "time_to_threshold_warm" if warm else "time_to_threshold_all"
            when = f"{secs((s.get(key) or {}).get('median'))} {'warm' if warm else 'all seeds'}"
            value += f"; median {when}"
        if warm and s.get("time_to_threshold_p90_warm"):
            value += f", 90th percentile {secs(s['time_to_threshold_p90_warm'])}"
        return f"{task}: {what}", value, [rel]

    return Headline(read)


def _transfer_row(task: str, rels: list[str], keys: tuple[str, ...]) -> Headline:
    def read(load: Callable[[str], Json]) -> tuple[str, str, list[str]]:
        parts = []
        for key in keys:
            rates = [r["success_rate"] for rel in rels for r in load(rel)["rows"]
                     if r.get("key") == key]  # fmt: skip
            label = next(r["label"] for r in load(rels[0])["rows"] if r.get("key") == key)
            parts.append(f"{label} {min(rates):.3f}-{max(rates):.3f}")
        return f"{task}: transfer of {len(rels)} policies, success", "; ".join(parts), rels

    return Headline(read)


def _throughput_row(load: Callable[[str], Json]) -> tuple[str, str, list[str]]:
    rel = "warp/mjx_throughput_touch_impls.json"
    data = load(rel)
    best = max(data["rows"], key=lambda r: r["env_control_steps_per_s"])
    ratio = data["warp_over_jax"][str(best["batch"])]
    value = (f"{fmt(best['env_control_steps_per_s'])} control steps/s at "
             f"{fmt(best['batch'])} envs ({best['impl']}, {fmt(ratio)}x JAX)")  # fmt: skip
    return "Touch: MJX env steps per second", value, [rel]


def _parity_row(load: Callable[[str], Json]) -> tuple[str, str, list[str]]:
    rel = "parity/parity.json"
    goals = load(rel)["goals"]
    fk = max(g["value"] for g in goals if g["check"].startswith("forward kinematics"))
    div = [g["value"] for g in goals if g["check"].startswith("joint divergence at 1 s")]
    met = sum(1 for g in goals if g["met"])
    value = (
        f"FK within {fmt(fk)} m; joint divergence at 1 s (median) "
        f"{fmt(min(div))}-{fmt(max(div))} rad; {met} of {len(goals)} goals met"
    )
    return "Engine parity (C MuJoCo, MJX, PyBullet)", value, [rel]


def _cpu_row(load: Callable[[str], Json]) -> tuple[str, str, list[str]]:
    rel = "cpu/cpu_envs.json"
    cases = load(rel)["cases"]
    value = "; ".join(f"{case} {fmt(c['env_steps_per_s']['median'])} steps/s "
                      f"({fmt(c['ratio'], 2)} of raw)" for case, c in cases.items())  # fmt: skip
    return "Gymnasium envs on the CPU, one env", value, [rel]


def _fuzz_row(load: Callable[[str], Json]) -> tuple[str, str, list[str]]:
    urdf, inputs = load("fuzz/urdf_fuzz.json"), load("fuzz/input_fuzz.json")
    crashes = sum(k.get("crash", 0) for k in urdf["by_kind"].values())
    total = inputs["by_command"]["all"]  # the sum of the commands' rows
    tracebacks = total.get("traceback", 0)
    outside = total.get("outside")
    outside = "" if outside is None else f", {outside} files changed outside their outputs"
    value = (
        f"{fmt(urdf['mutations'])} mutated URDFs: {crashes} crashes; "
        f"{fmt(inputs['cases'])} command lines: {tracebacks} tracebacks{outside}"
    )
    return "Hostile URDFs and bad inputs", value, ["fuzz/urdf_fuzz.json", "fuzz/input_fuzz.json"]


# Arms of the any-arm runs whose converted model let links pass through the table (a URDF
# root named ``world``: benchmarks/results/arms/any_arm/README.md); not trained again since.
TRAINED_BEFORE_WORLD_FIX = frozenset({"ur5_robot", "ur5_joint_limited_robot"})


def _any_arm_row(load: Callable[[str], Json]) -> tuple[str, str, list[str]]:
    parts = []
    for e in _merged_entries(load, ANY_ARM_SUMMARIES):  # a later run of a seed replaces it
        moved = [s["transfer"] for s in e["seeds"] if s["solved"] and s["transfer"]]
        low = min((min(v[0] for v in t.values()) for t in moved), default=None)
        worst = f", exported >= {low:.3f}" if low is not None else ""
        stale = " (trained before the table-contact fix)" * (e["arm"] in TRAINED_BEFORE_WORLD_FIX)
        parts.append(f"{e['arm']} {e['task']} {e['solved']}/{len(e['seeds'])}{worst}{stale}")
    figure = "Published arms, no arm file: seeds solved, lowest transfer of a solved seed"
    return figure, "; ".join(parts), list(ANY_ARM_SUMMARIES)


def _merged_entries(load: Callable[[str], Json], rels: tuple[str, ...]) -> list[Json]:
    """The (arm, task) entries of ``summarize_seeds`` files, their seeds merged by number (a
    later file's seed replaces an earlier one's); solved counts follow the merged seeds."""
    merged: dict[tuple[str, str], Json] = {}
    for rel in rels:
        for e in load(rel)["entries"]:
            old = merged.get((e["arm"], e["task"]), {"seeds": []})
            seeds = {s["seed"]: s for s in old["seeds"]} | {s["seed"]: s for s in e["seeds"]}
            ordered = [seeds[k] for k in sorted(seeds)]
            solved = sum(s["solved"] for s in ordered)
            merged[(e["arm"], e["task"])] = {**e, "seeds": ordered, "solved": solved}
    return list(merged.values())


def _summary_row(rels: tuple[str, ...], figure: str, task: str | None = None) -> Headline:
    """Seeds solved and their exported policies' transfer, from ``summarize_seeds`` files (their
    one entry, or the entry of ``task``; seeds merged over the files)."""

    def read(load: Callable[[str], Json]) -> tuple[str, str, list[str]]:
        (entry,) = [e for e in _merged_entries(load, rels) if task is None or e["task"] == task]
        seeds = entry["seeds"]
        parts = [f"{entry['solved']} of {len(seeds)} seeds at {fmt(entry['threshold'])} "
                 f"(seeds {', '.join(str(s['seed']) for s in seeds)})"]  # fmt: skip
        for engine, label in (("mujoco", "CPU MuJoCo"), ("pybullet", "PyBullet")):
            rates = [s["transfer"][engine] for s in seeds if engine in s["transfer"]]
            if rates:
                low, high = min(r[0] for r in rates), max(r[0] for r in rates)
                peak = max(r[1] for r in rates)
                parts.append(f"{label} {low:.3f}-{high:.3f} (mean peak up to {peak:.0f} N)")
        return figure, "; ".join(parts), list(rels)

    return Headline(read)


def _pick_row(load: Callable[[str], Json]) -> tuple[str, str, list[str]]:
    """Lift on the Panda beside Playground's PandaPickCube (``benchmarks/summarize_pick.py``)."""
    rel = PICK_COMPARISON
    parts = []
    for side, label in (("mjx_arm", "this project"), ("Playground", "Playground")):
        rows = [r for r in load(rel)["rows"] if r["side"].startswith(side)]
        times = [secs(r["time_to_threshold_s"]) for r in rows if r["reached"]]
        reached = sum(r["reached"] for r in rows)
        parts.append(f"{label}: {reached} of {len(rows)} seeds at {fmt(rows[0]['threshold'])}"
                     f" in {', '.join(times) or 'none'}")  # fmt: skip
    figure = "Lift on the Panda's own hand beside Playground's PandaPickCube (first seed cold)"
    return figure, "; ".join(parts), [rel]


def _cold_row(load: Callable[[str], Json]) -> tuple[str, str, list[str]]:
    rels = [f"cold_start/cold_start_fast_{name}.json" for name in ("touch", "lift", "arm")]
    parts = []
    for rel in rels:
        for row in load(rel)["rows"]:
            when = row.get("time_to_threshold_s") or row.get("first_epoch_done_s")
            if when is None or row["start"] == "warmup command":
                continue
            what = "to threshold" if row.get("time_to_threshold_s") else "first epoch"
            parts.append(f"{row['task']} {row['arm']} {row['start']}: {what} {secs(when)}")
    return "Start-up, every cache empty (cold) and after", "; ".join(parts), rels


def _group_row(load: Callable[[str], Json]) -> tuple[str, str, list[str]]:
    rel = "scaling/server_group_reach_tiny.json"
    data = load(rel)
    s = data["summary"]
    value = (
        f"new processes per command {secs(s['processes']['median_wall_s'])}, the warm group "
        f"{secs(s['group, warm']['median_wall_s'])} ({fmt(s['warm_over_processes'], 2)}x; its "
        f"first command {secs(s['group, first command']['median_wall_s'])}); each seed's two "
        f"runs identical, bit for bit: {sum(data['identical'])} of {len(data['identical'])}"
    )
    figure = (
        "A training on two devices per command (`train --devices 2`, the CPU preset cut down "
        "to three epochs; two CPU processes joined through gloo), new processes each time "
        "against a warm trainer of two (`mjx-arm serve --devices 2`), median from the "
        "command's start to its exit"
    )
    return figure, value, [rel]


def _robustness_row(load: Callable[[str], Json]) -> tuple[str, str, list[str]]:
    """Per group of shipped policies: perturbations held at the goal and the joint draw."""
    parts, rels = [], []
    for label, files in ROBUSTNESS_GROUPS:
        held, joint = [], []
        for rel in files:
            summary = load(rel)["summary"]
            held.append(sum(v["goal_met"] for v in summary["per_perturbation"].values()))
            joint.append(summary["joint_success"])
            total = len(summary["per_perturbation"])
        held_text = ", ".join(str(h) for h in held)
        draw = f"{min(joint):.2f}" + (f"-{max(joint):.2f}" if len(joint) > 1 else "")
        parts.append(f"{label}: {held_text} of {total} held at 0.9, joint draw {draw}")
        rels += files
    return (
        "Robustness of shipped policies (goals: 0.9 per point, joint draw 0.85)",
        "; ".join(parts),
        rels,
    )


ANY_ARM_SUMMARIES = (
    "arms/any_arm/final/summary.json",
    "arms/any_arm/z1/summary.json",
    "arms/any_arm/cradle/summary.json",
    "arms/any_arm/variants/summary.json",
    "arms/any_arm/touch_ur10_joint_limited/summary.json",
    "arms/any_arm/pick/summary.json",
)
PICK_COMPARISON = "arms/any_arm/pick/comparison.json"
LIFT_SUMMARIES = ("lift/seeds_stray_charge/summary.json",)
ROBUST_LIFT_SUMMARY = ("robustness/robust_seeds_lift_stray/summary.json",)
ROBUST_TOUCH_SUMMARY = ("robustness/robust_seeds/summary.json",)
ROBUSTNESS_GROUPS = (
    ("Lift robust", [f"robustness/robustness_lift_robust_stray_seed{i}.json" for i in range(3)]),
    ("Lift fast", [f"robustness/robustness_lift_fast_stray_seed{i}.json" for i in (61, 74)]),
    ("Touch robust", [f"robustness/robustness_touch_robust_seed{i}.json" for i in range(5)]),
    ("Touch fast", ["robustness/robustness_touch_fast_seed0.json"]),
)
TOUCH_TRANSFER = [f"contact/transfer/touch_fast_seed{i}.json" for i in range(3)]
# The five fresh Touch seeds of seeds_touch_fast_fresh_7864 that stopped lowest (0.950-0.959)
TOUCH_FRESH_TRANSFER = [
    f"contact/transfer/touch_fast_stop095_seed{i}.json" for i in (7880, 7873, 7892, 7865, 7870)
]
# ... and of seeds_lift_fast_fresh_7660 (0.917-0.920)
LIFT_FRESH_TRANSFER = [
    f"contact/transfer/lift_fast_stop090_seed{i}.json" for i in (7671, 7674, 7668)
]
GPU_SEEDS = ("scaling/seeds_touch_fast_2gpu_of_2.json", "scaling/seeds_touch_fast_1gpu_of_2.json")


def _gpu_seeds_row(load: Callable[[str], Json]) -> tuple[str, str, list[str]]:
    """The seeds benchmark with one seed per GPU at once beside the same seeds on one GPU."""
    many, one = (load(rel)["summary"] for rel in GPU_SEEDS)
    gpus = len(many["gpus"])
    value = (
        f"{many['seeds']} seeds on {gpus} GPUs at once {secs(many['wall_s'])} "
        f"({many['solved']} solved), one after another on 1 GPU {secs(one['wall_s'])} "
        f"({one['solved']} solved): {many['wall_s'] / one['wall_s']:.2f}x the wall time"
    )
    return "Touch `--preset fast` seeds, one process per GPU", value, list(GPU_SEEDS)


# Touch seeds trained on two GPUs each through a warm group (the preset's batch split over the
# GPUs, as shipped; then grown with them), and fresh seeds on one GPU's warm trainer
TWO_GPU_SEEDS = (
    "seeds/fresh/seeds_touch_fast_fresh_8530_2gpu_split_server.json",
    "seeds/fresh/seeds_touch_fast_fresh_8200_server.json",
    "seeds/fresh/seeds_touch_fast_fresh_8500_2gpu_server.json",
)


def _warm_solved(load: Callable[[str], Json], rel: str) -> list[Json]:
    """The warm seeds of a seeds report that reached its threshold."""
    return [r for r in load(rel)["seeds"] if r.get("warm") and r["time_to_threshold"]]


def _two_gpu_seeds_row(load: Callable[[str], Json]) -> tuple[str, str, list[str]]:
    """Touch on 2 GPUs per seed: solve rate, and its warm median beside the one-GPU campaign's
    (steps to the threshold and env steps/s as the causes), then the grown batch's; medians
    over each file's warm solved seeds."""
    summary = load(TWO_GPU_SEEDS[0])["summary"]
    two, one, grown = (_warm_solved(load, rel) for rel in TWO_GPU_SEEDS)

    def median(runs: list[Json], key: str) -> float:
        return statistics.median(r[key] for r in runs)

    def ratio(runs: list[Json], key: str) -> float:
        return median(runs, key) / median(one, key)

    t1 = median(one, "time_to_threshold")
    value = (
        f"{summary['solved']} of {summary['seeds']} seeds at {fmt(summary['threshold'])}; warm "
        f"median {secs(median(two, 'time_to_threshold'))} ({len(two)} seeds) against "
        f"{secs(t1)} on one GPU ({len(one)} seeds, "
        f"{ratio(two, 'time_to_threshold'):.2f}x): {ratio(two, 'training_steps_per_s'):.2f}x "
        f"the env steps/s, {ratio(two, 'steps_to_threshold'):.2f}x the steps. The batch grown "
        f"with the GPUs (`--set scale_with_devices=true`, seeds 8500-8509): "
        f"{secs(median(grown, 'time_to_threshold'))} ({ratio(grown, 'time_to_threshold'):.2f}x), "
        f"{ratio(grown, 'steps_to_threshold'):.2f}x the steps"
    )
    what = (
        "Touch: `--preset fast` on 2 H200s per seed (`train --devices 2 --server`, a warm "
        "group of both GPUs, the preset's batch split over them: the default since, run then "
        "with `--set scale_with_devices=false`), fresh seeds 8530-8540, beside fresh seeds "
        "8200-8255 on one H200's warm trainer, time from the command's start"
    )
    return what, value, list(TWO_GPU_SEEDS)


GPU_SCALING = (
    "scaling/throughput_touch_1_2_4gpu_h100x4.json",
    "scaling/solve_touch_1_2gpu_h100x2.json",
    "scaling/solve_touch_4gpu_h100x4.json",
)


def _gpu_scaling_row(load: Callable[[str], Json]) -> tuple[str, str, list[str]]:
    """Training steps/s at 8,192 envs per GPU on 1, 2 and 4 GPUs (a process per GPU), and
    Touch's time to its threshold with the fast preset's global batch split over them."""
    runs = load(GPU_SCALING[0])["runs"]
    one = runs["1"]["steps_per_s"]
    speeds = ", ".join(
        f"{d} GPU{'s' if d != '1' else ''} {fmt(r['steps_per_s'])} ({r['steps_per_s'] / one:.2f}x)"
        for d, r in sorted(runs.items(), key=lambda item: int(item[0]))
    )
    solve = {}
    for rel in GPU_SCALING[1:]:
        data = load(rel)
        for d, s in data["summary"].items():
            solve[d] = {**s, "limit_s": data["settings"]["limit"]}
    times = "; ".join(
        f"{d} GPU{'s' if d != '1' else ''} {s['solved']} of {s['seeds']} seeds"
        + (f", median {secs(s['median_s'])}" if s["median_s"] is not None else "")
        + (f" (runs stopped at {secs(s['limit_s'])})" if s["solved"] < s["seeds"] else "")
        for d, s in sorted(solve.items(), key=lambda item: int(item[0]))
    )
    value = f"env steps/s at 8,192 envs per GPU: {speeds}. Touch to 0.95: {times}"
    return "Training on several GPUs, a process per GPU", value, list(GPU_SCALING)


def _arm_group(load: Callable[[str], Json], label: str, seeds: tuple[str, ...],
               transfers: tuple[str, ...]) -> str:  # fmt: skip
    """``label N/M`` over the seeds files, then each engine's lowest transfer and highest mean
    peak force over the transfer files."""
    summaries = [load(rel)["summary"] for rel in seeds]
    solved, total = sum(s["solved"] for s in summaries), sum(s["seeds"] for s in summaries)
    rows = [r for rel in transfers for r in load(rel)["rows"]]
    engines = []
    for key in dict.fromkeys(r["key"] for r in rows):
        mine = [r for r in rows if r["key"] == key]
        peak = max(r["mean_peak_contact_force"] for r in mine)
        engines.append(f"{mine[0]['engine']} >= {min(r['success_rate'] for r in mine):.3f} "
                       f"(peak <= {peak:.0f} N)")  # fmt: skip
    return f"{label} {solved}/{total}" + (f", exported {', '.join(engines)}" if engines else "")


ArmGroup = tuple[str, tuple[str, ...], tuple[str, ...]]  # label, seeds files, transfer files


def _arm_groups_row(
    figure: str,
    groups: tuple[ArmGroup, ...],
    extra: Callable[[Callable[[str], Json]], str] | None = None,
) -> Headline:
    """Seeds solved per arm and the lowest transfer per engine of its policies."""

    def read(load: Callable[[str], Json]) -> tuple[str, str, list[str]]:
        value = "; ".join(_arm_group(load, *group) for group in groups)
        if extra is not None:
            value += f". {extra(load)}"
        rels = [rel for _, seeds, transfers in groups for rel in (*seeds, *transfers)]
        return figure, value, rels

    return Headline(read)


LINKAGE = "arms/linkage/"
LINKAGE_GROUPS = (
    ("2F-85 class", (f"{LINKAGE}seeds_lift_fast_ur5e_2f85.json",
                     f"{LINKAGE}seeds_lift_fast_ur5e_2f85_seed1.json"),
     tuple(f"{LINKAGE}transfer_lift_ur5e_2f85_seed{s}.json" for s in (0, 1))),
    ("xArm-gripper class", (f"{LINKAGE}seeds_lift_fast_ur5e_xarm_gripper.json",),
     tuple(f"{LINKAGE}transfer_lift_ur5e_xarm_gripper_seed{s}.json" for s in (0, 1))),
)  # fmt: skip
SEVEN = "arms/seven_joint/"
SEVEN_GROUPS = tuple(
    (label, (f"{SEVEN}seeds_touch_fast_{name}.json",),
     tuple(f"{SEVEN}transfer_touch_{stem}_seed{s}.json" for s in (0, 1, 2)))
    for label, name, stem in (("panda", "panda_mesh_warm", "panda"),
                              ("panda on capsules", "panda_capsules", "panda_capsules"),
                              ("xarm7 on capsules", "xarm7_capsules", "xarm7_capsules"))
)  # fmt: skip

SMALL = "arms/small_and_grippers/"
SMALL_GROUPS = (
    ("SO-101 reach", (f"{SMALL}seeds_reach_fast_so101_call1.json",),
     tuple(f"{SMALL}transfer_reach_so101_seed{s}.json" for s in (0, 1))),
    ("SO-101 touch", (f"{SMALL}seeds_touch_fast_so101_raised_home_shared_gpu.json",),
     tuple(f"{SMALL}transfer_touch_so101_raised_seed{s}.json" for s in (0, 1))),
    ("SO-101 lift", (f"{SMALL}seeds_lift_fast_so101_grip5mm.json",),
     tuple(f"{SMALL}transfer_lift_so101_seed{s}.json" for s in (0, 1))),
)  # fmt: skip
MESH_PAD_GROUPS = (
    ("xArm6 touch", (f"{SMALL}seeds_touch_fast_xarm6_table_collides.json",),
     tuple(f"{SMALL}transfer_touch_xarm6_seed{s}.json" for s in (0, 1))),
    ("xArm6 lift", (f"{SMALL}seeds_lift_fast_xarm6_gate_s0_shared_gpu.json",
                    f"{SMALL}seeds_lift_fast_xarm6_gate_s1.json"),
     tuple(f"{SMALL}transfer_lift_xarm6_gate_seed{s}.json" for s in (0, 1))),
)  # fmt: skip


def _seven_compile(load: Callable[[str], Json]) -> str:
    rows = load(f"{SEVEN}compile_cold_mesh_vs_capsules.json")["rows"]
    return "Cold compile: " + ", ".join(f"{r['arm']} {secs(r['compile_s'])}" for r in rows)


HEADLINES: tuple[Headline, ...] = (
    _seeds_row(
        "Touch",
        "seeds/fresh/seeds_touch_fast_fresh_8036.json",
        "`--preset fast` as shipped, 25 fresh seeds (8036-8047, 8054-8066), one H200 per seed "
        "(two at once, one per GPU of a host of two), one process per seed, time from the "
        "command's start",
    ),
    _seeds_row(
        "Touch",
        "seeds/fresh/seeds_touch_fast_fresh_8200_server.json",
        "`--preset fast` as shipped, each seed's `train --server` command run by the warm "
        "trainer (`mjx-arm serve`, one per H200 of a host of two: `bench seeds --server`), 52 "
        "fresh seeds (8200-8225, 8230-8255), time from the command's start; warm: its GPU's "
        "server had trained a seed before",
    ),
    Headline(_two_gpu_seeds_row),
    _seeds_row(
        "Lift",
        "seeds/fresh/seeds_lift_fast_fresh_8700_gate.json",
        "`--preset fast` as shipped (evaluations from 3M steps, of epochs whose training "
        "episodes succeeded at 1% or more) through the warm trainer (`bench seeds --server`, "
        "one per H200 of a host of two), 29 fresh seeds (8700-8735; 3 stopped by the call's "
        "deadline, 4 not started), time from the command's start",
    ),
    _seeds_row(
        "Reach",
        "seeds/fresh/seeds_reach_fast_fresh_8300_server.json",
        "`--preset fast` as shipped through the warm trainer (`bench seeds --server`, one "
        "H200), 20 fresh seeds (8300-8319), time from the command's start",
    ),
    _seeds_row(
        "Lift",
        "seeds/fresh/seeds_lift_fast_fresh_7660.json",
        "`--preset fast` as shipped, 20 fresh seeds (7660-7679), one H200 per seed (two at "
        "once, one per GPU of a host of two), one process per seed, time from the command's start",
    ),
    _seeds_row(
        "Reach",
        "seeds/fresh/seeds_reach_fast_fresh.json",
        "`--preset fast` (then stopping at 0.97: the time to 0.95 is the same), 20 fresh seeds "
        "(7300-7319), one GPU, one process per seed, time from the command's start",
    ),
    _seeds_row("Touch", "seeds/cpu_touch/cpu_fresh_shipped_all.json",
               "`--preset cpu --backend mujoco` as shipped, 20 fresh seeds (7903-7922), time to "
               "threshold", warm=False),
    _seeds_row("Reach", "seeds/cpu_reach/cpu_reach_process.json",
               "`--preset cpu --backend mujoco` as shipped, 3 fresh seeds (7930-7932) in turn in "
               "one process, time to threshold"),
    _seeds_row("Reach", "seeds/cpu_reach/cpu_reach_server.json",
               "`--preset cpu --backend mujoco` as shipped, the same seeds with `bench seeds "
               "--server` (envs and programs kept from seed to seed), time to threshold"),
    _before_touch_changes(_transfer_row("Touch", TOUCH_TRANSFER, ("mujoco", "pybullet"))),
    _transfer_row("Touch, `--preset fast` as shipped, the five fresh seeds of 7864-7899 that "
                  "stopped lowest (0.950-0.959 on the GPU)",
                  TOUCH_FRESH_TRANSFER, ("mujoco", "pybullet")),
    _transfer_row("Lift, `--preset fast` as shipped, the three fresh seeds of 7660-7679 that "
                  "stopped lowest (0.917-0.920 on the GPU)",
                  LIFT_FRESH_TRANSFER, ("mujoco", "pybullet")),
    _before_touch_changes(Headline(_any_arm_row)),
    Headline(_pick_row),
    _arm_groups_row("Lift on the UR5e with a linkage gripper, `--preset fast` as shipped",
                    LINKAGE_GROUPS),
    _before_touch_changes(_arm_groups_row("Touch on 7-joint arms, `--preset fast` as shipped",
                                        SEVEN_GROUPS, _seven_compile)),
    _before_touch_changes(_arm_groups_row(
        "Small arm with a one-jaw gripper, `--preset fast` as shipped, no arm file beyond "
        "`repair_inertia` (a crashed seed counts as unsolved)", SMALL_GROUPS)),
    _before_touch_changes(_arm_groups_row(
        "Published arm with a linkage gripper whose finger collisions are meshes "
        "(pybullet_data's xArm6), `--preset fast` as shipped, no arm file beyond "
        "`repair_inertia`", MESH_PAD_GROUPS)),
    _summary_row(LIFT_SUMMARIES, "Lift: `--preset fast` as shipped, seeds and transfer"),
    _summary_row(ROBUST_LIFT_SUMMARY, "Lift: `--preset robust` as shipped, seeds and transfer"),
    _summary_row(ROBUST_TOUCH_SUMMARY, "Touch: `--preset robust` as shipped, seeds and transfer",
                 task="touch"),
    _before_touch_changes(Headline(_robustness_row)),
    _before_touch_changes(Headline(_cold_row)),
    Headline(_group_row),
    _before_touch_changes(Headline(_gpu_seeds_row)),
    _before_touch_changes(Headline(_gpu_scaling_row)),
    Headline(_throughput_row),
    Headline(_parity_row),
    Headline(_cpu_row),
    Headline(_fuzz_row),
)  # fmt: skip


def _rows(results: Path, link_prefix: str) -> list[list[str]]:
    """Each headline's figure, value, device, date and sources (linked with ``link_prefix``,
    else named)."""

    def load(rel: str) -> Json:
        return json.loads((results / rel).read_text())

    rows = []
    for headline in HEADLINES:
        try:
            figure, value, rels = headline.read(load)
        except (OSError, KeyError, ValueError, TypeError, StopIteration):
            continue  # a file moved or renamed: the row waits for its new name
        meta = load(rels[0]).get("meta") or {}
        source = ", ".join(_source(rel, link_prefix) for rel in rels[:1])
        more = f" (+{len(rels) - 1})" if len(rels) > 1 else ""
        rows.append([figure, value, device(meta), date(meta), source + more])
    return rows


def headline_table(results: Path, link_prefix: str = "") -> list[str]:
    """The headline table (the README's); sources are linked with ``link_prefix`` or named."""
    header = ["figure", "value", "device", "date", "source"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    rows = _rows(results, link_prefix)
    return [*lines, *("| " + " | ".join(str(c) for c in row) + " |" for row in rows), ""]


def headline_list(results: Path) -> list[str]:
    """The headline figures as a definition list (the results index): the same rows as
    :func:`headline_table`, each source on its own line, so nothing runs off a narrow page."""
    lines = []
    for figure, value, dev, day, source in _rows(results, ""):
        lines += [figure, f": {value}", "", f"  *{dev}, {day}*; source {source}", ""]
    return lines


def _source(rel: str, link_prefix: str) -> str:
    if link_prefix:
        return f"[{Path(rel).name}]({link_prefix}{rel})"
    return f"`{rel}`"


def readme_block(results: Path) -> str:
    """The README's generated block, markers included."""
    body = headline_table(results, link_prefix="benchmarks/results/")
    return "\n".join([BEGIN, *body, END])


def update_readme(text: str, results: Path) -> str:
    """``text`` (README.md) with its headline block made again from ``results``."""
    start, end = text.index(BEGIN), text.index(END) + len(END)
    return text[:start] + readme_block(results) + text[end:]
