"""``mjx-arm train``: its command and parser."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from mjx_arm import names
from mjx_arm.inputs import nonnegative_int
from mjx_arm.jax_cache import enable_compilation_cache
from mjx_arm.names import EXIT_OK
from mjx_arm.settings import add_set_argument
from mjx_arm.task.registry import task_names


def cmd_train(args: argparse.Namespace) -> int:
    """Train a PPO policy with Brax on the batched env and write a run directory."""
    import time

    from mjx_arm.train.config import load_config, saved_config
    from mjx_arm.train.ppo import train

    enable_compilation_cache()
    if args.resume:
        run_dir = Path(args.resume)
        config = saved_config(run_dir)
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
        config = _with_arm(config, args.arm, args.ee_link)
        stamp = time.strftime("%Y%m%d-%H%M%S")
        run_dir = Path(args.run_dir or Path("runs") / f"{config.task}-{stamp}")
    print(f"run directory: {run_dir}")
    result = train(config, run_dir, resume=bool(args.resume), quiet=args.quiet)
    print(done_line(result))
    return EXIT_OK


def _with_arm(config, source: str | None, ee_link: str | None):
    """``config`` with the arm of ``--arm`` and ``--ee-link`` (each None: unchanged)."""
    from mjx_arm.urdf.arm_config import load_arm

    arm = load_arm(source) if source else config.arm
    if ee_link:
        arm = arm.replace(ee_link=ee_link, joints=())  # the chain follows the new ee link
    return config.replace(arm=arm)


def done_line(result) -> str:
    """The closing line of a run. Compile time and steady speed need two trained epochs after
    the first evaluation; a shorter run says so instead of printing NaN."""
    success = result.metrics.get("eval/episode_success", float("nan"))
    if math.isfinite(result.compile_seconds) and math.isfinite(result.steps_per_second):
        speed = f"compile {result.compile_seconds:.1f} s, {result.steps_per_second:,.0f} steps/s"
    else:
        speed = "compile time and steps/s need 3 or more evaluations"
    return f"done: {result.steps} steps in {result.train_seconds:.1f} s ({speed}), " + (
        f"eval success {success:.3f}"
    )


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``train`` to ``sub``."""
    p = sub.add_parser(
        "train",
        help="train a PPO policy (Brax) and write a run directory",
        description=cmd_train.__doc__,
    )
    p.add_argument(
        "--task",
        type=str.lower,
        choices=task_names(),
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
        type=nonnegative_int,
        help="local devices to train on, the env batch split evenly over them "
        "(default: all; also on --resume, which may change it)",
    )
    p.add_argument(
        "--arm",
        metavar="URDF_OR_FILE",
        help="the arm: a URDF, or an arm file (.toml/.json: urdf, ee_link, joints, home_qpos, "
        "ft_joint) (default: the shipped UR5e-class arm)",
    )
    p.add_argument(
        "--ee-link",
        help="end-effector link of the arm (default: ee_link, else the tip of the longest "
        "chain of revolute joints)",
    )
    p.add_argument("--config", help="JSON file with training config fields")
    add_set_argument(
        p,
        "override config fields (KEY=VALUE ...; repeatable); task.FIELD=... and "
        "task.reward.TERM=... for the task, physics.FIELD=..., randomization.FIELD=...",
    )
    p.add_argument("--run-dir", help="run directory (default: runs/TASK-TIMESTAMP)")
    p.add_argument("--resume", metavar="RUN_DIR", help="continue the run in RUN_DIR")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_train)
