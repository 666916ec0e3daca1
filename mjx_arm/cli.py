"""The ``mjx-arm`` command line: each package adds its own subcommands (``register``); this
module assembles them and owns ``demo``, the whole product in one command.

Every bad input ends the same way, here in :func:`main`: a named error
(:class:`~mjx_arm.inputs.InputError`, or a policy file's
:class:`~mjx_arm.policy.PolicyFileError`) becomes one ``error:`` line on stderr and exit code
:data:`~mjx_arm.names.EXIT_INVALID` (2). Bad arguments are one such line too, from
:class:`OneLineParser`. No line is longer than :data:`MAX_LINE_CHARS` (300): a longer message
is shortened, cause first and fix kept, and its whole text goes to an error-report file that the
line names (:func:`report_folders` says where). Any other exception is a bug: its traceback
shows and the exit code is 1.
"""

from __future__ import annotations

import argparse
import functools
import os
import re
import shlex
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

from mjx_arm.inputs import InputError, float_in, int_in
from mjx_arm.jax_cache import enable_compilation_cache
from mjx_arm.names import EXIT_INVALID, EXIT_OK
from mjx_arm.urdf.repair_args import add_repair_arguments

__all__ = [
    "EXIT_INVALID",
    "EXIT_OK",
    "MAX_LINE_CHARS",
    "OneLineParser",
    "build_parser",
    "error_line",
    "main",
    "report_folders",
]

# Warnings of the libraries underneath that are not the user's to act on: the command line
# hides them (a Python user of the package sees them as usual). (category, message start)
LIBRARY_WARNINGS = (
    (DeprecationWarning, "JAXopt is no longer maintained"),  # imported by Brax
    (RuntimeWarning, r"os\.fork\(\) was called"),  # JAX, when ffmpeg or a worker starts
    (UserWarning, "Explicitly requested dtype"),  # JAX without x64, on float64 constants
    (UserWarning, "Tight layout not applied"),  # matplotlib, on a small plot
)
# Longest ``error:`` line the command prints; a longer one is shortened and its whole text
# written to an error-report file that the line names.
MAX_LINE_CHARS = 300
# Characters of the shortened line kept for the fix (the part after the last "; ").
_FIX_CHARS = 110
# Attributes of a command's arguments that name the folder it writes into: its error reports go
# there when the folder exists.
_OUT_FOLDERS = ("out", "run", "run_dir", "out_dir")
# Longest folder path an error report is written to: the line must still hold cause and fix.
_FOLDER_CHARS = 150


class OneLineParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line, ``error: MESSAGE (see: PROG --help)``,
    on stderr with exit code 2 (instead of the usage block). ``add_subparsers`` gives every
    subcommand's parser this class too."""

    def parse_args(self, args=None, namespace=None):  # type: ignore[override]
        """As ``ArgumentParser.parse_args``; unknown arguments are reported by the parser of
        the subcommand they were given to, so the line points at that command's help. A
        command group given nothing (``mjx-arm``, ``mjx-arm bench``) prints its help on
        stderr instead, with exit code 2."""
        bare = self._bare_group(sys.argv[1:] if args is None else list(args))
        if bare is not None:
            bare.print_help(sys.stderr)
            bare.exit(EXIT_INVALID)
        parsed, extra = self.parse_known_args(args, namespace)
        if extra:
            self._owner(parsed).error(f"unrecognized arguments: {' '.join(extra)}")
        return parsed

    def _subcommands(self) -> dict[str, argparse.ArgumentParser]:
        """This parser's subcommands by name ({} for a command)."""
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                return dict(action.choices)
        return {}

    def _bare_group(self, argv: list[str]) -> OneLineParser | None:
        """The command group ``argv`` names without a subcommand: this parser for no
        arguments, a group's parser for its name alone; else None."""
        if not self._subcommands():
            return None
        if not argv:
            return self
        chosen = self._subcommands().get(argv[0]) if len(argv) == 1 else None
        return chosen if isinstance(chosen, OneLineParser) and chosen._subcommands() else None

    def _owner(self, parsed: argparse.Namespace) -> argparse.ArgumentParser:
        """The parser of the subcommand named in ``parsed``, else this one."""
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                chosen = action.choices.get(getattr(parsed, action.dest, None) or "")
                if chosen is not None:
                    return chosen
        return self

    def error(self, message: str) -> None:  # type: ignore[override]
        from mjx_arm.urdf.errors import one_line

        tail = f" (see: {self.prog} --help)"
        text = _cut(one_line(message), MAX_LINE_CHARS - len("error: ") - len(tail))
        self.exit(EXIT_INVALID, f"error: {text}{tail}\n")


def cmd_demo(args: argparse.Namespace) -> int:
    """The whole product on a CPU: validate and convert the arm, train Reach, export the
    policy, evaluate it in CPU MuJoCo, PyBullet and the batched JAX env, plot and film it.

    About 1-2 minutes on a 2-core CPU (--quick: under a minute). --arm runs it on another arm
    (a URDF or an arm file).
    """
    from mjx_arm.arm.config import load_arm
    from mjx_arm.demo import run_demo
    from mjx_arm.inputs import check_folder
    from mjx_arm.urdf.repair_args import given_repair_flags, with_repair_arguments

    if args.out:
        check_folder(args.out, "--out")
    arm = None
    if args.arm or given_repair_flags(args):  # a missing or broken arm file fails here
        arm = with_repair_arguments(load_arm(args.arm), args)
    enable_compilation_cache()
    run_demo(args.out, quick=args.quick, arm=arm)
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
        help="the arm: a URDF, an arm file (.toml/.json) or a shipped arm's name "
        "(default: the shipped UR5e-class arm, ur5e)",
    )
    add_repair_arguments(p, "the arm")
    p.set_defaults(func=cmd_demo)


def cmd_serve(args: argparse.Namespace) -> int:
    """Start a warm trainer: it keeps JAX, the envs and the compiled programs between the
    ``mjx-arm train --server`` commands it runs, so that a new seed of a config it has trained
    starts training at once (docs/training.md, "A warm trainer"). One command at a time; the
    others wait. With --devices N it is a process per GPU, joined once, for train --devices N
    commands ("A warm trainer of several GPUs"). It holds its GPUs' memory while it runs: stop
    it with Ctrl-C, or let --idle-minutes stop it."""
    from mjx_arm.train.server import Server
    from mjx_arm.train.server_protocol import default_socket

    path = Path(args.socket) if args.socket else default_socket()
    parse = build_parser().parse_args
    log = functools.partial(print, flush=True)
    warmup = shlex.split(args.warmup) if args.warmup is not None else None
    if args.devices > 1:
        from mjx_arm.train.server_group import ServerGroup, group_gpus

        gpus = group_gpus(args.devices, warmup)
        return ServerGroup(path, parse, gpus, args.idle_minutes * 60.0, log).serve_forever()
    return Server(path, main, parse, args.idle_minutes * 60.0, log, warmup).serve_forever()


def _add_serve(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "serve", help="a warm trainer for train --server", description=cmd_serve.__doc__
    )
    p.add_argument(
        "--socket",
        help="the socket to listen at (default: $MJX_ARM_SERVER, else trainer.sock in "
        "$XDG_RUNTIME_DIR/mjx-arm or in a folder of this user's under the temp folder)",
    )
    p.add_argument(
        "--idle-minutes",
        type=float_in(0.0, 7 * 24 * 60.0),
        default=30.0,
        help="stop after this many minutes without a command (0: never; default 30)",
    )
    p.add_argument(
        "--warmup",
        metavar="ARGS",
        help="build the envs and programs of a config before the first command: the flags of "
        '`mjx-arm warmup`, quoted (e.g. "--task touch --preset fast"); a later train '
        "--server with the same flags, any seed, then starts at once",
    )
    p.add_argument(
        "--devices",
        type=int_in(1, 64),
        default=1,
        help="GPUs of this host to train on, a process per GPU joined once, for train "
        "--devices N --server commands (default 1)",
    )
    p.set_defaults(func=cmd_serve)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand, in the order of the pipeline."""
    from mjx_arm import __version__
    from mjx_arm.arm import cli as arm_cli
    from mjx_arm.bench import cli as bench_cli
    from mjx_arm.evaluate import cli as evaluate_cli
    from mjx_arm.policy import cli as policy_cli
    from mjx_arm.sim2real import cli as sim2real_cli
    from mjx_arm.train import cli as train_cli
    from mjx_arm.urdf import cli as urdf_cli

    parser = OneLineParser(
        prog="mjx-arm",
        description="Train and check 6-DoF arm control policies (URDF -> MJCF -> MJX + Brax PPO).",
    )
    parser.add_argument("--version", action="version", version=f"mjx-arm {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for package in (urdf_cli, arm_cli, train_cli, policy_cli, evaluate_cli):
        package.register(sub)
    _add_serve(sub)
    _add_demo(sub)
    sim2real_cli.register(sub)
    bench_cli.register(sub)
    return parser


def named_errors() -> tuple[type[Exception], ...]:
    """The exceptions that mean a bad input: :class:`InputError` and the named errors that
    keep their own base (the standalone numpy runtime's, the arm config's, an arm mismatch)."""
    from mjx_arm.arm.config import ArmConfigError
    from mjx_arm.arm.info import ArmMismatchError
    from mjx_arm.policy.numpy_policy import PolicyFileError

    return InputError, PolicyFileError, ArmConfigError, ArmMismatchError


def error_line(err: Exception, args: argparse.Namespace, argv: list[str]) -> str:
    """The ``error:`` line of a named error, at most :data:`MAX_LINE_CHARS` characters.

    The line is the error's ``headline`` when it has one (a long report behind it), else its
    message on one line. When there is a report or the line is too long, the whole text is
    written to a file and the line, shortened (the cause first, then the fix, the part after
    the last ``"; "``), ends in ``(full report: PATH)``.
    """
    from mjx_arm.urdf.errors import one_line

    text = one_line(err) or type(err).__name__
    headline = getattr(err, "headline", "")
    line = f"error: {headline or text}"
    if not headline and len(line) <= MAX_LINE_CHARS:
        return line
    command = shlex.join(["mjx-arm", *argv])
    body = f"{command}\n\n{type(err).__name__}:\n{err}\n"
    path = _write_report(body, report_folders(args))
    if path is None:  # nowhere to write: the line alone, shortened
        return "error: " + _shorten(headline or text, MAX_LINE_CHARS - len("error: "))
    tail = f" (full report: {path})"
    budget = max(MAX_LINE_CHARS - len("error: ") - len(tail), 80)
    return f"error: {_shorten(headline or text, budget)}{tail}"


# an absolute path of four or more folders (shortened to its last two parts on a long line)
_PATH = re.compile(r"(?:/[^\s'\"/;:,()\[\]]+){4,}")


def _shorten(text: str, budget: int) -> str:
    """``text`` in at most ``budget`` characters: long paths first cut to their last two parts
    (the report keeps them whole), then the cause (before the first ``"; "``) cut to fit, then
    the fix (after the last ``"; "``) cut to :data:`_FIX_CHARS`."""
    if len(text) <= budget:
        return text
    text = _PATH.sub(lambda m: ".../" + "/".join(m.group(0).split("/")[-2:]), text)
    if len(text) <= budget:
        return text
    cause, _, rest = text.partition("; ")
    fix = _cut(rest.rpartition("; ")[2], min(_FIX_CHARS, budget // 2)) if rest else ""
    room = budget - (len(fix) + 2 if fix else 0)
    return f"{_cut(cause, room)}; {fix}" if fix else _cut(cause, budget)


def _cut(text: str, chars: int) -> str:
    """``text`` cut to at most ``chars`` characters, ending in ``...`` when cut."""
    return text if len(text) <= chars else text[: max(chars - 3, 0)].rstrip() + "..."


def report_folders(args: argparse.Namespace) -> list[Path]:
    """Where an error report may go, in order of preference: the folder the command writes
    into (``--out`` or the run folder; a ``run_dir`` only where it is a run directory, never
    a folder of the user's that ``train`` refused) when it exists,
    ``$XDG_STATE_HOME/mjx_arm/errors`` (default ``~/.local/state/mjx_arm/errors``), then
    ``mjx_arm-errors`` in the temp folder."""
    from mjx_arm.train.rundir import is_run_dir

    folders = []
    for name in _OUT_FOLDERS:
        value = getattr(args, name, None)
        folder = Path(value).expanduser() if isinstance(value, str | Path) else None
        if folder and folder.is_dir() and (name != "run_dir" or is_run_dir(folder)):
            folders.append(folder)
    state = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    folders.append(Path(state) / "mjx_arm" / "errors")
    folders.append(Path(tempfile.gettempdir()) / "mjx_arm-errors")
    return folders


def _write_report(body: str, folders: list[Path]) -> Path | None:
    """Write ``body`` atomically to ``error-TIME-PID.txt`` in the first folder that takes it
    (passing over a folder whose path is too long to name on the line); its absolute path, or
    None when none does."""
    from mjx_arm.inputs import OutputWriteError, write_atomic

    name = f"error-{time.strftime('%Y%m%d-%H%M%S', time.gmtime())}-{os.getpid()}.txt"
    for folder in folders:
        if len(str(folder.resolve())) > _FOLDER_CHARS:
            continue
        try:
            write_atomic(body.encode("utf-8", "replace"), folder / name)
        except (OutputWriteError, OSError):
            continue
        return (folder / name).resolve()
    return None


def take_ctrl_c() -> None:
    """Stop on SIGINT (Ctrl-C) even where this process started with SIGINT ignored.

    A non-interactive shell starts its background jobs (``cmd &`` in a script, each line of a
    ``gpu_suite.sh`` campaign) with SIGINT ignored, and Python then installs no handler for it.
    The processes this package starts and stops as Ctrl-C does (a training's per-GPU
    processes, a benchmark's seeds, the warm trainers and their clients) would ignore the
    signal and be killed after their grace period, instead of saving and ending. Only the main
    thread may set a handler; elsewhere (a command that a warm trainer runs) nothing changes.
    """
    main_thread = threading.current_thread() is threading.main_thread()
    if main_thread and signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``mjx-arm`` console script: parse, run the command, and turn a named
    input error (:func:`named_errors`) into one ``error:`` line and :data:`EXIT_INVALID`.

    A line over :data:`MAX_LINE_CHARS` characters, or an error that carries
    a long report (its ``headline``), is shortened and the whole text goes to an error-report
    file that the line names (:func:`report_folders` says where).
    """
    import warnings

    take_ctrl_c()
    for category, message in LIBRARY_WARNINGS:
        warnings.filterwarnings("ignore", message, category)
    args = build_parser().parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)  # as given (train --server)
    try:
        return int(args.func(args) or 0)
    except Exception as err:
        if not isinstance(err, named_errors()):
            raise  # a bug: its traceback shows, exit code 1
        print(error_line(err, args, sys.argv[1:] if argv is None else argv), file=sys.stderr)
        return EXIT_INVALID


if __name__ == "__main__":
    sys.exit(main())
