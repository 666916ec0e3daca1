"""``mjx-arm bench``: its parser (:func:`register`) and the ``parity``, ``transfer``, ``seeds`` and
``robustness`` commands.

The flags of each command come from its settings dataclass (:class:`~mjx_arm.bench.parity.
ParityConfig`, :class:`~mjx_arm.bench.transfer.TransferConfig`).
"""

from __future__ import annotations

import argparse
import functools
import os
import time
from pathlib import Path
from typing import TYPE_CHECKING

from mjx_arm import engines
from mjx_arm.bench.results import check_outside_results
from mjx_arm.bench.settings import add_arguments, from_arguments
from mjx_arm.inputs import ConfigError, check_folder
from mjx_arm.names import EXIT_OK, EXIT_STOPPED
from mjx_arm.settings import add_set_argument

if TYPE_CHECKING:
    from mjx_arm.bench.parity_config import ParityConfig
    from mjx_arm.bench.seeds_config import SeedsConfig

# Where a bench command writes without --out: a new folder per run, named as train names its
# runs; the committed benchmarks/results/ is written only where --out names it.
BENCH_RUNS = Path("runs") / "bench"


def _enable_jax_cache() -> None:
    from mjx_arm.jax_cache import enable_compilation_cache

    enable_compilation_cache()


def _on_jax(names: tuple[str, ...] | list[str]) -> bool:
    """Whether any of ``names`` is a batch engine of the registry (MJX: JAX, on an accelerator
    where there is one)."""
    return any(name in engines.batch_engines() for name in names)


def _check_arm(arm: str) -> None:
    """Validate a benchmark's ``--arm`` before any work ("" is the shipped arm).

    Raises:
        InputError: no such file, or an arm that does not validate or resolve.
    """
    if arm:
        from mjx_arm.arm.info import validated_arm_info

        validated_arm_info(arm, engines.CONVERTER_ENGINE)


def _out(args: argparse.Namespace, kind: str) -> Path:
    """``args.out``, set to ``runs/bench/KIND-TIMESTAMP`` where ``--out`` is not given, and
    checked (:func:`~mjx_arm.inputs.check_folder`) before any work.

    Raises:
        OutputPathError: ``--out`` is a file, or no writable folder can hold it.
    """
    if args.out is None:
        args.out = BENCH_RUNS / f"{kind}-{time.strftime('%Y%m%d-%H%M%S')}"
    return check_folder(args.out, "--out")


def _out_help(kind: str) -> str:
    return (
        f"output folder (default: a new {BENCH_RUNS}/{kind}-TIMESTAMP; the committed results: "
        f"--out benchmarks/results/{kind})"
    )


def _print_paths(paths: list[Path]) -> None:
    for path in paths:
        print(f"wrote {path}")


def _check_pictures(args: argparse.Namespace, *flags: str) -> None:
    """Refuse, before any work, the pictures or videos that ``flags`` ask for (``--plot``,
    ``--video``) where ``--out`` lies under ``benchmarks/results`` (JSON and Markdown only).

    Raises:
        ConfigError: such a flag is given and ``--out`` lies under ``benchmarks/results``.
    """
    for flag in flags:
        if getattr(args, flag.removeprefix("--").replace("-", "_")):
            check_outside_results(args.out, f"the files of {flag}", "--out")


def cmd_parity(args: argparse.Namespace) -> int:
    """Engine parity: C MuJoCo, MJX and PyBullet on the same states and actions.

    Forward kinematics at random joint angles; open-loop joint divergence over time (median and
    95th percentile over the sequences); the tared F/T reading while pressing the box; jitter
    while holding still, under a constant command and pressing, with the joint damping as
    converted and zeroed. Writes parity.md and parity.json into --out, with each goal met or
    missed (--plot: three PNG plots too, into an --out outside benchmarks/results). MJX on a
    CPU takes several minutes (compilation, its progress on stderr); --quick is a small run,
    without MJX on a CPU unless --engines names it. --grasp adds the grasp
    check on the gripper arm (grasp.md, grasp.json): the same scripted pick of a cube in each
    engine, off the table and in the air, and its slip in the fingers over 2 s; --grasp-video
    films the pick off the table in each engine.
    """
    from mjx_arm.bench.parity import ParityConfig, run_parity
    from mjx_arm.bench.parity_report import goals_table, write_report
    from mjx_arm.bench.results import environment_metadata

    config = from_arguments(ParityConfig.quick() if args.quick else ParityConfig(), args)
    config = _quick_on_cpu(config, args)
    _out(args, "parity")
    _check_pictures(args, "--plot", "--grasp-video")
    _check_arm(config.arm)
    if _on_jax(config.engines):
        _enable_jax_cache()
    meta = environment_metadata(accelerator=_on_jax(config.engines))
    result = run_parity(config)
    print(goals_table(result))
    _print_paths(write_report(result, meta, args.out, args.plot))
    if args.grasp:
        _print_paths(_grasp_report(config.engines, meta, args.out, args.grasp_video))
    return EXIT_OK


def _quick_on_cpu(config: ParityConfig, args: argparse.Namespace) -> ParityConfig:
    """``--quick`` on a CPU leaves the batch engines (MJX) out, which compile for minutes
    there, unless ``--engines`` names them; says so on stderr."""
    import dataclasses
    import sys

    import jax

    batch = [name for name in config.engines if name in engines.batch_engines()]
    if not (args.quick and args.engines is None and batch and jax.default_backend() == "cpu"):
        return config
    print(
        f"note: --quick on a CPU leaves {', '.join(batch)} out (MJX compiles for minutes "
        f"here); --engines {' '.join(config.engines)} compares them all",
        file=sys.stderr,
    )
    kept = tuple(name for name in config.engines if name not in batch)
    return dataclasses.replace(config, engines=kept)


def _grasp_report(engines: tuple[str, ...], meta: dict, out: Path, video: bool) -> list[Path]:
    """Run the grasp check (:mod:`mjx_arm.bench.grasp`) and write grasp.md and grasp.json (and
    with ``video`` one video of the pick from the table per engine)."""
    from mjx_arm.bench.grasp import grasp_check
    from mjx_arm.bench.results import fmt, markdown_table, save_results

    result = grasp_check(engines, video_dir=out if video else None)
    rows = [
        [start, name, fmt(r["lift_m"], ".3f"), fmt(1000 * r["slip_m"], ".2f"),
         fmt(1000 * r["opening_m"], ".1f"), "pass" if r["met"] else "MISS"]
        for start, runs in result["starts"].items()
        for name, r in runs["engines"].items()
    ]  # fmt: skip
    headers = ["start", "engine", "lift (m)", "slip over 2 s (mm)", "finger opening (mm)",
               "held, <= 5 mm"]  # fmt: skip
    table = markdown_table(headers, rows)
    print(table)
    return list(save_results("grasp", {"meta": meta, **result}, table, out))


def cmd_grasp(args: argparse.Namespace) -> int:
    """Grasp check on the gripper arm alone: the same scripted pick of a cube in each engine,
    off the table and in the air, with the cube's lift and its slip in the fingers over a 2 s
    hold. Writes grasp.md and grasp.json into --out; --video films the pick from the table in
    each engine (grasp_ENGINE.mp4, into an --out outside benchmarks/results). MJX on a CPU
    compiles for about a minute.
    """
    from mjx_arm.bench.results import environment_metadata

    _out(args, "grasp")
    _check_pictures(args, "--video")
    _enable_jax_cache()
    meta = environment_metadata(accelerator=_on_jax(args.engines))
    _print_paths(_grasp_report(tuple(args.engines), meta, args.out, args.video))
    return EXIT_OK


def cmd_transfer(args: argparse.Namespace) -> int:
    """Transfer matrix: one policy evaluated in every engine, beside the goals.

    Success rate with its 95% Wilson interval, mean return, steps to success and mean peak
    contact force per engine; goals: success >= 0.95 in every engine and, for Touch, a mean
    peak force <= 50 N. Without a GPU, MJX is skipped with a note and the C MuJoCo batch runs
    as the batched engine (--mjx-on-cpu runs MJX anyway). Writes NAME.md and NAME.json (and
    NAME.png with --plot, into an --out outside benchmarks/results) into --out.
    """
    import jax

    from mjx_arm.bench.results import environment_metadata
    from mjx_arm.bench.transfer import TransferConfig, transfer_matrix, write_report
    from mjx_arm.evaluate import eval_task, resolve_policy

    config = from_arguments(TransferConfig(), args)
    _out(args, "transfer")
    _check_pictures(args, "--plot")
    _check_arm(config.arm)
    policy, source = resolve_policy(args.policy)
    _enable_jax_cache()
    task, task_notes = eval_task(policy, config.task or None)
    meta = environment_metadata(accelerator=True)
    matrix = transfer_matrix(policy, task, config, jax.default_backend())
    matrix["notes"][:0] = task_notes
    name = args.name or f"transfer_{task.task}"
    paths = write_report(matrix, meta, args.out, name, source, args.trained_on, args.plot)
    print(paths[1].read_text())
    _print_paths(paths)
    return EXIT_OK


def cmd_seeds(args: argparse.Namespace) -> int:
    """Seeds benchmark: train a preset as shipped once per seed; on a GPU host each seed in its own
    process, one per GPU at a time (--devices: how many GPUs; --gpus-per-seed: K GPUs per seed;
    --server: each seed's command run by its GPU's warm trainer, mjx-arm serve).

    For each seed: final and best evaluation success, steps and wall time (from that seed's start,
    compilation included) to the first evaluation at --threshold, or "not reached". Overall: the
    fraction of seeds solved and the median and interquartile range of the time to the threshold,
    over all seeds and over the warm ones (started after a seed had ended, on filled caches). Writes
    NAME.md and NAME.json into --out (and NAME.png, the success curves, with --plot); the runs and
    their logs go to --runs. The report is written again as each seed finishes.
    """
    start = time.time()
    from mjx_arm.bench.results import environment_metadata
    from mjx_arm.bench.seeds import SeedsConfig, check_seed_settings
    from mjx_arm.bench.seeds_gpus import train_seeds
    from mjx_arm.bench.seeds_report import write_report
    from mjx_arm.train.launch import visible_gpus

    config = from_arguments(SeedsConfig(task=args.task or SeedsConfig.task), args)
    _out(args, "seeds")
    _check_pictures(args, "--plot")
    runs_dir = _runs_folder(args.runs, config)
    gpus = _seed_gpus(visible_gpus(), config.devices, config.gpus_per_seed)
    if gpus:  # this process leaves each GPU's memory to the seed trained on it
        os.environ["XLA_PYTHON_CLIENT_PREALLOCATE"] = "false"
    check_seed_settings(config, tuple(args.set or ()), config.gpus_per_seed if gpus else None)
    _enable_jax_cache()
    meta = environment_metadata(accelerator=True)
    overrides = tuple(args.set or ())
    log = functools.partial(print, flush=True)
    name = args.name or f"seeds_{config.task}_{config.preset}"
    report = functools.partial(write_report, config, meta=meta, out=args.out, name=name)
    runs, configs, pending = train_seeds(config, runs_dir, gpus, overrides, start, log, report)
    wall = time.time() - start
    paths = report(runs, configs, overrides=overrides, wall_s=wall, png=args.plot, pending=pending)
    print(paths[1].read_text())
    _print_paths(paths)
    return EXIT_STOPPED if pending else EXIT_OK


def _runs_folder(runs: Path | None, config: SeedsConfig) -> Path:
    """The folder of the seeds' runs: ``runs``, or ``runs/seeds-TASK-PRESET-STAMP``.

    Raises:
        InputError: ``runs`` is not a usable folder, or the folder lies under
            ``benchmarks/results`` (which keeps no runs or logs).
    """
    if runs:
        check_folder(runs, "--runs")
    stamp = time.strftime("%Y%m%d-%H%M%S")
    folder = runs or Path("runs") / f"seeds-{config.task}-{config.preset}-{stamp}"
    check_outside_results(folder, "the runs and their logs", "--runs")
    return folder


def _seed_gpus(gpus: list[str], devices: int, per_seed: int = 1) -> list[str]:
    """The GPU groups the seeds run on: ``devices`` GPUs of ``gpus`` (0: all) in groups of
    ``per_seed``, each a ``CUDA_VISIBLE_DEVICES`` value (``["0,1", "2,3"]`` for 4 GPUs, 2 per
    seed); a group short of ``per_seed`` GPUs is left idle.

    Raises:
        ConfigError: more GPUs asked for than there are, or fewer than one seed needs.
    """
    if devices > len(gpus) and gpus:
        raise ConfigError(f"asked for {devices} GPUs, this host has {len(gpus)}")
    chosen = gpus[: devices or len(gpus)]
    if per_seed > 1 and len(chosen) < per_seed:
        where = f"{len(chosen)} GPU(s) to use" if gpus else "no GPU (JAX sees none)"
        raise ConfigError(
            f"--gpus-per-seed {per_seed} needs {per_seed} GPUs of one host; there is {where}"
        )
    groups = len(chosen) // per_seed
    return [",".join(chosen[g * per_seed : (g + 1) * per_seed]) for g in range(groups)]


def cmd_robustness(args: argparse.Namespace) -> int:
    """Robustness benchmark: one policy's success under perturbations, each alone and all
    together.

    Sweeps servo gain, joint damping and friction, a payload at the flange, the cube's mass and
    friction (Lift), action latency of 0-3 control steps, noise and bias on the joint-angle
    and F/T readings, control-period jitter, the table's height and the box or cube pose,
    each over several values of its stated range (and a little beyond), then draws all of
    them at once. Per point: success with its 95% Wilson interval and the mean and median peak
    wrist force. Runs in the C MuJoCo batch (CPU) or the MJX batch (GPU). Writes NAME.md and
    NAME.json into --out (and NAME.png with --plot, into an --out outside benchmarks/results).
    """
    from mjx_arm.bench.results import environment_metadata
    from mjx_arm.bench.robustness import RobustnessConfig, run_robustness, write_report
    from mjx_arm.evaluate import eval_task, resolve_policy
    from mjx_arm.evaluate.core import check_policy_fits, eval_arm

    base = RobustnessConfig.quick() if args.quick else RobustnessConfig()
    config = from_arguments(base, args)
    _out(args, "robustness")
    _check_pictures(args, "--plot")
    policy, source = resolve_policy(args.policy)
    arm = eval_arm(policy, args.arm or None)
    _enable_jax_cache()
    task, _ = eval_task(policy)
    from mjx_arm.arm.info import arm_info

    check_policy_fits(policy, task, arm_info(arm))
    meta = environment_metadata(accelerator=_on_jax([config.engine]))
    result = run_robustness(policy, task, config, arm, log=lambda t: print(t, flush=True))
    name = args.name or f"robustness_{task.task}"
    paths = write_report(result, meta, args.out, name, source, args.plot)
    print(paths[1].read_text())
    _print_paths(paths)
    return EXIT_OK


def _command(commands, func, help_text: str, config: type) -> argparse.ArgumentParser:
    """The parser of ``func`` (named after it), with the flags of its settings ``config``."""
    p = commands.add_parser(
        func.__name__.removeprefix("cmd_"), help=help_text, description=func.__doc__
    )
    p.set_defaults(func=func)
    add_arguments(p, config)
    return p


def _add_robustness(commands) -> None:
    """The ``robustness`` subcommand's parser."""
    from mjx_arm.bench.robustness_config import RobustnessConfig

    p = _command(
        commands, cmd_robustness, "one policy under perturbations: success, peak force",
        RobustnessConfig,
    )  # fmt: skip
    p.add_argument("policy", help="policy file (.npz/.onnx) or run directory (newest checkpoint)")
    p.add_argument("--quick", action="store_true", help="a small run (8 episodes per point)")
    p.add_argument("--arm", default="", help="the arm file or URDF (default: the policy's)")
    p.add_argument("--name", help="file stem (default: robustness_TASK)")
    p.add_argument("--plot", action="store_true", help="also write NAME.png (success per point)")
    p.add_argument("--out", type=Path, help=_out_help("robustness"))


def _add_parity(commands) -> None:
    """The ``parity`` subcommand's parser."""
    from mjx_arm.bench.parity_config import ParityConfig

    p = _command(commands, cmd_parity, "engine parity: FK, divergence, force, jitter", ParityConfig)
    p.add_argument(
        "--quick",
        action="store_true",
        help="a small run (tests, a first look); on a CPU without MJX unless --engines names "
        "it (MJX compiles for minutes there)",
    )
    p.add_argument(
        "--grasp", action="store_true", help="also the grasp check on the gripper arm (grasp.md)"
    )
    p.add_argument(
        "--grasp-video",
        action="store_true",
        help="with --grasp: one video of the pick from the table per engine (grasp_ENGINE.mp4)",
    )
    p.add_argument("--plot", action="store_true", help="also write the three PNG plots")
    p.add_argument("--out", type=Path, help=_out_help("parity"))


def _add_grasp(commands) -> None:
    """The ``grasp`` subcommand's parser."""
    p = commands.add_parser(
        "grasp", help="the gripper's scripted pick in every engine", description=cmd_grasp.__doc__
    )
    p.set_defaults(func=cmd_grasp)
    parity = engines.engine_names("parity")
    p.add_argument("--engines", nargs="+", choices=parity, default=list(parity))
    p.add_argument("--video", action="store_true", help="film the pick from the table per engine")
    p.add_argument("--out", type=Path, help=_out_help("grasp"))


def register(sub) -> None:
    """Add ``bench`` with its ``parity``, ``grasp``, ``transfer``, ``robustness`` and ``seeds``
    subcommands to ``sub``."""
    from mjx_arm.bench.seeds_config import SeedsConfig
    from mjx_arm.bench.transfer import TransferConfig

    bench = sub.add_parser(
        "bench",
        help="benchmarks: engine parity, policy transfer, training over seeds",
        description="Engine benchmarks that write a markdown table and JSON (PNG plots with "
        "--plot, into a folder outside benchmarks/results) into --out, by default a new "
        "runs/bench/KIND-TIMESTAMP.",
    )
    commands = bench.add_subparsers(dest="bench_command", required=True, metavar="BENCH")
    _add_parity(commands)
    _add_grasp(commands)

    p = _command(commands, cmd_transfer, "one policy in every engine, with goals", TransferConfig)
    p.add_argument("policy", help="policy file (.npz/.onnx) or run directory (newest checkpoint)")
    p.add_argument("--trained-on", default="", help="where the policy was trained (text)")
    p.add_argument("--name", help="file stem (default: transfer_TASK)")
    p.add_argument("--plot", action="store_true", help="also write NAME.png")
    p.add_argument("--out", type=Path, help=_out_help("transfer"))

    _add_robustness(commands)

    p = _command(commands, cmd_seeds, "a preset over seeds: fraction solved, times", SeedsConfig)
    add_set_argument(
        p, "change the preset (exploration; the report then says so, never 'as shipped')"
    )
    p.add_argument("--name", help="file stem (default: seeds_TASK_PRESET)")
    p.add_argument("--plot", action="store_true", help="also write NAME.png (success curves)")
    p.add_argument("--runs", type=Path, help="where the runs go (default: runs/seeds-...)")
    p.add_argument("--out", type=Path, help=_out_help("seeds"))
