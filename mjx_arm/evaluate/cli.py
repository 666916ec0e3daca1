"""``mjx-arm eval`` and ``replay``: a policy's numbers in any engine, and its trajectories."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from mjx_arm import engines, names
from mjx_arm.inputs import (
    ConfigError,
    check_output,
    int_in,
    nonnegative_int,
    pixels,
    seed_int,
    write_atomic,
)
from mjx_arm.jax_cache import enable_compilation_cache
from mjx_arm.names import EXIT_OK
from mjx_arm.task.registry import task_names
from mjx_arm.urdf.repair_args import add_repair_arguments

VIDEO_SUFFIXES = (".mp4", ".gif")
MAX_EPISODES = 100_000
DEFAULT_VIDEO_EPISODES = 10  # episodes --video films unless --video-episodes says otherwise


def cmd_eval(args: argparse.Namespace) -> int:
    """Evaluate a policy file or a run directory (newest checkpoint) on one engine.

    Prints the success rate with its 95% Wilson interval, the mean return, the mean steps to
    success and the mean peak contact force (--json: as JSON instead), and saves them as JSON
    with -o. CPU engines reset episode i with seed + i, so mujoco and pybullet see the same
    episodes; --video films the first episodes (--video-episodes).
    """
    from mjx_arm.evaluate import eval_arm, eval_task, evaluate, resolve_policy
    from mjx_arm.urdf.repair_args import with_repair_arguments

    _check_eval_outputs(args)
    _check_contact(args.pybullet_contact)
    policy, source = resolve_policy(args.policy, args.step)
    task, notes = eval_task(policy, args.task)
    arm = with_repair_arguments(eval_arm(policy, args.arm), args)
    backend = None
    if args.engine in engines.batch_engines():  # the batched JAX env
        from mjx_arm.envs.backend import resolve_backend

        enable_compilation_cache()
        backend = resolve_backend(args.backend)
    result, run = evaluate(
        policy,
        args.engine,
        task,
        args.episodes,
        args.seed,
        args.video,
        args.width,
        args.height,
        backend=backend,
        video_episodes=args.video_episodes or min(args.episodes, DEFAULT_VIDEO_EPISODES),
        impl=args.impl,
        arm=arm,
        contact=args.pybullet_contact,
    )
    result = {"policy": str(source), **result, "notes": notes + result["notes"]}
    _write_eval(args, result, run.trajectory, task, arm)
    return EXIT_OK


def _check_contact(contact: str | None) -> None:
    """Check ``--pybullet-contact`` before any work (None: the default contact)."""
    if contact is None:
        return
    from pybullet_ref.contact import SceneContact

    try:
        SceneContact.parse(contact)
    except ConfigError as err:
        raise ConfigError(f"--pybullet-contact: {err}") from err


def _write_eval(
    args: argparse.Namespace, result: dict[str, Any], trajectory: Any, task: Any, arm: Any
) -> None:
    """Print the result (a few lines; --json: one JSON line without the episodes) and save
    what eval's arguments ask for (the first episode's ``trajectory`` of ``task`` on ``arm``,
    the ``result`` as JSON), saying where."""
    import json

    from mjx_arm.evaluate import format_summary
    from mjx_arm.replay import save_trajectory

    if args.json:
        print(json.dumps({k: v for k, v in result.items() if k != "per_episode"}))
    else:
        print(format_summary(result))
    say = (lambda text: print(text, file=sys.stderr)) if args.json else print
    if args.trajectory:
        say(f"trajectory: {save_trajectory(args.trajectory, trajectory, task, arm)}")
    if result["video"]:
        say(f"video: {result['video']} ({video_contents(result)})")
    if args.output:
        write_atomic(json.dumps(result, indent=2).encode(), Path(args.output))
        say(f"results: {args.output}")


def video_contents(result: dict[str, Any]) -> str:
    """What an evaluation's video shows: its episodes (their seeds) and frames."""
    frames, episodes = result["video_frames"], result["video_episodes"]
    if result["engine"] in engines.batch_engines():
        return f"env 0's episode, re-rendered in CPU MuJoCo, {frames} frames"
    seeds = (
        f"seed {result['seed']}"
        if episodes == 1
        else (f"seeds {result['seed']}-{result['seed'] + episodes - 1}")
    )
    return f"the first {episodes} of {result['episodes']} episodes ({seeds}), {frames} frames"


def _check_eval_outputs(args: argparse.Namespace) -> None:
    """Check eval's output paths before any work (:func:`~mjx_arm.inputs.check_output`)."""
    if args.video:
        check_output(args.video, "--video", VIDEO_SUFFIXES)
    if args.trajectory:
        check_output(args.trajectory, "--trajectory", (".npz",))
    if args.output:
        check_output(args.output, "-o")


def cmd_replay(args: argparse.Namespace) -> int:
    """Plot a trajectory (reward, ee x/y/z, contact force; the largest reward drop marked).

    Reads transitions.npz from a checkpoint or a file written by mjx-arm eval --trajectory;
    with --video, renders each step's joint angles and target through MuJoCo, on the arm the
    trajectory was recorded on (--arm draws another arm of as many joints).
    """
    from mjx_arm.replay import replay

    check_output(args.output, "-o", (".png",))
    if args.video:
        check_output(args.video, "--video", VIDEO_SUFFIXES)
    summary = replay(
        args.trajectory, args.output, args.video, args.width, args.height, args.task, args.arm
    )
    drop = summary["largest_reward_drop_step"]
    drop = "none" if drop is None else f"at step {drop}"
    print(
        f"{summary['steps']} steps, return {summary['return']:.2f}, task {summary['task']} "
        f"(from {summary['task_from']}), largest reward drop {drop}"
    )
    print(f"plot: {summary['plot']}")
    if summary["video"]:
        print(f"video: {summary['video']} ({summary['frames']} frames)")
        print(f"arm: {summary['arm']} (from {summary['arm_from']})")
    if "video_note" in summary:
        print(summary["video_note"])
    return EXIT_OK


def _add_eval(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "eval",
        help="evaluate a policy: success rate (95%% CI), return, force",
        description=cmd_eval.__doc__,
    )
    p.add_argument("policy", help="policy file (.npz/.onnx) or run directory (newest checkpoint)")
    _add_eval_run(p)
    _add_eval_arm(p)
    _add_eval_outputs(p)
    p.set_defaults(func=cmd_eval)


def _add_eval_run(p: argparse.ArgumentParser) -> None:
    """eval's engine, checkpoint and episodes."""
    p.add_argument(
        "--engine",
        choices=engines.eval_engines(),
        default="mujoco",
        help="mujoco or pybullet (Gymnasium env, CPU) or mjx (the batched JAX env, on the "
        "physics of --backend) (default: mujoco)",
    )
    p.add_argument(
        "--backend",
        choices=names.BACKENDS,
        default="auto",
        help="physics of --engine mjx: mjx (MJX: on a GPU; on a CPU minutes to compile), "
        "mujoco (C MuJoCo: seconds on a CPU), auto (mjx on an accelerator, else mujoco; the "
        "default, as train and the demo)",
    )
    p.add_argument(
        "--impl",
        choices=names.IMPLS,
        default="auto",
        help="MJX implementation for --engine mjx (default: auto: Warp on a GPU where installed)",
    )
    p.add_argument(
        "--step", type=nonnegative_int, help="checkpoint step of a run directory (default: newest)"
    )
    p.add_argument(
        "--episodes", type=int_in(1, MAX_EPISODES), default=50, help="episodes (default: 50)"
    )
    p.add_argument(
        "--seed", type=seed_int, default=0, help="seed of the first episode (default: 0)"
    )


def _add_eval_arm(p: argparse.ArgumentParser) -> None:
    """eval's task, arm (and its repairs) and PyBullet contact."""
    p.add_argument(
        "--task",
        type=str.lower,
        choices=task_names(),
        help="task (default: the one the policy was trained on)",
    )
    p.add_argument(
        "--arm",
        help="the arm: a URDF, an arm file (.toml/.json) or a shipped arm's name (ur5e, "
        "ur5e_gripper, ...) (default: the arm the policy was "
        "trained on; a policy run on another arm is an error)",
    )
    add_repair_arguments(p, "the arm (a policy trained with repairs records them)")
    p.add_argument(
        "--pybullet-contact",
        help="PyBullet's scene contact: soft (compliant, calibrated on MuJoCo; the default), "
        "rigid (Bullet's own), or FIXED/CUBE springs as STIFFNESS:DAMPING (N/m:N s/m)",
    )


def _add_eval_outputs(p: argparse.ArgumentParser) -> None:
    """eval's video, trajectory and JSON outputs."""
    p.add_argument("--video", help="video of the first episodes (.mp4 or .gif)")
    p.add_argument(
        "--video-episodes",
        type=int_in(1, MAX_EPISODES),
        help=f"episodes --video films (default: {DEFAULT_VIDEO_EPISODES}, or every episode "
        "when fewer; --engine mjx films env 0's episode)",
    )
    p.add_argument("--width", type=pixels, default=640, help="video width (default: 640)")
    p.add_argument("--height", type=pixels, default=480, help="video height (default: 480)")
    p.add_argument("--trajectory", help="save the first episode as a trajectory .npz (replay)")
    p.add_argument("-o", "--output", help="JSON file for the results")
    p.add_argument("--json", action="store_true", help="print the results as one JSON line instead")


def _add_replay(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "replay", help="plot (and film) a recorded trajectory", description=cmd_replay.__doc__
    )
    p.add_argument("trajectory", help="trajectory .npz (transitions.npz or from eval)")
    p.add_argument("-o", "--output", required=True, help="PNG plot to write")
    p.add_argument("--video", help="also render a video (.mp4 or .gif) through MuJoCo")
    p.add_argument("--width", type=pixels, default=800, help="plot and video width (default: 800)")
    p.add_argument(
        "--height", type=pixels, default=600, help="plot and video height (default: 600)"
    )
    p.add_argument(
        "--task",
        type=str.lower,
        choices=task_names(),
        help="scene to render (default: from the file or its run directory)",
    )
    p.add_argument(
        "--arm",
        help="the arm to draw: a URDF, an arm file or a shipped arm's name (default: the arm "
        "the trajectory was recorded on, from the file or its run directory)",
    )
    p.set_defaults(func=cmd_replay)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``eval`` and ``replay`` to ``sub``."""
    _add_eval(sub)
    _add_replay(sub)
