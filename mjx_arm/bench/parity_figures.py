"""The figures of engine parity (:mod:`mjx_arm.bench.parity`) and its goals.

Pure functions of the engines' traces: the divergence of every engine pair, the tared press
force, the jitter of the joints, and each goal with its figure, whether it is met and, when
missed, its stated cause.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from mjx_arm.bench.engines import Trace
from mjx_arm.bench.parity_config import CONTACT_N, ParityConfig
from mjx_arm.engines import REFERENCE_ENGINE, engine_names
from mjx_arm.engines import engine as engine_row

# --------------------------------------------------------------------------- figures


def pairs(names: list[str]) -> list[tuple[str, str]]:
    """Every pair of engines, in the order given."""
    return list(itertools.combinations(names, 2))


def pair_key(a: str, b: str) -> str:
    """The JSON key of a pair."""
    return f"{a} vs {b}"


def joint_divergence(a: Trace, b: Trace) -> np.ndarray:
    """Largest joint-angle difference (rad, wrapped to +-pi) per run and step, ``(B, T)``."""
    diff = np.angle(np.exp(1j * (a.qpos - b.qpos)))
    return np.abs(diff).max(axis=-1)


def curve_stats(values: np.ndarray, index: int) -> dict[str, Any]:
    """Median and 95th percentile over runs of ``values (B, T)``, whole curve and at ``index``."""
    median, p95 = np.median(values, axis=0), np.percentile(values, 95, axis=0)
    return {
        "median": median,
        "p95": p95,
        "at_goal_median": float(median[index]),
        "at_goal_p95": float(p95[index]),
        "final_median": float(median[-1]),
        "final_p95": float(p95[-1]),
        "max": float(values.max()),
    }


def fk_figures(ee: dict[str, np.ndarray]) -> dict[str, float]:
    """Largest ee point distance (m) of each engine pair over the poses."""
    return {
        pair_key(a, b): float(np.linalg.norm(ee[a] - ee[b], axis=-1).max())
        for a, b in pairs(list(ee))
    }


def open_loop_figures(traces: dict[str, Trace], ctrl_dt: float, goal_time: float) -> dict:
    """Divergence curves of every pair, from control-step traces ``(B, T, ...)``."""
    steps = next(iter(traces.values())).qpos.shape[1]
    index = round(goal_time / ctrl_dt) - 1  # the read after the control step ending at goal_time
    touched = np.any([t.force().max(axis=1) > CONTACT_N for t in traces.values()], axis=0)
    out: dict[str, Any] = {
        "time_s": ctrl_dt * np.arange(1, steps + 1),
        "sequences": len(touched),
        "sequences_with_contact": int(touched.sum()),
        "free_motion_force_max_n": {
            name: float(t.force()[~touched].max(initial=0.0)) for name, t in traces.items()
        },
        "pairs": {},
    }
    for a, b in pairs(list(traces)):
        div = joint_divergence(traces[a], traces[b])
        stats = curve_stats(div, index)
        stats["at_goal_median_free_motion"] = float(np.median(div[~touched, index]))
        out["pairs"][pair_key(a, b)] = stats
    return out


def press_figures(traces: dict[str, Trace], ctrl_dt: float, average: int) -> dict:
    """The tared force over time per engine, its steady value and the gap to the reference."""
    force = {name: t.force() for name, t in traces.items()}
    steady = {name: f[:, -average:].mean(axis=1) for name, f in force.items()}
    reference = REFERENCE_ENGINE if REFERENCE_ENGINE in force else next(iter(force))
    steps = next(iter(force.values())).shape[1]
    out: dict[str, Any] = {"time_s": ctrl_dt * np.arange(1, steps + 1), "reference": reference}
    out["engines"] = {}
    for name, f in force.items():
        contact = f > CONTACT_N
        first = np.where(contact.any(axis=1), contact.argmax(axis=1) + 1, 0) * ctrl_dt
        rel = np.abs(steady[name] - steady[reference]) / steady[reference]
        out["engines"][name] = {
            "force_n": f,
            "force_median_n": np.median(f, axis=0),
            "steady_n": steady[name],
            "first_contact_s": first,
            "rel_to_reference": rel,
            "rel_to_reference_max": float(rel.max()),
        }
    return out


def jitter_figures(trace: Trace, sim_dt: float, window: float, smooth: int) -> dict[str, Any]:
    """Spread of the joint acceleration and the velocity's high-frequency content.

    Args:
        trace: runs read at every physics step, ``(R, T, ...)``.
        sim_dt: physics step (s).
        window: the end of each run used (s).
        smooth: physics steps per control step: the velocity minus its moving average over
            this many steps is the content above the control rate.

    Returns:
        ``acc_std`` (rad/s^2) and ``hf_vel_rms`` (rad/s), per run and joint ``(R, 6)``, and
        their ``_max``: the largest joint's, median over the runs.
    """
    qvel = trace.qvel[:, -round(window / sim_dt) :]
    acc_std = (np.diff(qvel, axis=1) / sim_dt).std(axis=1)
    kernel = np.ones(smooth) / smooth
    average = np.apply_along_axis(np.convolve, 1, qvel, kernel, mode="same")
    hf = np.sqrt(np.mean((qvel - average)[:, smooth:-smooth] ** 2, axis=1))
    return {
        "acc_std": acc_std,
        "acc_std_max": float(np.median(acc_std.max(axis=1))),
        "hf_vel_rms": hf,
        "hf_vel_rms_max": float(np.median(hf.max(axis=1))),
    }


# --------------------------------------------------------------------------- goals


def divergence_goal(pair: tuple[str, str], config: ParityConfig) -> float:
    """The median divergence goal (rad) of a pair: that of the first engine in it whose registry
    row names one (``parity_goal``: PyBullet's), else MJX's."""
    for name in pair:
        if name in engine_names("parity_goal"):
            return getattr(config, engine_row(name).parity_goal)
    return config.goal_mjx_rad


def check_goals(
    figures: dict[str, Any], config: ParityConfig, band: tuple[float, float]
) -> list[dict[str, Any]]:
    """Each goal with its figure and whether it is met.

    Returns:
        Rows of ``check``, ``subject`` (pair or engine), ``value``, ``goal`` (text), ``met``
        and ``cause`` (why it is missed, from :func:`cause_of`; None when met).
    """
    rows = [
        _goal("forward kinematics, max", key, value, value <= config.goal_fk_m, config.goal_fk_m)
        for key, value in figures["fk_m"].items()
    ]
    check = f"joint divergence at {config.goal_time:g} s, median"
    for key, stats in figures["open_loop"]["pairs"].items():
        limit = divergence_goal(tuple(key.split(" vs ")), config)
        value = stats["at_goal_median"]
        rows.append(_goal(check, key, value, value <= limit, limit))
    low, high = band
    for name, press in figures["press"]["engines"].items():
        steady = press["steady_n"]
        met = bool(np.all((steady >= low) & (steady <= high)))
        value = [float(steady.min()), float(steady.max())]
        rows.append(_goal("steady press force in the Touch band", name, value, met, band))
    return rows


def _goal(check: str, subject: str, value: Any, met: bool, goal: Any) -> dict[str, Any]:
    met = bool(met)
    return {
        "check": check,
        "subject": subject,
        "value": value,
        "goal": goal,
        "met": met,
        "cause": None if met else cause_of(check, subject),
    }


# Where a goal is missed and no engine's row states a cause (``EngineSpec.parity_causes``): the
# difference that drives that figure, keyed by check prefix.
CAUSES = {
    "steady press force": (
        "the press commands were recorded in C MuJoCo; this engine resolves the contact "
        "(solver, friction) differently"
    ),
}


def cause_of(check: str, subject: str) -> str:
    """The stated cause of a missed goal, or a pointer to the figures.

    The first registry row (those that name a ``parity_goal`` first, as in
    :func:`divergence_goal`) whose name ``subject`` holds and one of whose ``parity_causes``
    prefixes ``check`` starts with gives it; else :data:`CAUSES`.
    """
    goals = engine_names("parity_goal")
    names = sorted(engine_names("parity_causes"), key=lambda name: name not in goals)
    for name in names:
        for prefix, cause in engine_row(name).parity_causes.items():
            if name in subject and check.startswith(prefix):
                return cause
    for prefix, cause in CAUSES.items():
        if check.startswith(prefix):
            return cause
    return "no cause established: see the figures in the JSON"
