"""``mjx-arm arm``: what an arm config resolves to (end effector, joints, home pose, F/T point,
reach), and an arm file to start from."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from mjx_arm.names import EXIT_OK


def cmd_arm(args: argparse.Namespace) -> int:
    """Show the arm the tasks would drive: the defaults an arm config takes from its URDF.

    With -o, also writes the resolved config as an arm file (TOML) to edit and pass to --arm.
    """
    from mjx_arm.envs.arm import validated_arm_info
    from mjx_arm.inputs import check_output, write_atomic
    from mjx_arm.urdf.arm_config import load_arm

    if args.output:  # named errors (bad files, bad arm) go to mjx_arm.cli.main
        check_output(args.output, "-o", (".toml",))
    config = load_arm(args.arm)
    if args.ee_link:
        config = config.replace(ee_link=args.ee_link, joints=())
    arm = validated_arm_info(config, "mujoco")
    print(describe(arm))
    if args.output:
        write_atomic(arm_file_text(arm).encode(), Path(args.output))
        print(f"wrote {args.output}")
    return EXIT_OK


def describe(arm) -> str:
    """Human-readable lines of an :class:`~mjx_arm.envs.arm.ArmInfo`."""
    ft = arm.ft_joint or f"the last arm joint (tool link {arm.ft_link!r})"
    lines = [
        f"urdf        {arm.urdf}",
        f"ee_link     {arm.ee_link}",
        f"joints      {arm.n_joints}: observation {16 + arm.n_joints}, action {arm.n_joints}",
    ]
    for name, q, lo, hi, v in zip(
        arm.joint_names, arm.home_qpos, arm.lower, arm.upper, arm.v_max, strict=True
    ):
        lines.append(f"  {name:<24} home {q:+.4f}  range [{lo:+.3f}, {hi:+.3f}]  v_max {v:g}")
    lines += [
        f"F/T         {ft}; tool {arm.tool.mass:.3f} kg",
        f"reach scale {arm.reach_scale:.3f} (targets drawn in the task box times this)",
        f"collision   {arm.config.collision}",
    ]
    return "\n".join(lines)


def arm_file_text(arm) -> str:
    """The resolved arm as TOML: every default written out."""
    values = {
        "urdf": str(arm.urdf),
        "ee_link": arm.ee_link,
        "joints": list(arm.joint_names),
        "home_qpos": [round(float(q), 6) for q in arm.home_qpos],
        "ft_joint": arm.ft_joint,
        "collision": arm.config.collision,
    }
    body = "\n".join(f"{key} = {json.dumps(value)}" for key, value in values.items())
    return f"# An arm file (mjx-arm train --arm THIS_FILE); every field as resolved.\n{body}\n"


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``arm`` to ``sub``."""
    p = sub.add_parser(
        "arm", help="show what an arm config resolves to", description=cmd_arm.__doc__
    )
    p.add_argument("arm", help="a URDF or an arm file (.toml/.json)")
    p.add_argument("--ee-link", help="end-effector link (default: from the URDF)")
    p.add_argument("-o", "--output", help="write the resolved config as an arm file (.toml)")
    p.set_defaults(func=cmd_arm)
