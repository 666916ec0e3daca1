"""Transfer matrix: one trained policy evaluated in every engine of the contract.

Engines (:data:`TRANSFER_ENGINES`): MJX (the batched JAX env), the C MuJoCo batched backend, the
CPU MuJoCo Gymnasium env and the PyBullet reference env. Each row gives the success rate with
its 95% Wilson interval, the mean return, the mean steps to success and the mean peak contact
force, beside the goals: success >= 0.95 in every engine and, for Touch, a mean peak force of
at most 50 N (the top of the success band: a policy that strikes the box does not transfer).

Without a GPU, MJX (minutes to compile, about 100x slower than C MuJoCo) is skipped with a note
and the C MuJoCo batch stands in as the batched engine, unless ``mjx_on_cpu`` is set.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mjx_arm.bench.results import fmt, markdown_table, save_results, verdict
from mjx_arm.bench.settings import setting
from mjx_arm.engines import batch_engines, engine, engine_names
from mjx_arm.envs.physics_config import IMPLS
from mjx_arm.inputs import MAX_SEED
from mjx_arm.names import TASK_IDS
from mjx_arm.settings import check_range
from mjx_arm.task.config import TaskConfig


@dataclass(frozen=True)
class TransferEngine:
    """One row of the matrix: its label, and the ``engine`` / ``backend`` of
    :func:`mjx_arm.evaluate.evaluate`."""

    label: str
    engine: str
    backend: str | None = None


# The batched JAX env's engine (MJX): its row runs it on MJX, the "batch" row on C MuJoCo (the
# backends of :func:`mjx_arm.envs.backend.make_batched_env`).
BATCH = batch_engines()[0]
TRANSFER_ENGINES = {
    BATCH: TransferEngine(engine(BATCH).label, BATCH, "mjx"),
    "batch": TransferEngine("C MuJoCo batch", BATCH, "mujoco"),
    # the Gymnasium env engines of the registry, labelled by their rows
    **{name: TransferEngine(engine(name).label, name) for name in engine_names("env")},
}


@dataclass(frozen=True)
class TransferConfig:
    """Settings of the transfer matrix. Saved in the result JSON; the CLI flags come from here."""

    engines: tuple[str, ...] = setting(
        (BATCH, *engine_names("env")), "engines (rows)", tuple(TRANSFER_ENGINES)
    )
    task: str = setting("", "task to evaluate in: reach or touch (default: the policy's own)")
    episodes: int = setting(200, "episodes per engine")
    seed: int = setting(1000, "first episode's seed (CPU engines) or the batch's seed")
    impl: str = setting("auto", "MJX implementation", IMPLS)
    mjx_on_cpu: bool = setting(False, "run MJX even without a GPU (minutes to compile)")
    arm: str = setting("", "the arm: a URDF or an arm file (default: the policy's own)")
    pybullet_contact: str = setting(
        "soft", "PyBullet's scene contact: soft, rigid or FIXED/CUBE (STIFFNESS:DAMPING each)"
    )
    goal_success: float = setting(0.95, "goal: success rate in every engine")
    goal_peak_force: float = setting(50.0, "goal (Touch): mean peak contact force (N)")

    def __post_init__(self) -> None:
        check_range(self, "episodes", low=1, high=100_000)
        check_range(self, "seed", low=0, high=MAX_SEED)
        check_range(self, "goal_success", low=0, high=1)
        check_range(self, "goal_peak_force", above=0)
        unknown = set(self.engines) - set(TRANSFER_ENGINES)
        if unknown or not self.engines:
            raise ValueError(f"engines must be some of {tuple(TRANSFER_ENGINES)}")
        if self.task not in ("", *TASK_IDS):
            raise ValueError(f"task must be one of {tuple(TASK_IDS)}, got {self.task!r}")
        from pybullet_ref.contact import SceneContact  # settings only: no PyBullet import

        SceneContact.parse(self.pybullet_contact)  # a named ValueError on a bad text

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return dataclasses.asdict(self)


def plan_engines(config: TransferConfig, jax_backend: str) -> tuple[list[str], list[str]]:
    """The engines to run and notes on what was skipped.

    Args:
        config: the settings.
        jax_backend: JAX's default backend ("cpu", "gpu", ...).

    Returns:
        Engine keys in row order, and notes.
    """
    keys = list(config.engines)
    if BATCH not in keys or jax_backend != "cpu" or config.mjx_on_cpu:
        return keys, []
    note = (
        "MJX skipped: no GPU (JAX runs on the CPU, where MJX takes minutes to compile and steps "
        "about 100x slower than C MuJoCo; --mjx-on-cpu runs it anyway)"
    )
    if "batch" in keys:
        keys.remove(BATCH)
        return keys, [note]
    keys[keys.index(BATCH)] = "batch"
    return keys, [note + "; the C MuJoCo batch is the batched engine instead"]


def row_goals(result: dict[str, Any], config: TransferConfig, task: TaskConfig) -> dict:
    """Whether a row meets the success goal and (Touch only) the peak-force goal."""
    peak = result["mean_peak_contact_force"]
    force_met = None
    if task.uses_contact:
        force_met = peak is not None and peak <= config.goal_peak_force
    return {"success_met": result["success_rate"] >= config.goal_success, "force_met": force_met}


def transfer_matrix(
    policy: Any, task: TaskConfig, config: TransferConfig, jax_backend: str, log=print
) -> dict[str, Any]:
    """Evaluate ``policy`` in every planned engine.

    Args:
        policy: observation -> action (single or batched), e.g. :func:`mjx_arm.policy.load`'s.
        task: the task to evaluate in.
        config: the settings.
        jax_backend: JAX's default backend (decides whether MJX runs).
        log: progress lines go here.

    Returns:
        ``config``, ``task``, ``rows`` (one :func:`~mjx_arm.evaluate.evaluate` summary per
        engine, with ``key``, ``label`` and the goals met) and ``notes``.
    """
    from mjx_arm.evaluate import eval_arm, evaluate

    arm = eval_arm(policy, config.arm or None)
    keys, notes = plan_engines(config, jax_backend)
    rows = []
    for key in keys:
        spec = TRANSFER_ENGINES[key]
        log(f"transfer: {spec.label}, {config.episodes} episodes")
        result, _ = evaluate(
            policy,
            spec.engine,
            task,
            config.episodes,
            config.seed,
            backend=spec.backend,
            impl=config.impl,
            arm=arm,
            contact=config.pybullet_contact,
        )
        result.pop("per_episode", None)
        rows.append({"key": key, "label": spec.label, **result, **row_goals(result, config, task)})
    return {"config": config.to_dict(), "task": task.task, "rows": rows, "notes": notes}


def markdown(matrix: dict[str, Any], source: str, trained_on: str) -> str:
    """The table, with a title line and the notes."""
    config = matrix["config"]
    force_goal = f"mean peak force <= {config['goal_peak_force']:g} N"
    headers = [
        "engine",
        "episodes",
        "success",
        "95% CI",
        "mean return",
        "steps to success",
        "mean peak force (N)",
        f"success >= {config['goal_success']:g}",
        force_goal,
    ]
    rows = [
        [
            r["label"],
            r["episodes"],
            f"{r['success_rate']:.3f}",
            f"{r['success_ci95'][0]:.3f}-{r['success_ci95'][1]:.3f}",
            fmt(r["mean_return"]),
            fmt(r["mean_steps_to_success"]),
            fmt(r["mean_peak_contact_force"]),
            verdict(r["success_met"]),
            "n/a (Reach)" if r["force_met"] is None else verdict(r["force_met"]),
        ]
        for r in matrix["rows"]
    ]
    trained = f"; trained on {trained_on}" if trained_on else ""
    title = f"Task {matrix['task']}; policy {source}{trained}.\n"
    notes = "".join(f"\nNote: {n}\n" for n in matrix["notes"])
    return title + "\n" + markdown_table(headers, rows) + notes


def plot(matrix: dict[str, Any], path: Path) -> Path:
    """Success with its Wilson interval and the mean peak force per engine, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows, config = matrix["rows"], matrix["config"]
    labels = [r["label"] for r in rows]
    rate = [r["success_rate"] for r in rows]
    err = [[p - r["success_ci95"][0] for p, r in zip(rate, rows, strict=True)]]
    err.append([r["success_ci95"][1] - p for p, r in zip(rate, rows, strict=True)])
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4))
    left.bar(labels, rate, yerr=err, capsize=4)
    left.axhline(config["goal_success"], color="grey", ls=":")
    left.set(ylim=(0, 1.05), ylabel="success rate (95% Wilson CI)", title="success")
    right.bar(labels, [r["mean_peak_contact_force"] or 0.0 for r in rows], color="C1")
    right.axhline(config["goal_peak_force"], color="grey", ls=":")
    right.set(ylabel="mean peak contact force (N)", title="peak force")
    for ax in (left, right):
        ax.tick_params(axis="x", labelsize="small", rotation=15)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_report(
    matrix: dict[str, Any],
    meta: dict[str, Any],
    folder: str | Path,
    name: str,
    source: str,
    trained_on: str = "",
    png: bool = False,
) -> list[Path]:
    """Write ``<name>.md``, ``<name>.json`` (and ``<name>.png``) into ``folder``."""
    payload = {"meta": meta, "policy": source, "trained_on": trained_on, **matrix}
    paths = list(save_results(name, payload, markdown(matrix, source, trained_on), folder))
    if png:
        paths.append(plot(matrix, Path(folder) / f"{name}.png"))
    return paths
