"""``mjx-arm export``: a trained run's policy into a file that runs without the trainer."""

from __future__ import annotations

import argparse

from mjx_arm.inputs import nonnegative_int
from mjx_arm.names import EXIT_OK


def cmd_export(args: argparse.Namespace) -> int:
    """Export a run's policy (normaliser, MLP, action scaling, contract version, config).

    The suffix of each -o picks the format: .npz runs with numpy alone, .onnx with onnxruntime.
    """
    from mjx_arm.inputs import check_output
    from mjx_arm.policy.export import SUFFIXES, export_run

    for output in args.output:  # every output checked before any is written
        check_output(output, "-o", SUFFIXES)
    for output in args.output:
        path = export_run(args.source_run, output, step=args.step)
        print(f"wrote {path} ({path.stat().st_size / 1024:.0f} KiB)")
    return EXIT_OK


def _add_export(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export",
        help="export a run's policy to .npz (numpy) or .onnx",
        description=cmd_export.__doc__,
    )
    # Not dest "run_dir": that names the folder a command writes into (an error report goes
    # there, mjx_arm.cli.report_folders); export only reads the run.
    p.add_argument("source_run", metavar="run_dir", help="training run directory")
    p.add_argument(
        "-o",
        "--output",
        action="append",
        required=True,
        help="policy file to write, .npz or .onnx (repeatable)",
    )
    p.add_argument("--step", type=nonnegative_int, help="checkpoint step (default: the newest)")
    p.set_defaults(func=cmd_export)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``export`` to ``sub``."""
    _add_export(sub)
