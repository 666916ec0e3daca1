"""``mjx-arm arm``: what an arm config resolves to (end effector, joints, F/T point, servo,
reach), with ``--check`` each task's derived setup and verdict, and an arm file to start from.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from mjx_arm.engines import CONVERTER_ENGINE
from mjx_arm.names import EXIT_OK


def cmd_arm(args: argparse.Namespace) -> int:
    """Show the arm the tasks would drive: the defaults an arm config takes from its URDF.

    With --check, also each task's setup derived from the model (home pose, task area, episode)
    and whether the arm can do the task, and why not. With --picture P.png, draws the home pose
    over the task area into P.png (nothing is drawn unless asked). With -o, writes the resolved
    config as an arm file (TOML) to edit and pass to --arm. Every file written is named.
    """
    from mjx_arm.arm.config import load_arm
    from mjx_arm.arm.info import validated_arm_info
    from mjx_arm.arm.report import arm_file_text, check_lines, describe, draw_check
    from mjx_arm.arm.setup import arm_setup
    from mjx_arm.inputs import check_output, write_atomic
    from mjx_arm.names import TASKS
    from mjx_arm.task.config import task_config
    from mjx_arm.urdf.repair_args import with_repair_arguments

    if args.output:  # named errors (bad files, bad arm) go to mjx_arm.cli.main
        check_output(args.output, "-o", (".toml",))
    picture = args.picture
    if picture:
        check_output(picture, "--picture", (".png",))
    config = with_repair_arguments(load_arm(args.arm), args)
    if args.ee_link:
        config = config.replace(ee_link=args.ee_link, joints=())
    arm = validated_arm_info(config, CONVERTER_ENGINE)
    print(describe(arm))
    tasks = [task_config(name) for name in TASKS]
    if args.check:
        print(check_lines(arm, tasks))
    if picture:
        draw_check(arm, tasks, Path(picture))
        print(f"wrote the picture of the home pose over the task area to {Path(picture).resolve()}")
    elif args.check:
        print("(add --picture P.png to draw the home pose over the task area)")
    if args.output:
        touch = None if config.home_qpos else arm_setup(arm, task_config("touch"))
        write_atomic(arm_file_text(arm, touch).encode(), Path(args.output))
        print(f"wrote {args.output}")
    return EXIT_OK


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``arm`` to ``sub``."""
    from mjx_arm.urdf.repair_args import add_repair_arguments

    p = sub.add_parser(
        "arm", help="show what an arm config resolves to", description=cmd_arm.__doc__
    )
    p.add_argument("arm", help="a URDF or an arm file (.toml/.json)")
    p.add_argument("--ee-link", help="end-effector link (default: from the URDF)")
    add_repair_arguments(p, "the arm, written with -o")
    p.add_argument("-o", "--output", help="write the resolved config as an arm file (.toml)")
    p.add_argument(
        "--check",
        action="store_true",
        help="derive each task's setup and say whether the arm can do it (and why not)",
    )
    p.add_argument(
        "--picture",
        metavar="P.png",
        help="draw the home pose over the task area into this file (nothing drawn otherwise)",
    )
    p.set_defaults(func=cmd_arm)
