"""The kinds of result file and how each is rendered as markdown (for ``gen_results.py``).

A :class:`Renderer` tells its kind by the keys a file holds and turns the file into markdown
lines; :data:`RENDERERS` is tried in order and ends with :func:`render_generic`, which takes
any file. Add a kind by writing ``render_KIND`` and a ``Renderer`` before the generic one.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

Json = dict[str, Any]


def fmt(value: Any, digits: int = 3) -> str:
    """A number in at most ``digits`` significant figures (thousands with commas), a list as
    ``a-b`` for pairs, anything else as text; table bars escaped."""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return f"{value:,}"
    if isinstance(value, float):
        if math.isnan(value):
            return "—"  # a figure the run could not make (no episode reached the goal, ...)
        if math.isinf(value):
            return str(value)
        if value != 0 and (abs(value) < 1e-3 or abs(value) >= 1e7):
            return f"{value:.{digits - 1}e}"
        if abs(value) >= 1000:
            return f"{value:,.0f}"
        return f"{value:.{digits}g}"
    if isinstance(value, list | tuple) and len(value) == 2 and all(_is_num(v) for v in value):
        return f"{fmt(value[0], digits)}-{fmt(value[1], digits)}"
    if value is None:
        return ""
    return str(value).replace("|", "\\|").replace("\n", " ")


def _is_num(value: Any) -> bool:
    """A real, finite-or-infinite number (not a bool, not NaN)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and value == value


def table(header: list[str], rows: list[list[Any]]) -> list[str]:
    """A markdown table, cells formatted with :func:`fmt`."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(fmt(c) for c in row) + " |" for row in rows]
    return [*lines, ""]


def device(meta: Json) -> str:
    """``NVIDIA H200`` or ``2-core CPU (AMD EPYC)``, from a file's ``meta``."""
    dev = meta.get("device") or {}
    kind = dev.get("kind") or (meta.get("accelerator") or {}).get("device_kind") or "unknown"
    if str(kind).lower() == "cpu":
        cores = dev.get("cores") or dev.get("cpu_count")
        model = dev.get("cpu_model")
        name = f"{cores}-core CPU" if cores else "CPU"
        return f"{name} ({model})" if model else name
    count = (meta.get("accelerator") or {}).get("device_count") or 1
    return f"{count} x {kind}" if count > 1 else str(kind)


def versions(meta: Json) -> str:
    """``Python 3.11.7; mujoco 4.0.0, jax 0.10.2, ...`` (packages that were installed)."""
    packages = meta.get("packages") or {}
    parts = [f"{name} {ver}" for name, ver in packages.items() if ver]
    head = f"Python {meta['python']}" if meta.get("python") else ""
    return "; ".join(p for p in (head, ", ".join(parts)) if p)


def date(meta: Json) -> str:
    """The run's date, ``YYYY-MM-DD``."""
    return str(meta.get("date", ""))[:10]


def provenance(meta: Json) -> list[str]:
    """The line under each figure's heading: date, device, commit and versions."""
    if not meta:
        return ["*No run metadata in this file.*", ""]
    commit = str(meta.get("git_commit") or "")[:7]
    bits = [f"**{date(meta) or 'undated'}**", device(meta)]
    if commit:
        bits.append(f"commit `{commit}`")
    if meta.get("load_average_1min") is not None:
        bits.append(f"load {meta['load_average_1min']:.2f}")
    return ["Measured " + " · ".join(bits) + f". {versions(meta)}", ""]


# ---------------------------------------------------------------------------------------------
# renderers: one per kind of result file


@dataclass(frozen=True)
class Renderer:
    """A kind of result file: ``matches(data)`` tells it, ``render(data)`` writes markdown."""

    name: str
    matches: Callable[[Json], bool]
    render: Callable[[Json], list[str]]


def _has(*keys: str) -> Callable[[Json], bool]:
    return lambda data: all(k in data for k in keys)


def render_seeds(data: Json) -> list[str]:
    """``mjx-arm bench seeds``: the summary, then one row per seed."""
    s, settings = data["summary"], data.get("settings", {})
    warm, every = s.get("time_to_threshold_warm") or {}, s.get("time_to_threshold_all") or {}
    lines = [
        f"Task **{settings.get('task', '?')}**, preset **{settings.get('preset', '?')}**, "
        f"backend {settings.get('backend', 'auto')}, threshold {fmt(s.get('threshold'))}"
        + (f", overrides `{' '.join(data['overrides'])}`" if data.get("overrides") else "")
        + ".",
        "",
    ]
    lines += table(
        ["seeds solved", "time to threshold, warm: median (IQR)", "all seeds: median",
         "steps to threshold: median", "training steps/s: median"],
        [[f"{s.get('solved')} of {s.get('seeds')}", _iqr(warm), secs(every.get("median")),
          s.get("median_steps_to_threshold"), s.get("median_training_steps_per_s")]],
    )  # fmt: skip
    rows = [
        [r.get("seed"), rate(r.get("best_success")), rate(r.get("final_success")),
         secs(r.get("time_to_threshold")), r.get("steps_to_threshold"),
         secs(r.get("compile_s")), r.get("training_steps_per_s")]
        for r in data.get("seeds", [])
    ]  # fmt: skip
    header = ["seed", "best success", "final success", "time to threshold",
              "steps to threshold", "compile", "training steps/s"]  # fmt: skip
    return lines + table(header, rows)


def secs(value: Any) -> str:
    """Seconds as ``12.3 s``; anything else (a run that never got there) as not reached."""
    return f"{value:.1f} s" if _is_num(value) else "not reached"


def _iqr(stats: Json) -> str:
    if not stats or not _is_num(stats.get("median")):
        return "not reached"
    return f"{stats['median']:.1f} s ({stats['q25']:.1f}-{stats['q75']:.1f} s)"


def render_transfer(data: Json) -> list[str]:
    """``mjx-arm bench transfer``: one policy in several engines."""
    lines = [
        f"Policy `{data.get('policy', '?')}`"
        + (f", trained on {data['trained_on']}" if data.get("trained_on") else "")
        + f"; task {data.get('task', '?')}.",
        "",
    ]
    rows = [
        [r.get("label", r.get("key")), r.get("episodes"), rate(r.get("success_rate")),
         fmt(r.get("success_ci95")), r.get("mean_peak_contact_force"),
         r.get("mean_steps_to_success"), _met(r)]
        for r in data["rows"]
    ]  # fmt: skip
    header = ["engine", "episodes", "success", "95% CI", "mean peak force (N)",
              "steps to success", "goals"]  # fmt: skip
    lines += table(header, rows)
    notes = [n for n in data.get("notes", []) if n]
    return lines + [f"- {fmt(n)}" for n in notes] + ([""] if notes else [])


def _met(row: Json) -> str:
    flags = [row[k] for k in ("success_met", "force_met") if k in row]
    return "" if not flags else ("met" if all(flags) else "missed")


def render_throughput(data: Json) -> list[str]:
    """``bench_mjx_throughput.py``: env and raw physics steps per second per batch."""
    rows = [
        [r.get("batch"), r.get("impl") or (r.get("physics") or {}).get("impl"),
         r.get("env_control_steps_per_s"), r.get("env_physics_steps_per_s"),
         r.get("raw_physics_steps_per_s"), secs(r.get("env_compile_s")),
         _gib(r.get("env_peak_bytes"))]
        for r in data["rows"]
    ]  # fmt: skip
    arm = f", arm {data['arm']}" if data.get("arm") else ""
    lines = [f"Task {data.get('task', '?')}, backend {data.get('backend', '?')}{arm}.", ""]
    header = ["envs", "impl", "control steps/s", "physics steps/s", "raw physics steps/s",
              "env compile", "peak memory"]  # fmt: skip
    lines += table(header, rows)
    ratio = data.get("warp_over_jax") or {}
    if ratio:
        lines += [
            "Warp over JAX: " + ", ".join(f"{fmt(v)}x at {k} envs" for k, v in ratio.items()),
            "",
        ]
    return lines + render_goals(data)


def _gib(value: Any) -> str:
    return f"{value / 2**30:.2f} GiB" if _is_num(value) else ""


def render_parity(data: Json) -> list[str]:
    """``mjx-arm bench parity``: each goal with its value."""
    cfg = data.get("config", {})
    lines = [
        f"Engines {', '.join(data.get('engines', []))}; {cfg.get('fk_poses')} FK poses, "
        f"{cfg.get('sequences')} open-loop sequences of {fmt(cfg.get('seconds'))} s, "
        f"{cfg.get('press_boxes')} press boxes"
        + (f", arm `{cfg['arm']}`" if cfg.get("arm") else ", the shipped arm")
        + ".",
        "",
    ]
    return lines + render_goals(data)


def render_goals(data: Json) -> list[str]:
    """A ``goals`` list of ``{check, subject, value, goal, met}`` as a table."""
    goals = data.get("goals")
    if not isinstance(goals, list) or not all(isinstance(g, dict) for g in goals):
        return []
    rows = [
        [g.get("check"), g.get("subject"), g.get("value"), g.get("goal"),
         "met" if g.get("met") else f"missed{': ' + g['cause'] if g.get('cause') else ''}"]
        for g in goals
    ]  # fmt: skip
    return table(["check", "subject", "value", "goal", ""], rows)


def render_cpu_envs(data: Json) -> list[str]:
    """``bench_cpu_envs.py``: each env beside raw physics, then ``make_vec``."""
    rows = [
        [case, c["env_steps_per_s"]["median"], c["raw_steps_per_s"]["median"], c["ratio"],
         c.get("goal"), "met" if c.get("passed") else "missed"]
        for case, c in data["cases"].items()
    ]  # fmt: skip
    lines = [f"Medians of {data.get('repeats')} repeats, side by side in one run.", ""]
    header = ["case", "env steps/s", "raw physics steps/s (same commands)", "env / raw", "goal",
              ""]  # fmt: skip
    lines += table(header, rows)
    pusher = data.get("pusher_v5")
    if pusher:
        lines += [
            f"Gymnasium's `Pusher-v5` in the same run: {fmt(pusher['env_steps_per_s']['median'])}"
            f" env steps/s, {fmt(pusher['ratio'])} of its raw `mj_step`.",
            "",
        ]
    vec = data.get("make_vec") or {}
    vec_rows = [
        [case, v["sync_env_steps_per_s"]["median"], v["async_env_steps_per_s"]["median"]]
        for case, v in vec.items()
        if isinstance(v, dict) and "sync_env_steps_per_s" in v
    ]
    if vec_rows:
        lines += [f"`gymnasium.make_vec` with {vec.get('num_envs')} envs:", ""]
        lines += table(["case", "sync env steps/s", "async env steps/s"], vec_rows)
    history = data.get("history") or []
    if history:
        lines += ["Earlier runs kept in the file:", ""]
        lines += table(
            ["date", "commit", "case", "env / raw"],
            [
                [date(h), str(h.get("git_commit") or "")[:7], case, c.get("ratio")]
                for h in history
                for case, c in (h.get("cases") or {}).items()
            ],
        )
    return lines


def render_fuzz(data: Json) -> list[str]:
    """``bench_urdf_fuzz.py`` / ``bench_input_fuzz.py``: the outcome per kind or command."""
    groups = data.get("by_kind") or data.get("by_command") or {}
    label = "mutation kind" if "by_kind" in data else "command"
    cols = sorted({k for g in groups.values() for k in g})
    lines = []
    if isinstance(data.get("summary"), str):
        summary = data["summary"]
        lines += [summary if summary.endswith(".") else summary + ".", ""]
    total = data.get("mutations") or data.get("cases")
    lines += [f"{fmt(total)} cases, seed {data.get('seed')}, {secs(data.get('wall_seconds'))}.",
              ""]  # fmt: skip
    return lines + table([label, *cols], [[name, *(g.get(c) for c in cols)]
                                          for name, g in groups.items()])  # fmt: skip


def render_grasp(data: Json) -> list[str]:
    """``mjx-arm bench grasp``: per start and engine, the lift, the slip and the opening."""
    cube = data.get("cube") or {}
    lines = [
        f"Cube {fmt(cube.get('size_m'))} m, {fmt(cube.get('mass_kg'))} kg; finger press "
        f"{fmt(data.get('finger_press_n'))} N; phases (s): "
        + ", ".join(f"{k} {fmt(v)}" for k, v in (data.get("phases_s") or {}).items())
        + ".",
        "",
    ]
    rows = [
        [start, engine, e.get("lift_m"), _mm(e.get("slip_m")), _mm(e.get("opening_m")),
         "held" if e.get("met") else "dropped"]
        for start, s in data["starts"].items()
        for engine, e in s["engines"].items()
    ]  # fmt: skip
    header = ["start", "engine", "lift (m)", "slip (mm)", "opening (mm)", ""]
    return lines + table(header, rows)


def _mm(value: Any) -> Any:
    return value * 1000 if _is_num(value) else value


def rate(value: Any) -> str:
    """A success rate with three decimals (``1.000``, ``0.953``)."""
    return f"{value:.3f}" if _is_num(value) else fmt(value)


def render_robustness(data: Json) -> list[str]:
    """``mjx-arm bench robustness``: per perturbation, the worst point inside its stated range."""
    s = data["summary"]
    pool = s.get("nominal_pooled") or {}
    lines = [
        f"Policy `{Path(str(data.get('policy', '?'))).name}`, task {data.get('task', '?')}, "
        f"engine {data.get('engine', '?')}; goal {fmt(s.get('goal_point'))} at every point, "
        f"{fmt(s.get('goal_joint'))} for the joint draw. Nominal success "
        f"{rate(pool.get('success_rate'))} over {fmt(pool.get('episodes'))} episodes; joint draw "
        f"{rate(s.get('joint_success'))}.",
        "",
    ]
    stated = {p["name"]: (p.get("stated"), p.get("unit")) for p in data.get("perturbations", [])}
    rows = [
        [name, fmt(stated.get(name, (None,))[0]), stated.get(name, (None, ""))[1],
         rate(v.get("worst_inside")), v.get("worst_value"),
         ", ".join(fmt(x) for x in v.get("below_goal_at") or []) or "none",
         "met" if v.get("goal_met") else "missed"]
        for name, v in s["per_perturbation"].items()
    ]  # fmt: skip
    header = ["perturbation", "stated range", "unit", "worst success inside", "at",
              "below the goal at", ""]  # fmt: skip
    return lines + table(header, rows)


def render_failures(data: Json) -> list[str]:
    """``benchmarks/robustness_failures.py``: one perturbation's failures, strikes apart."""
    rows = data["rows"]
    lines = [
        f"Policy `{Path(str(data.get('policy', '?'))).name}`, perturbation "
        f"**{rows[0].get('perturbation', '?') if rows else '?'}**. A strike is a failure whose "
        "wrist peak reached the task's strike limit, which ends the episode; the other "
        "failures are drops, slips or time running out.",
        "",
    ]
    body = [
        [r.get("value"), rate(r.get("success_rate")), r.get("episodes"), r.get("failures"),
         r.get("strikes"), r.get("median_peak_success"),
         ", ".join(f"{x:.0f}" for x in r.get("peaks_of_other_failures") or []) or "none"]
        for r in rows
    ]  # fmt: skip
    header = ["value", "success", "episodes", "failures", "of them strikes",
              "median peak of successes (N)", "peaks of the other failures (N)"]  # fmt: skip
    return lines + table(header, body)


def render_eval(data: Json) -> list[str]:
    """``mjx-arm eval`` written as JSON: one engine's summary."""
    keys = ["engine", "impl", "episodes", "success_rate", "mean_peak_contact_force",
            "mean_steps_to_success", "mean_return"]  # fmt: skip
    return table(keys, [[data.get(k) for k in keys]])


def render_generic(data: Json) -> list[str]:
    """Any other file: its ``summary``, ``goals``, ``rows`` (scalar columns) and ``score``."""
    lines: list[str] = []
    summary = data.get("summary")
    if isinstance(summary, str):
        lines += [summary, ""]
    elif isinstance(summary, dict):
        lines += table(["measure", "value"], [[k, v] for k, v in summary.items()
                                              if not isinstance(v, dict | list)])  # fmt: skip
    lines += render_goals(data)
    rows = data.get("rows")
    if isinstance(rows, list) and rows and all(isinstance(r, dict) for r in rows):
        cols = [k for k in rows[0] if all(_scalar(r.get(k)) for r in rows)]
        lines += table(cols, [[r.get(c) for c in cols] for r in rows]) if cols else []
    score = data.get("score")
    if isinstance(score, dict):
        flat = [[k, *v.values()] for k, v in score.items() if isinstance(v, dict)]
        if flat:
            head = list(next(v for v in score.values() if isinstance(v, dict)))
            lines += table(["setting", *head], flat)
        if data.get("closest"):
            lines += [f"Closest: **{data['closest']}**.", ""]
    if not lines:
        lines = ["*No table for this file's shape; its markdown twin has the details.*", ""]
    return lines


def _scalar(value: Any) -> bool:
    if isinstance(value, list):
        return len(value) == 2 and all(_is_num(v) for v in value)
    return not isinstance(value, dict)


RENDERERS: tuple[Renderer, ...] = (
    Renderer("seeds", _has("seeds", "summary", "settings"), render_seeds),
    Renderer("robustness", _has("perturbations", "rows", "summary"), render_robustness),
    Renderer("failures", lambda d: "strikes" in _first_row(d), render_failures),
    Renderer("transfer", _has("rows", "policy"), render_transfer),
    Renderer("throughput", lambda d: "env_control_steps_per_s" in _first_row(d), render_throughput),
    Renderer("parity", _has("figures", "goals", "engines"), render_parity),
    Renderer("cpu_envs", lambda d: d.get("benchmark") == "cpu_envs", render_cpu_envs),
    Renderer("fuzz", lambda d: "by_kind" in d or "by_command" in d, render_fuzz),
    Renderer("eval", _has("engine", "episodes", "success_rate"), render_eval),
    Renderer("grasp", _has("starts", "cube"), render_grasp),
    Renderer("train", lambda d: "curve" in _first_row(d), render_generic),
    Renderer("generic", lambda d: True, render_generic),
)


def _first_row(data: Json) -> Json:
    rows = data.get("rows")
    return rows[0] if isinstance(rows, list) and rows and isinstance(rows[0], dict) else {}


def renderer_for(data: Json) -> Renderer:
    """The first renderer whose kind matches ``data``."""
    return next(r for r in RENDERERS if r.matches(data))
