"""The ``mjx-arm`` command line. Each subcommand lives in a small function below."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

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

    _enable_compilation_cache()
    if args.resume:
        run_dir = Path(args.resume)
        saved = json.loads((run_dir / "config.json").read_text())["train"]
        config = TrainConfig.from_dict(saved)
    else:
        overrides = list(args.set or [])
        if args.task:
            overrides.insert(0, f"task={args.task.lower()}")
        if args.backend:
            overrides.insert(0, f"backend={args.backend}")
        config = load_config(args.preset, args.config, overrides)
        stamp = time.strftime("%Y%m%d-%H%M%S")
        run_dir = Path(args.run_dir or Path("runs") / f"{config.task}-{stamp}")
    print(f"run directory: {run_dir}")
    result = train(config, run_dir, resume=bool(args.resume), quiet=args.quiet)
    success = result.metrics.get("eval/episode_success", float("nan"))
    print(f"done: {result.steps} steps in {result.train_seconds:.1f} s "
          f"(compile {result.compile_seconds:.1f} s, {result.steps_per_second:,.0f} steps/s), "
          f"eval success {success:.3f}")
    return EXIT_OK


def _enable_compilation_cache() -> None:
    """JAX's persistent compilation cache under ~/.cache (MJX_ARM_JAX_CACHE overrides)."""
    import os

    import jax

    folder = os.environ.get("MJX_ARM_JAX_CACHE",
                            str(Path.home() / ".cache" / "mjx_arm" / "jax"))
    jax.config.update("jax_compilation_cache_dir", folder)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


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

    p = sub.add_parser("train", help="train a PPO policy (Brax) and write a run directory",
                       description=cmd_train.__doc__)
    p.add_argument("--task", type=str.lower, choices=["reach", "touch"],
                   help="task to train (default: the preset's)")
    p.add_argument("--preset", choices=["seed", "fast", "cpu"], default="seed",
                   help="hyperparameter preset (default: seed)")
    p.add_argument("--backend", choices=["auto", "mjx", "mujoco"],
                   help="physics: mjx (GPU), mujoco (C MuJoCo, CPU), auto (default)")
    p.add_argument("--config", help="JSON file with training config fields")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a config field (repeatable); task.FIELD=... for the task")
    p.add_argument("--run-dir", help="run directory (default: runs/TASK-TIMESTAMP)")
    p.add_argument("--resume", metavar="RUN_DIR", help="continue the run in RUN_DIR")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_train)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``mjx-arm`` console script."""
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
