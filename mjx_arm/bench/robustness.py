"""Robustness benchmark: one exported policy's success under perturbations of the model, its
sensors and its timing, each alone and all together.

``mjx-arm bench robustness POLICY`` runs the policy in the batched env (C MuJoCo on a CPU, MJX on
a GPU: the same code) with the env's own domain randomisation
(:class:`~mjx_arm.envs.physics_config.RandomizationConfig`) set to fixed values: each sweep
point is a config whose ranges are single values, so the benchmark measures exactly what the
training randomisation draws from. All points run as one batch (each env carries its own draw,
:class:`~mjx_arm.envs.randomization.Episode`), each env's first episode counts. For every point:
success rate with its 95 % Wilson interval, and the mean and median of each episode's peak
wrist force (the tared F/T reading's norm, N). The joint draw samples every perturbation at
once, uniform over its stated range, per episode.

The perturbations, their stated ranges and where those come from:
:mod:`~mjx_arm.bench.robustness_config`.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

import numpy as np

from mjx_arm.bench.results import fmt, markdown_table, save_results
from mjx_arm.bench.robustness_config import (
    GOAL_JOINT,
    GOAL_POINT,
    JOINT,
    Perturbation,
    Point,
    RobustnessConfig,
    perturbations_for,
    sweep_points,
)
from mjx_arm.envs.physics_config import NOMINAL
from mjx_arm.evaluate.stats import wilson_interval

# --------------------------------------------------------------------------- running


def point_draws(env: Any, points: list[Point], counts: list[int], seed: int) -> Any:
    """Each point's draws, ``counts[i]`` envs each, stacked into one batched Episode."""
    import jax

    from mjx_arm.envs.randomization import sample_episode

    keys = jax.random.split(jax.random.PRNGKey(seed + 1), len(points))
    n = env.arm.n_joints
    parts = [
        jax.vmap(lambda k, cfg=point.config: sample_episode(k, cfg, n))(jax.random.split(key, c))
        for point, key, c in zip(points, keys, counts, strict=True)
    ]
    return jax.tree.map(lambda *xs: jax.numpy.concatenate(xs), *parts)


def rollout(env: Any, policy: Any, episode: Any, seed: int) -> dict[str, np.ndarray]:
    """Run each env's first episode under its draw ``episode`` (batched, ``B`` envs).

    Returns:
        ``success (B,)`` bool and ``peak_force (B,)`` (N, the largest wrist force norm before
        the episode ended).
    """
    import jax
    import jax.numpy as jnp

    from mjx_arm.task import observation as obs_lib

    size = int(np.asarray(episode.latency).shape[0])
    start = jax.jit(jax.vmap(env.start))
    step = jax.jit(jax.vmap(env.step))
    state = start(jax.random.split(jax.random.PRNGKey(seed), size), episode)
    active = np.ones(size, bool)
    success = np.zeros(size, bool)
    peak = np.zeros(size)
    for _ in range(env.task.episode_steps):
        obs = obs_lib.unflatten_obs(np.asarray(state.obs, np.float32), env.task_spec.extra_obs)
        actions = np.asarray(policy(obs), np.float32).reshape(size, env.action_size)
        state = step(state, jnp.asarray(actions))
        env.physics.check_overflow(state.metrics["physics_overflow"])
        force = np.asarray(state.metrics["contact_force"])
        success |= active & (np.asarray(state.metrics["success"]) > 0)
        peak = np.where(active, np.maximum(peak, force), peak)
        active &= ~(np.asarray(state.done) > 0)
        if not active.any():
            break
    return {"success": success, "peak_force": peak}


def point_result(point: Point, success: np.ndarray, peak: np.ndarray) -> dict[str, Any]:
    """One point's numbers: success rate, Wilson 95 % interval, mean and median peak force."""
    n, k = len(success), int(success.sum())
    low, high = wilson_interval(k, n)
    return {
        "perturbation": point.perturbation,
        "value": point.value,
        "inside_stated": point.inside,
        "episodes": n,
        "successes": k,
        "success_rate": k / n if n else None,
        "success_ci95": [low, high],
        "mean_peak_force": float(np.mean(peak)) if n else None,
        "median_peak_force": float(np.median(peak)) if n else None,
    }


def make_env(task: Any, engine: str, impl: str, arm: Any, batch: int) -> Any:
    """The batched env of ``engine`` with randomisation on (the draws come from the points)."""
    from mjx_arm.envs.backend import make_batched_env
    from mjx_arm.envs.physics_config import PhysicsConfig

    backend = "mujoco" if engine == "mujoco-batch" else "mjx"
    return make_batched_env(task, backend, PhysicsConfig(impl=impl), batch, NOMINAL, arm)


def run_robustness(
    policy: Any, task: Any, config: RobustnessConfig, arm: Any = None, log=print
) -> dict[str, Any]:
    """The sweep of ``policy`` on ``task``: every point of :func:`sweep_points`.

    Returns:
        JSON-ready: ``rows`` (one per point, :func:`point_result`), ``perturbations`` (their
        values, stated ranges and sources), ``joint_config``, ``summary`` (goals), times.
    """
    perturbations = perturbations_for(bool(task.spec.gripper))
    points = sweep_points(perturbations)
    joint_n = config.joint_episodes or 4 * config.episodes
    counts = [config.episodes] * (len(points) - 1) + [joint_n]
    env = make_env(task, config.engine, config.impl, arm, min(sum(counts), config.max_batch))
    episode = point_draws(env, points, counts, config.seed)
    bounds = np.cumsum([0, *counts])
    success, peak = np.zeros(bounds[-1], bool), np.zeros(bounds[-1])
    t0 = time.monotonic()
    for lo in range(0, bounds[-1], config.max_batch):
        hi = min(lo + config.max_batch, bounds[-1])
        chunk = _pad(episode, lo, hi, config.max_batch if bounds[-1] > config.max_batch else 0)
        out = rollout(env, policy, chunk, config.seed + lo)
        success[lo:hi], peak[lo:hi] = out["success"][: hi - lo], out["peak_force"][: hi - lo]
        log(f"  envs {lo}-{hi} of {bounds[-1]}: {time.monotonic() - t0:.0f} s")
    rows = [
        point_result(p, success[a:b], peak[a:b])
        for p, a, b in zip(points, bounds[:-1], bounds[1:], strict=True)
    ]
    return {
        "task": task.task,
        "engine": config.engine,
        "physics": env.physics.describe(),
        "config": config.to_dict(),
        "perturbations": [dataclasses.asdict(p) for p in perturbations],
        "joint_config": points[-1].config.to_dict(),
        "rows": rows,
        "summary": summarize(rows, perturbations),
        "episodes_total": int(bounds[-1]),
        "run_seconds": time.monotonic() - t0,
    }


def _pad(episode: Any, lo: int, hi: int, size: int) -> Any:
    """Rows ``lo:hi`` of a batched Episode, padded to ``size`` rows by repeating the last
    one (0: no padding), so that every chunk has one shape (one compilation)."""
    import jax
    import jax.numpy as jnp

    def cut(x):
        part = x[lo:hi]
        if size and hi - lo < size:
            part = jnp.concatenate([part, jnp.repeat(part[-1:], size - (hi - lo), axis=0)])
        return part

    return jax.tree.map(cut, episode)


def summarize(rows: list[dict[str, Any]], perturbations: tuple[Perturbation, ...]) -> dict:
    """Per perturbation: the lowest success inside the stated range, and the first value
    (going out from nominal) where success falls below :data:`GOAL_POINT`; the goals."""
    per: dict[str, Any] = {}
    for p in perturbations:
        mine = [r for r in rows if r["perturbation"] == p.name]
        inside = [r for r in mine if r["inside_stated"]]
        worst = min(inside, key=lambda r: r["success_rate"])
        breaks = [r["value"] for r in mine if r["success_rate"] < GOAL_POINT]
        per[p.name] = {
            "worst_inside": worst["success_rate"],
            "worst_value": worst["value"],
            "below_goal_at": breaks,
            "goal_met": worst["success_rate"] >= GOAL_POINT,
        }
    joint = next(r for r in rows if r["perturbation"] == JOINT)
    return {
        "nominal_pooled": nominal_pool(rows, perturbations),
        "per_perturbation": per,
        "joint_success": joint["success_rate"],
        "joint_goal_met": joint["success_rate"] >= GOAL_JOINT,
        "all_points_goal_met": all(v["goal_met"] for v in per.values()),
        "goal_point": GOAL_POINT,
        "goal_joint": GOAL_JOINT,
    }


def nominal_pool(rows: list[dict[str, Any]], perturbations: tuple[Perturbation, ...]) -> dict:
    """Every point at the model's own values (each perturbation's nominal point: the same
    config), pooled: the policy's unperturbed success, with a tighter interval than one
    point's."""
    by_name = {p.name: p for p in perturbations}
    mine = [
        r
        for r in rows
        if r["perturbation"] in by_name and by_name[r["perturbation"]].config(r["value"]) == NOMINAL
    ]
    n, k = sum(r["episodes"] for r in mine), sum(r["successes"] for r in mine)
    low, high = wilson_interval(k, n)
    return {
        "points": len(mine),
        "episodes": n,
        "successes": k,
        "success_rate": k / n if n else None,
        "success_ci95": [low, high],
    }


# --------------------------------------------------------------------------- report


def _point_rows(result: dict[str, Any]) -> list[list[Any]]:
    """One table row per sweep point."""
    rows = []
    for r in result["rows"]:
        low, high = r["success_ci95"]
        value = "all, uniform over stated ranges" if r["value"] is None else f"{r['value']:g}"
        rows.append([
            r["perturbation"], value, "yes" if r["inside_stated"] else "beyond",
            f"{r['success_rate']:.3f}", f"[{low:.2f}, {high:.2f}]", r["episodes"],
            fmt(r["mean_peak_force"]), fmt(r["median_peak_force"]),
        ])  # fmt: skip
    return rows


def _goal_rows(summary: dict[str, Any]) -> list[list[Any]]:
    """One table row per perturbation's goal, then the joint draw's."""
    rows = [
        [name, f"{v['worst_inside']:.3f} at {v['worst_value']:g}",
         ", ".join(f"{x:g}" for x in v["below_goal_at"]) or "none",
         "pass" if v["goal_met"] else "MISS"]
        for name, v in summary["per_perturbation"].items()
    ]  # fmt: skip
    rows.append(
        [JOINT, f"{summary['joint_success']:.3f}", "",
         "pass" if summary["joint_goal_met"] else "MISS"]
    )  # fmt: skip
    return rows


def markdown(result: dict[str, Any], source: str) -> str:
    """The report: one row per point, the goals, and where each range comes from."""
    headers = ["perturbation", "value", "in stated range", "success", "95% Wilson CI",
               "episodes", "mean peak wrist force (N)", "median peak (N)"]  # fmt: skip
    summary = result["summary"]
    sources = [
        [p["name"], p["unit"], f"{p['stated'][0]:g} to {p['stated'][1]:g}", p["source"]]
        for p in result["perturbations"]
    ]
    text = [
        f"Robustness of {source} on {result['task']}, engine {result['engine']} "
        f"({result['physics'].get('impl')}), {result['episodes_total']} episodes in "
        f"{result['run_seconds']:.0f} s.\n",
        markdown_table(headers, _point_rows(result)),
        _nominal_line(summary["nominal_pooled"]),
        f"\nGoals: success >= {GOAL_POINT} at every point of each stated range, "
        f">= {GOAL_JOINT} under the joint draw.\n",
        markdown_table(
            ["perturbation", "worst success in stated range", f"values below {GOAL_POINT}", "goal"],
            _goal_rows(summary),
        ),
        "\nRanges and their sources:\n",
        markdown_table(["perturbation", "unit", "stated range", "source"], sources),
        "\nSources: UR5e technical specifications (Universal Robots); Isaac Lab's UR10e reach "
        "sim-to-real recipe; mjlab's domain randomisation guide "
        "(mujocolab.github.io/mjlab). A sweep point fixes one perturbation (ranges low = high; "
        "noise and pose error as a scale); payload sits at the flange, upstream of the wrist "
        "F/T sensor; joint bias and F/T bias apply the value to every joint / force axis.\n",
    ]
    return "\n".join(text)


def _nominal_line(pool: dict[str, Any]) -> str:
    low, high = pool["success_ci95"]
    return (
        f"\nNominal (the {pool['points']} points at the model's own values, pooled): success "
        f"{pool['success_rate']:.3f} [{low:.2f}, {high:.2f}] over {pool['episodes']} episodes.\n"
    )


def plot(result: dict[str, Any], path: Path) -> Path:
    """One panel per perturbation: success (Wilson 95 % interval) against its value, the
    stated range shaded; the joint draw as its own panel."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    perts = result["perturbations"]
    cols = 4
    rows_n = -(-(len(perts) + 1) // cols)
    fig, axes = plt.subplots(rows_n, cols, figsize=(4 * cols, 3 * rows_n), squeeze=False)
    for ax, p in zip(axes.flat, perts, strict=False):
        rows = [r for r in result["rows"] if r["perturbation"] == p["name"]]
        x = [r["value"] for r in rows]
        y = [r["success_rate"] for r in rows]
        err = [[max(r["success_rate"] - r["success_ci95"][0], 0.0) for r in rows],
               [max(r["success_ci95"][1] - r["success_rate"], 0.0) for r in rows]]  # fmt: skip
        ax.axvspan(*p["stated"], color="C2", alpha=0.12)
        ax.errorbar(x, y, yerr=err, marker="o", capsize=3)
        ax.axhline(GOAL_POINT, color="grey", ls=":")
        ax.set(ylim=(0, 1.05), title=p["name"], xlabel=p["unit"], ylabel="success")
    joint = next(r for r in result["rows"] if r["perturbation"] == JOINT)
    ax = axes.flat[len(perts)]
    low, high = joint["success_ci95"]
    rate = joint["success_rate"]
    yerr = [[max(rate - low, 0.0)], [max(high - rate, 0.0)]]
    ax.bar([JOINT], [rate], yerr=yerr, capsize=4, color="C1")
    ax.axhline(GOAL_JOINT, color="grey", ls=":")
    ax.set(ylim=(0, 1.05), title="all at once", ylabel="success")
    for ax in list(axes.flat)[len(perts) + 1 :]:
        ax.axis("off")
    fig.suptitle(f"{result['task']}: success under perturbations ({result['engine']})")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def write_report(
    result: dict[str, Any],
    meta: dict[str, Any],
    folder: str | Path,
    name: str,
    source: str,
    png: bool = False,
) -> list[Path]:
    """Write ``<name>.md`` and ``<name>.json`` (and with ``png``, ``<name>.png``) into
    ``folder``."""
    payload = {"meta": meta, "policy": source, **result}
    paths = list(save_results(name, payload, markdown(result, source), folder))
    if png:
        paths.append(plot(result, Path(folder) / f"{name}.png"))
    return paths
