"""``mjx-arm demo``: the whole product on a CPU in a few minutes.

1. validate the arm's URDF (three layers, MuJoCo and PyBullet; the shipped arm unless
   ``--arm`` names another) and write the MJCF of the model Reach trains on
   (``<urdf stem>_reach.xml``);
2. train Reach with Brax PPO (preset ``cpu``, backend ``auto``);
3. export the policy to ``.npz`` (and ``.onnx`` when onnxruntime is installed) and check that
   the exports agree with each other;
4. evaluate it on the three engines (:func:`mjx_arm.engines.eval_engines`): CPU MuJoCo, PyBullet
   and ``mjx``, the batched JAX env (backend ``mjx`` on an accelerator, ``mujoco`` on a CPU),
   filming the first MuJoCo episodes (skipped, with a note, where MuJoCo cannot render);
5. plot the longest MuJoCo episode;
6. print and save a summary with the path of every file written.
"""

from __future__ import annotations

import importlib.util
import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mjx_arm.engines import REFERENCE_ENGINE, batch_engines, eval_engines
from mjx_arm.inputs import InputError
from mjx_arm.names import engine_label

if TYPE_CHECKING:
    from mjx_arm.arm.config import ArmConfig
    from mjx_arm.evaluate import EvalRun


class DemoError(InputError, RuntimeError):
    """The demo cannot run (e.g. its output folder already holds a run)."""


@dataclass(frozen=True)
class DemoSettings:
    """How much the demo does.

    Attributes:
        timesteps: PPO env steps (Brax rounds up to whole epochs).
        num_evals: evaluations during training.
        episodes: evaluation episodes per engine.
        video_episodes: episodes in the MuJoCo video.
        width, height: video frame size (pixels).
    """

    timesteps: int
    num_evals: int
    episodes: int
    video_episodes: int
    width: int
    height: int


TASK = "reach"  # what the demo trains; the MJCF it writes is this task's model
# The file that marks a folder as the demo's: the demo replaces its own files only.
MARKER = ".mjx_arm_demo"
FULL = DemoSettings(300_000, 6, 50, 10, 640, 480)
QUICK = DemoSettings(122_880, 4, 20, 2, 320, 240)


class _Log:
    """Step headers and timings, printed as they happen."""

    def __init__(self, echo: Callable[[str], None] = print) -> None:
        self.echo, self.start, self.timings = echo, time.monotonic(), {}

    def step(self, name: str, text: str) -> float:
        self.echo(f"\n== {text}")
        self.timings[name] = time.monotonic()
        return self.timings[name]

    def done(self, name: str) -> None:
        self.timings[name] = round(time.monotonic() - self.timings[name], 1)


# --------------------------------------------------------------------------- the steps


def validate_and_convert(
    out: Path, echo: Callable[[str], None], arm: ArmConfig | None = None, task: str = TASK
) -> dict[str, Any]:
    """Validate ``arm`` (default: the shipped arm) for both engines, with the repairs its config
    allows, and write the MJCF of ``task``'s model: the arm in the task's scene, as the envs
    build it (``<urdf stem>_<task>.xml``)."""
    import mujoco

    from mjx_arm.arm.config import ArmConfig
    from mjx_arm.arm.info import arm_info
    from mjx_arm.arm.model_io import task_convert_config
    from mjx_arm.task.config import task_config
    from mjx_arm.urdf import to_mjcf
    from mjx_arm.urdf.errors import report_error
    from mjx_arm.urdf.validate import validate

    arm = arm or ArmConfig()
    urdf = arm.urdf_path
    report = validate(
        urdf,
        engine="all",
        repair_inertia=arm.repair_inertia,
        default_limits=arm.default_limits(),
    )
    echo(f"{urdf}: {len(report.errors)} errors, {len(report.warnings)} warnings")
    if not report.ok:  # the line names the fix: a repair flag the demo takes, where one is
        raise report_error(DemoError, report)
    mjcf = out / f"{urdf.stem}_{task}.xml"
    mjcf.write_text(to_mjcf(urdf, task_convert_config(task_config(task), arm_info(arm))))
    model = mujoco.MjModel.from_xml_path(str(mjcf))
    echo(
        f"wrote {mjcf} ({task.capitalize()}'s model): {model.nbody} bodies, "
        f"{model.nu} velocity actuators, {model.nsensor} sensors"
    )
    return {"urdf": str(urdf), "warnings": len(report.warnings), "mjcf": str(mjcf)}


def train_reach(
    run_dir: Path,
    settings: DemoSettings,
    echo: Callable[[str], None],
    arm: ArmConfig | None = None,
):
    """Train Reach (preset cpu, backend auto) on ``arm`` (default: the shipped arm) into
    ``run_dir``; returns Brax's TrainResult."""
    from mjx_arm.envs.backend import resolve_backend
    from mjx_arm.train.ppo import train
    from mjx_arm.train.presets import load_config

    config = load_config(
        "cpu",
        overrides=[
            f"task={TASK}",
            "backend=auto",
            f"num_timesteps={settings.timesteps}",
            f"num_evals={settings.num_evals}",
        ],
    )
    if arm is not None:
        config = config.replace(arm=arm)
    echo(
        f"backend {resolve_backend(config.backend)}, {config.num_envs} envs, "
        f"{config.num_timesteps:,} steps -> {run_dir}"
    )
    result = train(config, run_dir)
    success = result.metrics.get("eval/episode_success", float("nan"))
    echo(
        f"{trained_steps(run_dir):,} steps in {result.train_seconds:.0f} s "
        f"(compiled in {result.compile_seconds:.0f} s), training eval success {success:.2f}"
    )
    return result


def trained_steps(run_dir: Path) -> int:
    """Env steps of the newest checkpoint (Brax rounds ``num_timesteps`` up to whole epochs)."""
    from mjx_arm.policy.export import available_steps

    steps = available_steps(run_dir)
    return steps[-1] if steps else 0


def export_all(run_dir: Path, out: Path, echo: Callable[[str], None]) -> dict[str, Any]:
    """Export .npz (and .onnx when possible) and measure how far the runtimes disagree."""
    from mjx_arm.policy import export_policy, load

    paths = {"npz": export_policy(run_dir, out / "policy.npz")}
    have_onnx = all(importlib.util.find_spec(m) for m in ("onnx", "onnxruntime"))
    if have_onnx:
        paths["onnx"] = export_policy(run_dir, out / "policy.onnx")
    else:
        echo("onnx/onnxruntime not installed: skipping policy.onnx (pip install 'mjx_arm[onnx]')")
    info: dict[str, Any] = {k: str(v) for k, v in paths.items()}
    states = _probe_states(load(paths["npz"]), np.random.default_rng(0))
    if have_onnx:
        diff = np.abs(load(paths["npz"])(states) - load(paths["onnx"])(states)).max()
        info["npz_vs_onnx_max_abs_diff"] = float(diff)
    for path in paths.values():
        echo(f"wrote {path} ({path.stat().st_size / 1024:.0f} KiB)")
    if "npz_vs_onnx_max_abs_diff" in info:
        echo(f"numpy and onnxruntime actions agree to {info['npz_vs_onnx_max_abs_diff']:.1e}")
    return info


def _probe_states(policy: Any, rng: np.random.Generator, n: int = 256) -> np.ndarray:
    """Random observations ``(n, 22)`` around the policy's normaliser statistics."""
    mean = getattr(policy, "mean", np.zeros(policy.obs_size, np.float32))
    std = getattr(policy, "std", np.ones(policy.obs_size, np.float32))
    return (mean + std * rng.standard_normal((n, policy.obs_size))).astype(np.float32)


def evaluate_engines(
    policy_path: Path, out: Path, settings: DemoSettings, echo: Callable[[str], None]
) -> tuple[dict[str, dict], EvalRun]:
    """Evaluate on CPU MuJoCo (filming the first episodes), PyBullet and ``mjx`` (the batched
    JAX env on the ``auto`` backend), on the arm the policy records.

    Returns:
        Results per engine name (``eval_<engine>.json`` each) and the
        :class:`~mjx_arm.evaluate.EvalRun` of the reference engine (CPU MuJoCo, filmed).
    """
    from mjx_arm.envs.backend import resolve_backend
    from mjx_arm.evaluate import eval_arm, eval_task, evaluate, format_summary
    from mjx_arm.policy import load

    policy = load(policy_path)
    task, _ = eval_task(policy)
    arm = eval_arm(policy)  # the arm the policy was trained on
    backend = resolve_backend("auto")
    runs: dict[str, dict] = {}
    filmed = None
    for engine in eval_engines():
        reference = engine == REFERENCE_ENGINE
        video = out / f"episodes_{engine}.mp4" if reference else None
        result, run = evaluate(
            policy,
            engine,
            task,
            settings.episodes,
            seed=0,
            video=video,
            width=settings.width,
            height=settings.height,
            backend=backend if engine in batch_engines() else None,
            video_episodes=settings.video_episodes,
            arm=arm,
        )
        result["policy"] = str(policy_path)
        path = out / f"eval_{engine}.json"
        path.write_text(json.dumps(result, indent=2))
        result["json"] = str(path)
        runs[engine] = {k: v for k, v in result.items() if k != "per_episode"}
        echo(format_summary(result))
        filmed = run if reference else filmed
    return runs, filmed


def plot_episode(
    run: EvalRun, policy_path: str, out: Path, echo: Callable[[str], None]
) -> dict[str, Any]:
    """Save the reference engine's longest episode of the policy at ``policy_path`` as a
    trajectory (with the policy's task and arm) and plot it."""
    from mjx_arm.evaluate import eval_arm, eval_task
    from mjx_arm.policy import load
    from mjx_arm.replay import replay, save_trajectory

    policy = load(policy_path)
    path = out / f"trajectory_{REFERENCE_ENGINE}.npz"
    task, arm = eval_task(policy)[0], eval_arm(policy)
    traj_path = save_trajectory(path, run.longest_trajectory(), task, arm)
    summary = replay(traj_path, out / "replay.png")
    echo(f"wrote {traj_path} ({summary['steps']} steps) and {summary['plot']}")
    return {"trajectory": str(traj_path), "plot": summary["plot"]}


# --------------------------------------------------------------------------- the demo


def default_out() -> Path:
    """``runs/demo-YYYYmmdd-HHMMSS`` in the working directory."""
    return Path("runs") / f"demo-{time.strftime('%Y%m%d-%H%M%S')}"


def demo_files(urdf_stem: str) -> tuple[str, ...]:
    """The names the demo writes into its folder (``urdf_stem``: the arm URDF's stem)."""
    engines = eval_engines()
    return (
        f"{urdf_stem}_{TASK}.xml",
        "run",
        "policy.npz",
        "policy.onnx",
        *(f"eval_{engine}.json" for engine in engines),
        f"episodes_{REFERENCE_ENGINE}.mp4",
        f"trajectory_{REFERENCE_ENGINE}.npz",
        "replay.png",
        "summary.json",
    )


def claim_out(out: Path, urdf_stem: str) -> None:
    """Make ``out`` the demo's folder, marked by :data:`MARKER`: refuse a folder that holds a
    demo run, or a file of a name the demo writes that no demo wrote (no marker there).

    Raises:
        DemoError: ``out`` holds a run, or a file the demo would replace that is not its own.
    """
    if (out / "run" / "checkpoints").exists():
        raise DemoError(f"{out} already holds a demo run; choose another --out")
    if not (out / MARKER).is_file():
        taken = [name for name in demo_files(urdf_stem) if (out / name).exists()]
        if taken:
            raise DemoError(
                f"{out} holds {', '.join(taken)}, which the demo would replace and did not "
                "write; pass a fresh folder with --out"
            )
    out.mkdir(parents=True, exist_ok=True)
    (out / MARKER).write_text("a folder of mjx-arm demo's outputs\n")


def run_demo(
    out: str | Path | None = None,
    quick: bool = False,
    echo: Callable[[str], None] = print,
    arm: str | Path | ArmConfig | None = None,
) -> dict[str, Any]:
    """Run the demo into ``out``; print and return its summary (also in ``out/summary.json``).

    Args:
        out: output folder (default: :func:`default_out`).
        quick: the smaller settings (:data:`QUICK`).
        echo: where progress lines go.
        arm: a URDF or an arm file (default: the shipped arm). The evaluation runs the
            policy on the arm it recorded: this one.

    Raises:
        DemoError: ``out`` already holds a training run or a file the demo did not write
            (:func:`claim_out`), or the arm's URDF is invalid.
    """
    from mjx_arm.arm.config import load_arm

    arm_config = load_arm(arm) if arm else None
    settings = QUICK if quick else FULL
    out = Path(out) if out is not None else default_out()
    claim_out(out, (arm_config or load_arm(None)).urdf_path.stem)
    log = _Log(echo)
    summary: dict[str, Any] = {"out": str(out), "quick": quick, "settings": vars(settings)}
    summary["arm"] = (arm_config.urdf if arm_config else "") or "shipped"
    summary.update(_steps(out, settings, log, arm_config))
    summary["timings_s"] = log.timings
    summary["wall_seconds"] = round(time.monotonic() - log.start, 1)
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=str))
    echo(format_demo_summary(summary))
    return summary


def _steps(out: Path, settings: DemoSettings, log: _Log, arm: ArmConfig | None) -> dict[str, Any]:
    """The demo's five steps into ``out``, each timed into ``log``; their summaries by name
    (``urdf``, ``train``, ``export``, ``eval``, ``replay``)."""
    echo, run_dir, summary = log.echo, out / "run", {}
    log.step("validate", f"1/5 validate the arm and write {TASK.capitalize()}'s MJCF")
    summary["urdf"] = validate_and_convert(out, echo, arm)
    log.done("validate")
    log.step("train", f"2/5 train {TASK.capitalize()} with Brax PPO")
    trained = train_reach(run_dir, settings, echo, arm)
    summary["train"] = {
        "run_dir": str(run_dir),
        "steps": trained_steps(run_dir),
        "seconds": round(trained.train_seconds, 1),
        "eval_success": trained.metrics.get("eval/episode_success"),
    }
    log.done("train")
    log.step("export", "3/5 export the policy")
    summary["export"] = export_all(run_dir, out, echo)
    log.done("export")
    log.step("evaluate", f"4/5 evaluate ({settings.episodes} episodes per engine)")
    summary["eval"], run = evaluate_engines(Path(summary["export"]["npz"]), out, settings, echo)
    log.done("evaluate")
    log.step("replay", "5/5 plot the longest MuJoCo episode")
    summary["replay"] = plot_episode(run, summary["export"]["npz"], out, echo)
    log.done("replay")
    return summary


def _video_line(result: dict[str, Any]) -> str:
    if result["video"]:
        return result["video"]
    skipped = [n for n in result["notes"] if n.startswith("video")]
    return skipped[0] if skipped else "none"


def format_demo_summary(summary: dict[str, Any]) -> str:
    """The closing table: numbers per engine and the files written."""
    lines = [
        "",
        f"== demo done in {summary['wall_seconds']:.0f} s "
        f"(train {summary['timings_s']['train']:.0f} s)",
        f"{'engine':<22}{'success':>9}{'95% CI':>17}{'return':>10}{'steps':>8}{'peak N':>9}",
    ]
    for engine, r in summary["eval"].items():
        low, high = r["success_ci95"]
        steps = r["mean_steps_to_success"]
        name = engine_label(engine, r.get("backend"))
        lines.append(
            f"{name:<22}{r['success_rate']:>9.3f}{f'{low:.3f} - {high:.3f}':>17}"
            f"{r['mean_return']:>10.2f}{'n/a' if steps is None else f'{steps:.1f}':>8}"
            f"{r['mean_peak_contact_force']:>9.2f}"
        )
    files = [
        (f"MJCF ({TASK} model)", summary["urdf"]["mjcf"]),
        ("run directory", summary["train"]["run_dir"]),
        *((f"policy .{k}", v) for k, v in summary["export"].items() if k in ("npz", "onnx")),
        *((f"eval {k} JSON", r["json"]) for k, r in summary["eval"].items()),
        ("trajectory", summary["replay"]["trajectory"]),
        ("replay plot", summary["replay"]["plot"]),
        ("video", _video_line(summary["eval"][REFERENCE_ENGINE])),
        ("summary", str(Path(summary["out"]) / "summary.json")),
    ]
    lines.append("files:")
    lines += [f"  {name:<20}{path}" for name, path in files]
    return "\n".join(lines)
