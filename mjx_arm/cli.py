"""The ``mjx-arm`` command line. Each subcommand lives in a small function below."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from mjx_arm import names
from mjx_arm.jax_cache import enable_compilation_cache

EXIT_OK, EXIT_INVALID = 0, 2


def _package_dirs(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items or []:
        name, sep, folder = item.partition("=")
        if not sep:
            raise SystemExit(f"--package expects NAME=DIR, got {item!r}")
        out[name] = folder
    return out


def cmd_validate(args: argparse.Namespace) -> int:
    """Validate a URDF in three layers and print every finding."""
    from mjx_arm.urdf.validate import validate

    report = validate(args.urdf, engine=args.engine, package_dirs=_package_dirs(args.package))
    print(report.format())
    return EXIT_OK if report.ok else EXIT_INVALID


def cmd_convert(args: argparse.Namespace) -> int:
    """Validate a URDF for MuJoCo, convert it to MJCF and write the XML."""
    from mjx_arm.urdf import ConversionError, ConvertConfig, to_mjcf
    from mjx_arm.urdf.validate import validate

    package_dirs = _package_dirs(args.package)
    report = validate(
        args.urdf,
        engine="mujoco",
        package_dirs=package_dirs,
        native=False,
        repair_inertia=args.repair_inertia,
    )
    if not report.ok:
        print(report.format(), file=sys.stderr)
        return EXIT_INVALID
    config = ConvertConfig(
        scene=args.scene, package_dirs=package_dirs, repair_inertia=args.repair_inertia
    )
    try:
        xml = to_mjcf(args.urdf, config)
    except ConversionError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    Path(args.output).write_text(xml)
    print(_summary(args.output))
    return EXIT_OK


def _summary(mjcf_path: str) -> str:
    import mujoco

    model = mujoco.MjModel.from_xml_path(mjcf_path)
    joints = [model.joint(i).name for i in range(model.njnt) if model.jnt_type[i] != 0]
    lines = [
        f"wrote {mjcf_path}",
        f"  bodies {model.nbody}, joints {len(joints)}, velocity actuators {model.nu}, "
        f"sensors {model.nsensor}, timestep {model.opt.timestep:.6f} s",
        f"  joint damping {', '.join(f'{d:g}' for d in model.dof_damping)}",
    ]
    return "\n".join(lines)


def cmd_train(args: argparse.Namespace) -> int:
    """Train a PPO policy with Brax on the batched env and write a run directory."""
    import json
    import time

    from mjx_arm.train.config import TrainConfig, load_config
    from mjx_arm.train.ppo import train
    from mjx_arm.train.rundir import RunDirError

    enable_compilation_cache()
    if args.resume:
        run_dir = Path(args.resume)
        saved = json.loads((run_dir / "config.json").read_text())["train"]
        config = TrainConfig.from_dict(saved)
        if args.devices is not None:  # a run resumes on any number of devices
            config = config.replace(devices=args.devices)
    else:
        overrides = list(args.set or [])
        if args.devices is not None:
            overrides.insert(0, f"devices={args.devices}")
        if args.task:
            overrides.insert(0, f"task={args.task.lower()}")
        if args.backend:
            overrides.insert(0, f"backend={args.backend}")
        config = load_config(args.preset, args.config, overrides)
        stamp = time.strftime("%Y%m%d-%H%M%S")
        run_dir = Path(args.run_dir or Path("runs") / f"{config.task}-{stamp}")
    print(f"run directory: {run_dir}")
    try:
        result = train(config, run_dir, resume=bool(args.resume), quiet=args.quiet)
    except RunDirError as err:
        print(f"error: {err}", file=sys.stderr)
        return EXIT_INVALID
    success = result.metrics.get("eval/episode_success", float("nan"))
    print(
        f"done: {result.steps} steps in {result.train_seconds:.1f} s "
        f"(compile {result.compile_seconds:.1f} s, {result.steps_per_second:,.0f} steps/s), "
        f"eval success {success:.3f}"
    )
    return EXIT_OK


def cmd_export(args: argparse.Namespace) -> int:
    """Export a run's policy (normaliser, MLP, action scaling, contract version, config).

    The suffix of each -o picks the format: .npz runs with numpy alone, .onnx with onnxruntime.
    """
    from mjx_arm.policy.export import export_run

    for output in args.output:
        try:
            path = export_run(args.run_dir, output, step=args.step)
        except (FileNotFoundError, ValueError, ImportError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_INVALID
        print(f"wrote {path} ({path.stat().st_size / 1024:.0f} KiB)")
    return EXIT_OK


def cmd_eval(args: argparse.Namespace) -> int:
    """Evaluate a policy file or a run directory (newest checkpoint) on one engine.

    Prints the success rate with its 95% Wilson interval, the mean return, the mean steps to
    success and the mean peak contact force, and saves them as JSON with -o. CPU engines reset
    episode i with seed + i, so mujoco and pybullet see the same episodes.
    """
    import json

    from mjx_arm.evaluate import eval_task, evaluate, format_summary, resolve_policy
    from mjx_arm.replay import save_trajectory

    if args.engine == "mjx":
        enable_compilation_cache()
        _warn_mjx_on_cpu()
    policy, source = resolve_policy(args.policy, args.step)
    task, notes = eval_task(policy, args.task)
    result, run = evaluate(
        policy,
        args.engine,
        task,
        args.episodes,
        args.seed,
        args.video,
        args.width,
        args.height,
        impl=args.impl,
    )
    result = {"policy": str(source), **result, "notes": notes + result["notes"]}
    print(format_summary(result))
    if args.trajectory:
        print(f"trajectory: {save_trajectory(args.trajectory, run.trajectory, task)}")
    if result["video"]:
        print(f"video: {result['video']}")
    if args.output:
        Path(args.output).parent.mkdir(parents=True, exist_ok=True)
        Path(args.output).write_text(json.dumps(result, indent=2))
        print(f"results: {args.output}")
    print(json.dumps({k: v for k, v in result.items() if k != "per_episode"}))
    return EXIT_OK


def _warn_mjx_on_cpu() -> None:
    import jax

    if jax.default_backend() == "cpu":
        print(
            "note: --engine mjx runs MJX (JAX) on the CPU here: compiling takes minutes and "
            "stepping is about 100x slower than C MuJoCo",
            file=sys.stderr,
        )


def cmd_replay(args: argparse.Namespace) -> int:
    """Plot a trajectory (reward, ee x/y/z, contact force; the largest reward drop marked).

    Reads transitions.npz from a checkpoint or a file written by mjx-arm eval --trajectory;
    with --video, renders each step's joint angles and target through MuJoCo.
    """
    from mjx_arm.replay import replay

    try:
        summary = replay(
            args.trajectory, args.output, args.video, args.width, args.height, args.task
        )
    except (OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    drop = summary["largest_reward_drop_step"]
    print(
        f"{summary['steps']} steps, return {summary['return']:.2f}, task {summary['task']} "
        f"(from {summary['task_from']}), largest reward drop at step {drop}"
    )
    print(f"plot: {summary['plot']}")
    if summary["video"]:
        print(f"video: {summary['video']} ({summary['frames']} frames)")
    if "video_note" in summary:
        print(summary["video_note"])
    return EXIT_OK


def cmd_demo(args: argparse.Namespace) -> int:
    """The whole product on a CPU: validate and convert the arm, train Reach, export the
    policy, evaluate it in CPU MuJoCo, PyBullet and the batched JAX env, plot and film it.

    About 1-2 minutes on a 2-core CPU (--quick: under a minute).
    """
    from mjx_arm.demo import DemoError, run_demo

    enable_compilation_cache()
    try:
        run_demo(args.out, quick=args.quick)
    except DemoError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    return EXIT_OK


def _add_policy_commands(sub) -> None:
    """Parsers of export, eval, replay and demo."""
    p = sub.add_parser(
        "export",
        help="export a run's policy to .npz (numpy) or .onnx",
        description=cmd_export.__doc__,
    )
    p.add_argument("run_dir", help="training run directory")
    p.add_argument(
        "-o",
        "--output",
        action="append",
        required=True,
        help="policy file to write, .npz or .onnx (repeatable)",
    )
    p.add_argument("--step", type=int, help="checkpoint step (default: the newest)")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser(
        "eval",
        help="evaluate a policy: success rate (95%% CI), return, force",
        description=cmd_eval.__doc__,
    )
    p.add_argument("policy", help="policy file (.npz/.onnx) or run directory (newest checkpoint)")
    p.add_argument(
        "--engine",
        choices=names.EVAL_ENGINES,
        default="mujoco",
        help="mujoco or pybullet (Gymnasium env, CPU) or mjx (the batched MJX env; "
        "on a CPU it still runs MJX, only slowly: minutes to compile, about "
        "100x slower than C MuJoCo) (default: mujoco)",
    )
    p.add_argument(
        "--impl",
        choices=names.IMPLS,
        default="auto",
        help="MJX implementation for --engine mjx (default: auto: Warp on a GPU where installed)",
    )
    p.add_argument("--step", type=int, help="checkpoint step of a run directory (default: newest)")
    p.add_argument("--episodes", type=int, default=50, help="episodes (default: 50)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first episode (default: 0)")
    p.add_argument(
        "--task",
        type=str.lower,
        choices=names.TASKS,
        help="task (default: the one the policy was trained on)",
    )
    p.add_argument("--video", help="video of the first episode (.mp4 or .gif)")
    p.add_argument("--width", type=int, default=640, help="video width (default: 640)")
    p.add_argument("--height", type=int, default=480, help="video height (default: 480)")
    p.add_argument("--trajectory", help="save the first episode as a trajectory .npz (replay)")
    p.add_argument("-o", "--output", help="JSON file for the results")
    p.set_defaults(func=cmd_eval)

    p = sub.add_parser(
        "replay", help="plot (and film) a recorded trajectory", description=cmd_replay.__doc__
    )
    p.add_argument("trajectory", help="trajectory .npz (transitions.npz or from eval)")
    p.add_argument("-o", "--output", required=True, help="PNG plot to write")
    p.add_argument("--video", help="also render a video (.mp4 or .gif) through MuJoCo")
    p.add_argument("--width", type=int, default=800, help="plot and video width (default: 800)")
    p.add_argument("--height", type=int, default=600, help="plot and video height (default: 600)")
    p.add_argument(
        "--task",
        type=str.lower,
        choices=names.TASKS,
        help="scene to render (default: from the file or its run directory)",
    )
    p.set_defaults(func=cmd_replay)

    p = sub.add_parser(
        "demo", help="the whole pipeline on a CPU in a few minutes", description=cmd_demo.__doc__
    )
    p.add_argument("--out", help="output folder (default: runs/demo-TIMESTAMP)")
    p.add_argument(
        "--quick", action="store_true", help="shorter training, fewer episodes, smaller video"
    )
    p.set_defaults(func=cmd_demo)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    parser = argparse.ArgumentParser(
        prog="mjx-arm",
        description="Train and check 6-DoF arm control policies (URDF -> MJCF -> MJX + Brax PPO).",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser(
        "validate",
        help="validate a URDF (XML/tree, engine compatibility, physics)",
        description=cmd_validate.__doc__,
    )
    p.add_argument("urdf", help="path of the URDF file")
    p.add_argument(
        "--engine",
        choices=["mujoco", "pybullet", "all"],
        default="all",
        help="engine(s) to check compatibility with and load into (default: all)",
    )
    p.add_argument(
        "--package",
        action="append",
        metavar="NAME=DIR",
        help="directory of a package:// name (repeatable)",
    )
    p.set_defaults(func=cmd_validate)

    p = sub.add_parser(
        "convert", help="convert a URDF to an MJX-ready MJCF", description=cmd_convert.__doc__
    )
    p.add_argument("urdf", help="path of the URDF file")
    p.add_argument("-o", "--output", required=True, help="MJCF file to write")
    p.add_argument(
        "--scene",
        choices=["none", "reach", "touch"],
        default="none",
        help="add the task scene (floor, table, target) around the arm",
    )
    p.add_argument(
        "--package",
        action="append",
        metavar="NAME=DIR",
        help="directory of a package:// name (repeatable)",
    )
    p.add_argument(
        "--repair-inertia",
        action="store_true",
        help="replace inertia tensors that break the triangle inequality",
    )
    p.set_defaults(func=cmd_convert)

    p = sub.add_parser(
        "train",
        help="train a PPO policy (Brax) and write a run directory",
        description=cmd_train.__doc__,
    )
    p.add_argument(
        "--task",
        type=str.lower,
        choices=names.TASKS,
        help="task to train (default: the preset's)",
    )
    p.add_argument(
        "--preset",
        choices=names.PRESET_NAMES,
        default="seed",
        help="hyperparameter preset (default: seed)",
    )
    p.add_argument(
        "--backend",
        choices=names.BACKENDS,
        help="physics: mjx (GPU), mujoco (C MuJoCo, CPU), auto (default)",
    )
    p.add_argument(
        "--devices",
        type=int,
        help="local devices to train on, the env batch split evenly over them "
        "(default: all; also on --resume, which may change it)",
    )
    p.add_argument("--config", help="JSON file with training config fields")
    p.add_argument(
        "--set",
        action="extend",
        nargs="+",
        metavar="KEY=VALUE",
        help=(
            "override config fields (KEY=VALUE ...; repeatable); task.FIELD=... and "
            "task.reward.TERM=... for the task, physics.FIELD=..., randomization.FIELD=..."
        ),
    )
    p.add_argument("--run-dir", help="run directory (default: runs/TASK-TIMESTAMP)")
    p.add_argument("--resume", metavar="RUN_DIR", help="continue the run in RUN_DIR")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_train)
    _add_policy_commands(sub)
    from mjx_arm.sim2real.cli import register

    register(sub)
    from mjx_arm.bench.cli import register as register_bench

    register_bench(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``mjx-arm`` console script."""
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
