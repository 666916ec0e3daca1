"""``mjx-arm deploy-sim``: its parser (:func:`register`) and command (:func:`cmd_deploy_sim`)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from mjx_arm import engines
from mjx_arm.inputs import (
    ConfigError,
    OutputPathError,
    check_output,
    int_in,
    seed_int,
    write_atomic,
)
from mjx_arm.names import EXIT_OK
from mjx_arm.settings import add_set_argument, apply_settings, describe

DEFAULT_SCRIPT = "deploy_sim.script"  # where a UR arm's URScript goes without --script


def cmd_deploy_sim(args: argparse.Namespace) -> int:
    """Run a policy through the sim-to-real chain against a position-controlled sim arm.

    policy -> joint velocity targets -> velocity-to-position adapter (first-order filter) ->
    safety limiter (position, velocity, acceleration) -> position servos of a copy of the sim
    arm. The same policy also runs on the normal velocity-controlled env with the same
    episodes. Prints both success rates, the position run's tracking error (joint angles
    against the commands) and its end-effector deviation from the velocity run, and writes the
    URScript (servoj) of the first episode.
    """
    from mjx_arm.arm.info import arm_info
    from mjx_arm.evaluate import eval_arm, resolve_policy
    from mjx_arm.sim2real.deploy import DeployConfig, deploy_sim, write_commands

    for flag, path, suffixes in (
        ("--script", args.script, (".script",)),
        ("--trajectory", args.trajectory, (".json",)),
        ("-o", args.output, ()),
    ):
        if path:
            check_output(path, flag, suffixes)
    config = apply_settings(DeployConfig(), args.set or [])
    policy, source = resolve_policy(args.policy)
    script = script_path(args.script, arm_info(eval_arm(policy, args.arm)), args.trajectory)
    report = deploy_sim(policy, args.engine, args.episodes, args.seed, config, arm=args.arm)
    write_commands(report, config, script, args.trajectory)
    commands = report.pop("commands")
    report = {
        "policy": source,
        **report,
        "script": None if script is None else str(script),
        "trajectory": args.trajectory,
        "script_episode": {"index": commands["index"], "seed": commands["seed"]},
        "script_steps": len(commands["commands"]),
    }
    print(format_report(report))
    if args.output:
        write_atomic(json.dumps(report, indent=2).encode(), Path(args.output))
        print(f"results: {args.output}")
    return EXIT_OK


def script_path(given: str | None, arm: Any, trajectory: str | None = None) -> Path | None:
    """Where deploy-sim writes its URScript: ``--script``, else :data:`DEFAULT_SCRIPT` unless a
    file there is not one mjx-arm wrote; on an arm URScript does not run (not a Universal
    Robots arm: :func:`~mjx_arm.sim2real.deploy.ur_like`) nowhere, with a note saying what to
    use instead (or, where ``trajectory`` names the JointTrajectory file, where it goes).

    Raises:
        ConfigError: ``--script`` for an arm that is not a Universal Robots arm.
        OutputPathError: the default file exists and mjx-arm did not write it.
    """
    from mjx_arm.sim2real.deploy import ur_like, written_urscript

    if not ur_like(arm.joint_names):
        instead = "write a ROS 2 JointTrajectory with --trajectory traj.json instead"
        what = f"{arm.urdf.name} ({arm.n_joints} joints: {', '.join(arm.joint_names[:2])}, ...)"
        if given:
            raise ConfigError(
                f"--script writes URScript, which runs on Universal Robots' 6-joint arms "
                f"only; {what} is not one: {instead}"
            )
        if trajectory:
            instead = f"its ROS 2 JointTrajectory goes to {trajectory}"
        print(
            f"note: no URScript: {what} is not a Universal Robots arm; {instead}", file=sys.stderr
        )
        return None
    if given:
        return Path(given)
    path = Path(DEFAULT_SCRIPT)
    if path.exists() and not written_urscript(path):
        raise OutputPathError(
            f"{path} is there and mjx-arm did not write it; pass --script PATH to write the "
            "URScript elsewhere (or to replace that file), or run in a fresh folder"
        )
    return path


def format_report(report: dict[str, Any]) -> str:
    """Human-readable lines of a deploy-sim report."""
    s = report["settings"]
    vel, pos = report["velocity_control"], report["position_control"]
    track, dev = report["tracking_error_rad"], report["ee_deviation_m"]

    def rate(summary: dict[str, Any]) -> str:
        low, high = summary["success_ci95"]
        return f"{summary['success_rate']:.3f} ({low:.3f}-{high:.3f})"

    def num(value: float | None, fmt: str) -> str:
        return "n/a" if value is None else format(value, fmt)

    clips = sum(sum(kinds.values()) for kinds in report["limiter_clips"].values())

    def row(name: str, key: str, fmt: str) -> str:
        return f"  {name:<24}{num(vel[key], fmt):<22}{num(pos[key], fmt)}"

    lines = [
        f"deploy-sim {report['task']} on {report['engine']}: {report['episodes']} episodes "
        f"(seed {report['seed']}); tau {s['tau']:g} s, acceleration limit "
        f"{s['limiter']['acceleration']:g} rad/s^2, "
        f"position gain {s['servo']['position_gain']:g} /s, "
        + ("feed-forward stream" if s["servo"].get("feedforward") else "held commands"),
        f"  {'':<24}{'velocity control':<22}position control (adapter + limiter)",
        f"  {'success rate (95% CI)':<24}{rate(vel):<22}{rate(pos)}",
        row("mean steps to success", "mean_steps_to_success", ".1f"),
        row("mean return", "mean_return", ".2f"),
        f"  tracking error (rad): max {num(track['max'], '.4f')}, mean {num(track['mean'], '.4f')}"
        " (joint angles against the limiter's commands)",
        f"  ee deviation (m): max {num(dev['max'], '.4f')}, mean {num(dev['mean'], '.4f')}"
        " (position run against velocity run, same episodes)",
        f"  limiter clips: {clips}" + _clip_lines(report["limiter_clips"]),
    ]
    if report.get("script"):
        episode = report["script_episode"]
        lines.append(
            f"URScript: {report['script']} ({report['script_steps']} servoj lines: the longest "
            f"episode, number {episode['index'] + 1}, seed {episode['seed']})"
        )
    if report.get("trajectory"):
        lines.append(f"JointTrajectory: {report['trajectory']}")
    return "\n".join(lines)


def _clip_lines(clips: dict[str, dict[str, int]]) -> str:
    """A line per joint the limiter clipped: its clips by kind (``acceleration 3, ...``)."""
    return "".join(
        f"\n    {joint}: " + ", ".join(f"{kind} {count}" for kind, count in kinds.items())
        for joint, kinds in clips.items()
    )


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``deploy-sim`` subcommand to the ``mjx-arm`` parser's subparsers ``sub``."""
    from mjx_arm.sim2real.settings import DeployConfig

    p = sub.add_parser(
        "deploy-sim",
        help="run a policy through adapter + limiter on a position-controlled sim arm",
        description=cmd_deploy_sim.__doc__,
    )
    p.add_argument("policy", help="policy file (.npz/.onnx) or run directory (newest checkpoint)")
    p.add_argument(
        "--engine",
        choices=engines.engine_names("position_env"),
        default="mujoco",
        help="physics engine (default: mujoco)",
    )
    p.add_argument(
        "--episodes", type=int_in(1, 100_000), default=20, help="episodes per run (default: 20)"
    )
    p.add_argument(
        "--arm",
        help="a URDF, an arm file or a shipped arm's name (ur5e, ur5e_gripper, ...) (default: "
        "the arm the policy was trained on)",
    )
    p.add_argument(
        "--seed", type=seed_int, default=0, help="seed of the first episode (default: 0)"
    )
    add_set_argument(p, "chain settings (defaults: " + ", ".join(describe(DeployConfig())) + ")")
    p.add_argument(
        "--script",
        help="URScript file of the longest episode's commands, for a Universal Robots arm "
        f"(default: {DEFAULT_SCRIPT}, unless a file there is not one mjx-arm wrote; another "
        "make of arm: none, use --trajectory)",
    )
    p.add_argument("--trajectory", help="also write them as a ROS 2 JointTrajectory JSON file")
    p.add_argument("-o", "--output", help="JSON file for the results")
    p.set_defaults(func=cmd_deploy_sim)
