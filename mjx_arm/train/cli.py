"""``mjx-arm train``: its command and parser."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from mjx_arm import names
from mjx_arm.inputs import ConfigError, nonnegative_int, positive_int
from mjx_arm.jax_cache import enable_compilation_cache
from mjx_arm.names import EXIT_OK
from mjx_arm.settings import (
    LazyHelpAction,
    LinesHelpFormatter,
    add_field_flags,
    add_set_argument,
    field_flag_settings,
)
from mjx_arm.task.registry import task_names
from mjx_arm.train.run_lines import devices_note, done_line, end_lines, start_lines
from mjx_arm.urdf.repair_args import add_repair_arguments, with_repair_arguments

if TYPE_CHECKING:
    from mjx_arm.train.config import TrainConfig

DEFAULT_PRESET = "seed"
# Fields of the training config that are flags of their own: --seed N is --set seed=N.
FIELD_FLAGS = ("seed",)
# What each preset is for (its size is read from the preset; docs/training.md says more).
PRESET_USES = {
    "seed": "the seed document's PPO settings, for a GPU",
    "fast": "fastest to a solved task on one GPU",
    "cpu": "a small run for a CPU, with --backend mujoco",
    "robust": "fast under randomised physics, for transfer; for a GPU",
}


def cmd_train(args: argparse.Namespace) -> int:
    """Train a PPO policy with Brax on the batched env and write a run directory.

    On several hosts, the same command on each with --coordinator, --hosts and --host-rank
    (or MJX_ARM_COORDINATOR, MJX_ARM_HOSTS / SLURM_NNODES and MJX_ARM_HOST_RANK /
    SLURM_NODEID), joined by jax.distributed. On MuJoCo Warp, --devices N starts a process per
    GPU of this host (docs/training.md, "Several devices").
    """
    from mjx_arm.train.compile_report import mark

    mark("command read")
    if getattr(args, "server", False):
        from mjx_arm.train.client import train_through_server

        code = train_through_server(args.argv)
        if code is not None:
            return code
    if args.resume:
        _check_resume_flags(args)
    named = args.resume or args.run_dir
    group, launched = _group_or_launch(args, named)
    if group is None:
        return launched
    from mjx_arm.train.ppo import train  # JAX, MuJoCo, Brax, Warp: seconds on a GPU host

    mark("trainer imported")
    group.join()
    enable_compilation_cache()
    config = _run_config(args)
    mark("config read")
    run_dir = Path(named) if named else default_run_dir(args, config.task)
    if getattr(args, "check_repeat", False):
        return check_repeat(config, run_dir, args.quiet)
    if group.joined:
        config = config.replace(devices=0)  # every process trains on all of its devices
    if group.leader:
        start_lines(run_dir, config, None if args.resume else args.preset or DEFAULT_PRESET)
        devices_note(args.devices, config)
    result = train(config, run_dir, resume=bool(args.resume), quiet=args.quiet or not group.leader)
    if group.leader:
        end_lines(result, run_dir, args.quiet)
    return EXIT_OK


def _group_or_launch(args: argparse.Namespace, named: str | None):
    """``(group, None)``: the process group this process trains in (started by a launcher, or
    this host's share of several). ``(None, exit code)`` where this host starts a process per
    GPU instead: they ran under this launcher, which never imports the trainer."""
    import sys

    from mjx_arm.train import launch
    from mjx_arm.train.distributed import Hosts, ProcessGroup
    from mjx_arm.train.rundir import claim

    group = ProcessGroup.from_env()  # set where a launcher started this process
    if group.joined:
        return group, None
    hosts = Hosts.from_args(args.coordinator, args.hosts, args.host_rank, args.join_timeout)
    plan = launch.plan(hosts, args.devices, per_gpu=_per_gpu(args))
    if not plan.spawns:
        return plan.group, None
    run_dir = Path(named) if named else default_run_dir(args)  # one, named, for every process
    if not args.resume:  # checked (rundir.claim) before the processes write logs/
        claim(run_dir)
    print(f"run directory: {run_dir}")
    argv = _child_argv(sys.argv[1:], run_dir, bool(named))
    return None, launch.run(plan, argv, run_dir / "logs")


def check_repeat(config: TrainConfig, run_dir: Path, quiet: bool = False) -> int:
    """Train ``config`` twice, in ``run_dir/repeat-a`` and ``repeat-b``, and print where the
    two runs part (:func:`~mjx_arm.train.repeat.compare_runs`). Returns 0 when they are
    identical, 1 when they differ."""
    from mjx_arm.train.ppo import train
    from mjx_arm.train.repeat import compare_runs

    runs = [run_dir / "repeat-a", run_dir / "repeat-b"]
    for i, run in enumerate(runs):
        print(f"repeat: run {i + 1} of 2 in {run}")
        print(done_line(train(config, run, quiet=quiet)))
    report = compare_runs(*runs)
    print(report.line())
    return EXIT_OK if report.identical else 1


def _run_config(args: argparse.Namespace) -> TrainConfig:
    """The run's config: the flags', or a resumed run's saved one (on --devices where given)."""
    from mjx_arm.train.config import saved_config

    if not args.resume:
        return config_from_args(args)
    config = saved_config(args.resume)
    if args.devices is not None:  # a run resumes on any number of devices
        config = config.replace(devices=args.devices)
    return config


def _check_resume_flags(args: argparse.Namespace) -> None:
    """A resumed run keeps the config it was started with: the flags that would change it are
    an error, not silently dropped.

    Raises:
        ConfigError: ``--resume`` with --task, --preset, --backend, --arm, --ee-link, --config,
            --set or a repair flag.
    """
    from mjx_arm.urdf.repair_args import given_repair_flags

    flags = {
        "--task": args.task,
        "--preset": args.preset,
        "--backend": args.backend,
        "--arm": args.arm,
        "--ee-link": args.ee_link,
        "--config": args.config,
        "--set": args.set,
        **{f"--{name}": getattr(args, f"field_{name}", None) for name in FIELD_FLAGS},
    }
    given = [flag for flag, value in flags.items() if value] + given_repair_flags(args)
    if given:
        raise ConfigError(
            f"--resume continues a run with the config it was started with, so {', '.join(given)} "
            "would be ignored: drop them (only --devices, --quiet and the host flags go with "
            "--resume), or start a new run with --run-dir"
        )


def default_run_dir(args: argparse.Namespace, task: str | None = None) -> Path:
    """``runs/TASK-TIMESTAMP`` (the task of the flags, else of the preset)."""
    import time

    from mjx_arm.train.presets import preset_config

    task = task or args.task or preset_config(args.preset or DEFAULT_PRESET).task
    return Path("runs") / f"{task}-{time.strftime('%Y%m%d-%H%M%S')}"


def _per_gpu(args: argparse.Namespace) -> bool:
    """Whether ``--devices`` GPUs train in a process each (the physics from the flags alone,
    without loading the arm: :func:`~mjx_arm.train.launch.per_gpu_wanted`)."""
    from mjx_arm.train import launch
    from mjx_arm.train.config import saved_config
    from mjx_arm.train.presets import load_config

    if args.devices is None or args.devices < 2:
        return launch.process_per_gpu()
    if args.resume:
        config = saved_config(args.resume)
    else:
        overrides = [f"task={args.task.lower()}"] if args.task else []
        overrides += [f"backend={args.backend}"] if args.backend else []
        overrides += list(args.set or [])
        config = load_config(args.preset or DEFAULT_PRESET, args.config, overrides)
    return launch.per_gpu_wanted(args.devices, config.backend, config.physics.impl)


def _child_argv(argv: list[str], run_dir: Path, named: bool) -> list[str]:
    """``train``'s arguments for a started process: the run directory named."""
    return argv if named else [*argv, "--run-dir", str(run_dir)]


def config_from_args(args: argparse.Namespace):
    """The training config of ``train``'s (or ``warmup``'s) flags: the preset for the task,
    then ``--config``, ``--set``, ``--devices``, ``--backend``, ``--arm``, ``--ee-link`` and the
    repair flags (``--repair-inertia``, ...: the arm config's fields, saved with the run)."""
    from mjx_arm.train.presets import load_config

    overrides = list(args.set or [])
    if args.devices is not None:
        overrides.insert(0, f"devices={args.devices}")
    if args.task:
        overrides.insert(0, f"task={args.task.lower()}")
    if args.backend:
        overrides.insert(0, f"backend={args.backend}")
    if getattr(args, "deterministic", False):
        overrides.append("deterministic=true")
    overrides += field_flag_settings(args, FIELD_FLAGS)
    config = load_config(args.preset or DEFAULT_PRESET, args.config, overrides)
    config = _with_arm(config, args.arm, args.ee_link)
    config = config.scaled_for_devices(args.devices or 1)  # scale_with_devices: grown batch
    return config.replace(arm=with_repair_arguments(config.arm, args))


def cmd_warmup(args: argparse.Namespace) -> int:
    """Fill the compilation caches for a task, arm and preset ahead of time.

    Runs one epoch of the training (same config, same programs) in a temporary folder, so that
    a later `mjx-arm train` or `mjx-arm bench seeds` of that task, arm and preset (any seed)
    loads its compiled programs and kernels instead of compiling them. Prints where the caches
    live: copy those folders into a container image or point every job of a cluster at a
    shared copy with the environment variables shown.
    """
    from mjx_arm.envs.backend import resolve_backend
    from mjx_arm.train.warmup import cache_locations, warm_up

    enable_compilation_cache()
    config = config_from_args(args)
    preset = args.preset or DEFAULT_PRESET
    print(f"warming up {config.task} on {config.arm.urdf or 'the shipped arm'} ({preset})")
    result = warm_up(config, quiet=args.quiet)
    if args.quiet:  # else the compile line came after the epoch, with the bar
        print(result.compile_summary)
    print("caches (share these folders between machines of the same GPU and versions):")
    for what, where in cache_locations().items():
        print(f"  {what}: {where}")
    if resolve_backend(config.backend) == "mujoco":
        print(
            "note: on the C MuJoCo backend the reset, rollout and evaluation call C MuJoCo "
            "through host callbacks, which JAX's cache cannot store (they compile again in a "
            "new process); the learner init and the PPO update are cached. Under MJX "
            "(--backend mjx) every program is."
        )
    return EXIT_OK


def _with_arm(config, source: str | None, ee_link: str | None):
    """``config`` with the arm of ``--arm`` and ``--ee-link`` (each None: unchanged)."""
    from mjx_arm.arm.config import load_arm

    arm = load_arm(source) if source else config.arm
    if ee_link:
        arm = arm.replace(ee_link=ee_link, joints=())  # the chain follows the new ee link
    return config.replace(arm=arm)


def _add_config_arguments(p: argparse.ArgumentParser) -> None:
    """The flags that choose a training config (``train`` and ``warmup``)."""
    p.add_argument(
        "--task",
        type=str.lower,
        choices=task_names(),
        help="task to train (default: the preset's)",
    )
    p.add_argument(
        "--preset", choices=names.PRESET_NAMES, action=LazyHelpAction, help_text=preset_help
    )
    p.add_argument(
        "--backend",
        choices=names.BACKENDS,
        help="physics: mjx (GPU), mujoco (C MuJoCo, CPU), auto (default)",
    )
    p.add_argument(
        "--devices",
        type=nonnegative_int,
        help="devices of this host to train on: N > 1 multiplies the preset's envs, minibatch "
        "size, budget and first evaluated step by N, split evenly over them; on a GPU host one "
        "process per GPU (default: all; also on --resume, which keeps the run's totals)",
    )
    p.add_argument(
        "--arm",
        metavar="URDF_OR_FILE",
        help="the arm: a URDF, a shipped arm's name (ur5e, ur5e_gripper, ...), or an arm file "
        "(.toml/.json: urdf, ee_link, joints, home_qpos, "
        "ft_joint) (default: the shipped UR5e-class arm)",
    )
    p.add_argument(
        "--ee-link",
        help="end-effector link of the arm (default: ee_link, else the tip of the longest "
        "chain of revolute joints)",
    )
    add_repair_arguments(p, "the arm, saved with the run")
    _add_setting_arguments(p)


def _add_setting_arguments(p: argparse.ArgumentParser) -> None:
    """The flags that change the preset's settings (``train`` and ``warmup``)."""
    add_field_flags(p, _train_config_class, FIELD_FLAGS)
    p.add_argument(
        "--deterministic",
        action="store_true",
        help="the same seed, config, GPU model, device count and versions give the same run, "
        "bit for bit (XLA's deterministic ops; MJX steps its JAX physics, not MuJoCo Warp; "
        "a CPU run always repeats)",
    )
    p.add_argument("--config", help="JSON file with training config fields")
    add_set_argument(
        p,
        "override config fields (KEY=VALUE ...; repeatable); task.FIELD=... and "
        "task.reward.TERM=... for the task, physics.FIELD=..., randomization.FIELD=...",
    )


def _train_config_class() -> type:
    """The training config's class (imported when asked: it imports JAX and Brax)."""
    from mjx_arm.train.config import TrainConfig

    return TrainConfig


def preset_help() -> str:
    """``--preset``'s help: each preset on a line, with its envs, steps and use."""
    from mjx_arm.train.presets import PRESETS

    lines = [f"hyperparameter preset (default: {DEFAULT_PRESET}; a task may change its budget):"]
    for name, config in PRESETS.items():
        size = f"{config.num_envs:,} envs, {config.num_timesteps / 1e6:g}M env steps"
        lines.append(f"  {name}: {size}: {PRESET_USES[name]}")
    return "\n".join(lines)


def _add_host_arguments(p: argparse.ArgumentParser) -> None:
    """The flags of a training over several hosts (docs/training.md, several hosts)."""
    p.add_argument(
        "--coordinator",
        metavar="HOST:PORT",
        help="several hosts: host 0's address and a free port, the same on every host "
        "(default: $MJX_ARM_COORDINATOR)",
    )
    p.add_argument(
        "--hosts",
        type=positive_int,
        help="several hosts: how many run this command (default: $MJX_ARM_HOSTS, "
        "$SLURM_NNODES, else 1)",
    )
    p.add_argument(
        "--host-rank",
        type=nonnegative_int,
        help="several hosts: this host's rank, 0 to hosts-1; host 0 logs and writes the run "
        "directory (default: $MJX_ARM_HOST_RANK, $SLURM_NODEID, else 0)",
    )
    p.add_argument(
        "--join-timeout",
        type=positive_int,
        help="seconds to wait for every host's processes at the start (default: 300)",
    )


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``train`` and ``warmup`` to ``sub``."""
    p = sub.add_parser(
        "train",
        help="train a PPO policy (Brax) and write a run directory",
        description=cmd_train.__doc__,
        formatter_class=LinesHelpFormatter,
    )
    _add_config_arguments(p)
    p.add_argument(
        "--run-dir",
        help="run directory: a new or empty folder, or one an earlier mjx-arm train wrote "
        "(default: runs/TASK-TIMESTAMP)",
    )
    p.add_argument("--resume", metavar="RUN_DIR", help="continue the run in RUN_DIR")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument(
        "--check-repeat",
        action="store_true",
        help="train the config twice (RUN_DIR/repeat-a and repeat-b) and report the first "
        "step where the runs differ (exit 0: identical, 1: they differ); give a short budget "
        "with --set num_timesteps=N",
    )
    p.add_argument(
        "--server",
        action="store_true",
        help="train in the warm trainer `mjx-arm serve` started (socket: $MJX_ARM_SERVER or "
        "its default): a seed of a config it has trained starts at once; where none answers, "
        "train in this process",
    )
    _add_host_arguments(p)
    p.set_defaults(func=cmd_train)
    w = sub.add_parser(
        "warmup",
        help="fill the compilation caches for a task and arm ahead of time",
        description=cmd_warmup.__doc__,
        formatter_class=LinesHelpFormatter,
    )
    _add_config_arguments(w)
    w.add_argument("--quiet", action="store_true", help="no progress bar")
    w.set_defaults(func=cmd_warmup)
