"""What a Touch policy does the step after it feels the box: the contact reflex, measured.

A Touch seed that ends "tapping" (``benchmarks/training_diagnosis.py``) meets the box on many
steps of an episode, but its in-band steps never come two in a row. This runs exported
policies (``.npz``, deterministic) in the CPU MuJoCo Gymnasium env and, for every step whose
reading is at least the band's lower end (1 N), looks at the action of the next step:

- ``retract``: the next action is saturated (``|a| >= 0.9``) on at least ``SATURATED_JOINTS``
  joints: the policy answers the reading by throwing the arm off the box at full speed;
- the reading that triggers it (median force of the contact steps followed by a retract);
- per episode: success, strike (a reading over the strike limit ends it), contact steps,
  in-band steps, in-band pairs (two in a row: a press that held) and the gap between contacts;
- each impact (a contact step after a step without): how fast the ee point closed on the
  target over the step before it (m/s), and the reading it made.

With ``--smoothing A [A ...]`` it runs each policy again with its actions low-passed at test
time (``a'_t = A a'_{t-1} + (1 - A) a_t``) and reports success and strikes per ``A``: does a
policy that retracts keep its presses when it cannot retract at once?

    python -m benchmarks.touch_contact_reflex runs/pol/*.npz --episodes 50 \\
        --name touch_contact_reflex --out benchmarks/results/diagnosis
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import mjx_arm  # noqa: F401  (registers the envs)
from benchmarks.common import environment_metadata, markdown_table, save_results
from mjx_arm import policy as policy_lib

SATURATED = 0.9  # |action| at or above this is at full speed
SATURATED_JOINTS = 3  # joints at full speed at once: a retract, not a correction
FIRST_EPISODE = 5000  # episode seeds start here (never used to train or choose anything)


def episode(env: gym.Env, policy, seed: int, smoothing: float = 0.0) -> dict[str, Any]:
    """One deterministic episode: per-step forces (N, ``(T,)``) and actions ``(T, n)``, the
    actions low-passed by ``smoothing`` (0: as the policy gives them)."""
    obs, info = env.reset(seed=seed)
    forces, actions, distances, success, strike = [], [], [], False, False
    for _ in range(10_000):
        action = np.asarray(policy(obs), dtype=np.float32)
        if actions and smoothing:
            action = smoothing * actions[-1] + (1.0 - smoothing) * action
        obs, _, terminated, truncated, info = env.step(action)
        actions.append(action)
        forces.append(float(np.nan_to_num(info["contact_force_norm"], nan=0.0)))
        distances.append(float(info["distance"]))
        if terminated or truncated:
            success = bool(info["is_success"])
            strike = bool(terminated and not success)
            break
    return {"forces": np.asarray(forces), "actions": np.asarray(actions), "success": success,
            "strike": strike, "distances": np.asarray(distances)}  # fmt: skip


def impacts(forces: np.ndarray, distances: np.ndarray, low: float, ctrl_dt: float) -> list:
    """``(closing speed (m/s), reading (N))`` of each impact of one episode: a step reading at
    least ``low`` after one that did not, its speed that of the step before (how fast the
    distance to the target shrank), from forces and distances ``(T,)``."""
    touching = forces >= low
    steps = [t for t in range(2, len(forces)) if touching[t] and not touching[t - 1]]
    return [((distances[t - 2] - distances[t - 1]) / ctrl_dt, forces[t]) for t in steps]


def reflex(forces: np.ndarray, actions: np.ndarray, band: tuple[float, float]) -> dict[str, Any]:
    """The contact steps of one episode and what followed each: forces ``(T,)``, actions
    ``(T, n)`` (the action of step t is taken before reading ``forces[t]``)."""
    touching = forces >= band[0]
    in_band = touching & (forces <= band[1])
    contact = np.nonzero(touching[:-1])[0]
    saturated = (np.abs(actions[contact + 1]) >= SATURATED).sum(axis=1) >= SATURATED_JOINTS
    gaps = np.diff(np.nonzero(touching)[0])
    return {
        "contact_steps": int(touching.sum()),
        "in_band_steps": int(in_band.sum()),
        "in_band_pairs": int((in_band[1:] & in_band[:-1]).sum()),
        "retracts": int(saturated.sum()),
        "retract_forces": forces[contact[saturated]].tolist(),
        "contact_gap_median": float(np.median(gaps)) if gaps.size else float("nan"),
    }


def measure(path: Path, episodes: int) -> dict[str, Any]:
    """The reflex figures of the policy file ``path`` over ``episodes`` episodes."""
    policy = policy_lib.load(path)
    env = gym.make("mjx_arm/Touch-v0", engine="mujoco")
    band, ctrl_dt = tuple(env.unwrapped.task.force_band), env.unwrapped.task.ctrl_dt
    rows, hits = [], []
    for i in range(episodes):
        ep = episode(env, policy, FIRST_EPISODE + i)
        rows.append({**reflex(ep["forces"], ep["actions"], band), "success": ep["success"],
                     "strike": ep["strike"], "length": len(ep["forces"])})  # fmt: skip
        hits += impacts(ep["forces"], ep["distances"], band[0], ctrl_dt)
    env.close()
    contacts = sum(r["contact_steps"] for r in rows)
    retract_forces = [f for r in rows for f in r["retract_forces"]]
    return {
        "policy": path.name,
        "episodes": episodes,
        "success": float(np.mean([r["success"] for r in rows])),
        "strike": float(np.mean([r["strike"] for r in rows])),
        "contact_steps": float(np.mean([r["contact_steps"] for r in rows])),
        "in_band_steps": float(np.mean([r["in_band_steps"] for r in rows])),
        "in_band_pairs": float(np.mean([r["in_band_pairs"] for r in rows])),
        "retract_share": sum(r["retracts"] for r in rows) / contacts if contacts else 0.0,
        "retract_force_median": float(np.median(retract_forces)) if retract_forces else None,
        "contact_gap_median": float(np.nanmedian([r["contact_gap_median"] for r in rows])),
        "impacts": len(hits),
        "impact_speed_median": float(np.median([v for v, _ in hits])) if hits else None,
        "impact_reading_median": float(np.median([f for _, f in hits])) if hits else None,
        "per_episode": [{k: v for k, v in r.items() if k != "retract_forces"} for r in rows],
    }


def smoothed(path: Path, episodes: int, alphas: list[float]) -> list[dict[str, Any]]:
    """Success and strike rate of the policy file ``path`` with its actions low-passed by
    each of ``alphas``, over ``episodes`` episodes each."""
    policy = policy_lib.load(path)
    env = gym.make("mjx_arm/Touch-v0", engine="mujoco")
    rows = []
    for alpha in alphas:
        eps = [episode(env, policy, FIRST_EPISODE + i, alpha) for i in range(episodes)]
        rows.append({"policy": path.name, "smoothing": alpha, "episodes": episodes,
                     "success": float(np.mean([e["success"] for e in eps])),
                     "strike": float(np.mean([e["strike"] for e in eps]))})  # fmt: skip
    env.close()
    return rows


def table(results: list[dict[str, Any]]) -> str:
    """One row per policy."""
    head = ["policy", "success", "strike", "contact steps", "in-band steps", "in-band pairs",
            "contacts then a retract", "retract at (N)", "steps between contacts",
            "closing speed before an impact (cm/s)", "impact reading (N)"]  # fmt: skip
    rows = [
        [r["policy"], f"{r['success']:.3f}", f"{r['strike']:.3f}", f"{r['contact_steps']:.1f}",
         f"{r['in_band_steps']:.1f}", f"{r['in_band_pairs']:.2f}", f"{r['retract_share']:.2f}",
         "-" if r["retract_force_median"] is None else f"{r['retract_force_median']:.1f}",
         f"{r['contact_gap_median']:.1f}", _fmt(r["impact_speed_median"], 100.0),
         _fmt(r["impact_reading_median"])]
        for r in results
    ]  # fmt: skip
    return markdown_table(head, rows)


def _as_trained(result: dict[str, Any]) -> dict[str, Any]:
    """The smoothing row (factor 0) of a policy's :func:`measure` result."""
    return {"policy": result["policy"], "smoothing": 0.0, "episodes": result["episodes"],
            "success": result["success"], "strike": result["strike"]}  # fmt: skip


def _fmt(value: float | None, scale: float = 1.0) -> str:
    return "-" if value is None else f"{value * scale:.1f}"


def smoothing_table(rows: list[dict[str, Any]]) -> str:
    """One row per policy and smoothing."""
    head = ["policy", "smoothing", "success", "strike"]
    cells = [
        [r["policy"], f"{r['smoothing']:.1f}", f"{r['success']:.3f}", f"{r['strike']:.3f}"]
        for r in rows
    ]
    return markdown_table(head, cells)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policies", type=Path, nargs="+", help="exported Touch policies (.npz)")
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--name", default="touch_contact_reflex")
    parser.add_argument("--out", type=Path, default=None, help="results folder")
    parser.add_argument(
        "--smoothing", type=float, nargs="*", default=[], help="low-pass factors to try too"
    )
    args = parser.parse_args(argv)
    results = []
    for path in args.policies:
        result = measure(path, args.episodes)
        results.append(result)
        share = result["retract_share"]
        print(f"{path.name}: success {result['success']:.3f}, retracts {share:.0%}")
    text = table(results)
    smooth = []
    if args.smoothing:  # the unsmoothed rows are the measured ones above
        smooth = [
            row
            for path, result in zip(args.policies, results, strict=True)
            for row in [_as_trained(result), *smoothed(path, args.episodes, args.smoothing)]
        ]
        text += "\n\nActions low-passed at test time:\n\n" + smoothing_table(smooth)
    print(text)
    payload = {"meta": environment_metadata(), "saturated": SATURATED,
               "saturated_joints": SATURATED_JOINTS, "first_episode": FIRST_EPISODE,
               "results": results, "smoothing": smooth}  # fmt: skip
    save_results(args.name, payload, f"# Touch: the step after a contact\n\n{text}", args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
