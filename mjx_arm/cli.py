"""The ``mjx-arm`` command line: each package adds its own subcommands (``register``); this
module assembles them and owns ``demo``, the whole product in one command.

Every bad input ends the same way, here in :func:`main`: a named error
(:class:`~mjx_arm.inputs.InputError`, or a policy file's
:class:`~mjx_arm.policy.PolicyFileError`) becomes one ``error:`` line on stderr and exit code
:data:`~mjx_arm.names.EXIT_INVALID` (2); argparse reports bad arguments with the same code. Any
other exception is a bug: its traceback shows and the exit code is 1.
"""

from __future__ import annotations

import argparse
import sys

from mjx_arm.inputs import InputError
from mjx_arm.jax_cache import enable_compilation_cache
from mjx_arm.names import EXIT_INVALID, EXIT_OK

__all__ = ["EXIT_INVALID", "EXIT_OK", "build_parser", "main"]


def cmd_demo(args: argparse.Namespace) -> int:
    """The whole product on a CPU: validate and convert the arm, train Reach, export the
    policy, evaluate it in CPU MuJoCo, PyBullet and the batched JAX env, plot and film it.

    About 1-2 minutes on a 2-core CPU (--quick: under a minute). --arm runs it on another arm
    (a URDF or an arm file).
    """
    from mjx_arm.demo import run_demo
    from mjx_arm.inputs import check_folder
    from mjx_arm.urdf.arm_config import load_arm

    if args.out:
        check_folder(args.out, "--out")
    if args.arm:
        load_arm(args.arm)  # a missing or broken arm file fails before any work
    enable_compilation_cache()
    run_demo(args.out, quick=args.quick, arm=args.arm)
    return EXIT_OK


def _add_demo(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo", help="the whole pipeline on a CPU in a few minutes", description=cmd_demo.__doc__
    )
    p.add_argument("--out", help="output folder (default: runs/demo-TIMESTAMP)")
    p.add_argument(
        "--quick", action="store_true", help="shorter training, fewer episodes, smaller video"
    )
    p.add_argument(
        "--arm",
        help="the arm: a URDF or an arm file (.toml/.json) (default: the shipped UR5e-class arm)",
    )
    p.set_defaults(func=cmd_demo)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand, in the order of the pipeline."""
    from mjx_arm.bench import cli as bench_cli
    from mjx_arm.envs import cli as envs_cli
    from mjx_arm.evaluate import cli as evaluate_cli
    from mjx_arm.policy import cli as policy_cli
    from mjx_arm.sim2real import cli as sim2real_cli
    from mjx_arm.train import cli as train_cli
    from mjx_arm.urdf import cli as urdf_cli

    parser = argparse.ArgumentParser(
        prog="mjx-arm",
        description="Train and check 6-DoF arm control policies (URDF -> MJCF -> MJX + Brax PPO).",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for package in (urdf_cli, envs_cli, train_cli, policy_cli, evaluate_cli):
        package.register(sub)
    _add_demo(sub)
    sim2real_cli.register(sub)
    bench_cli.register(sub)
    return parser


def named_errors() -> tuple[type[Exception], ...]:
    """The exceptions that mean a bad input: :class:`InputError` and the named errors that
    keep their own base (the standalone numpy runtime's, the arm config's, an arm mismatch)."""
    from mjx_arm.envs.arm import ArmMismatchError
    from mjx_arm.policy.numpy_policy import PolicyFileError
    from mjx_arm.urdf.arm_config import ArmConfigError

    return InputError, PolicyFileError, ArmConfigError, ArmMismatchError


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``mjx-arm`` console script: parse, run the command, and turn a named
    input error (:func:`named_errors`) into one ``error:`` line and :data:`EXIT_INVALID`."""
    from mjx_arm.urdf.errors import one_line

    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except Exception as err:
        if not isinstance(err, named_errors()):
            raise  # a bug: its traceback shows, exit code 1
        print(f"error: {one_line(err) or type(err).__name__}", file=sys.stderr)
        return EXIT_INVALID


if __name__ == "__main__":
    sys.exit(main())
