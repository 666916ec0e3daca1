"""``mjx-arm validate`` and ``mjx-arm convert``: the URDF pipeline's commands."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from mjx_arm.engines import CONVERTER_ENGINE, engine_names
from mjx_arm.inputs import InputError, OutputPathError, check_output, require_file, write_atomic
from mjx_arm.names import EXIT_INVALID, EXIT_OK
from mjx_arm.urdf.repair_args import add_repair_arguments, repairs_of
from mjx_arm.urdf.scene_shapes import SCENES


def _package_dirs(items: list[str]) -> dict[str, str]:
    """``--package NAME=DIR`` items as ``{NAME: DIR}``.

    Raises:
        InputError: an item without ``=`` or a DIR that is not a folder.
    """
    out = {}
    for item in items or []:
        name, sep, folder = item.partition("=")
        if not sep or not name:
            raise InputError(f"--package expects NAME=DIR, got {item!r}")
        if not Path(folder).expanduser().is_dir():
            raise InputError(f"--package {item!r}: {folder!r} is not a folder")
        out[name] = folder
    return out


# Length of the error line after a failed validation: under 300 characters, as the report's
# lines (mjx_arm.cli.MAX_LINE_CHARS for other commands).
LINE_CHARS = 299


def _invalid(urdf: str, report) -> int:
    """The one ``error:`` line after a failed validation's report (on stdout): the number of
    errors and the first of them, in at most :data:`LINE_CHARS` characters (a long path is
    shortened to its file name: the report above gives it whole); returns
    :data:`EXIT_INVALID`."""
    tail = "; each with its fix in the report above"
    shown = urdf if len(urdf) <= 100 else f".../{Path(urdf).name[:90]}"
    head = f"error: {shown}: "
    room = LINE_CHARS - len(head) - len(tail)
    line = f"{head}{report.summary(room)}{tail}"
    while len(line) > LINE_CHARS and room > 60:  # the count and "; " took their share
        room -= len(line) - LINE_CHARS
        line = f"{head}{report.summary(room)}{tail}"
    print(line, file=sys.stderr)
    return EXIT_INVALID


def cmd_validate(args: argparse.Namespace) -> int:
    """Validate a URDF in three layers and print every finding (with the repair flags: of the
    URDF as each engine loads it repaired)."""
    from mjx_arm.urdf.validate import validate

    require_file(args.urdf, "URDF")  # a missing file is one error line, not a report
    repairs = repairs_of(args)
    report = validate(
        args.urdf,
        engine=args.engine,
        package_dirs=_package_dirs(args.package),
        repair_inertia=repairs.repair_inertia,
        default_limits=repairs.limits(),
    )
    print(report.format())
    return EXIT_OK if report.ok else _invalid(args.urdf, report)


def cmd_convert(args: argparse.Namespace) -> int:
    """Validate a URDF for MuJoCo, convert it to MJCF and write the XML."""
    from mjx_arm.urdf import ConvertConfig, to_mjcf
    from mjx_arm.urdf.mesh_convert import cache_dir_for
    from mjx_arm.urdf.validate import validate

    output = check_output(args.output, "-o", (".xml",))
    if not output.parent.is_dir():  # a mistyped folder is named, not made (with its parents)
        raise OutputPathError(
            f"-o {str(output)!r}: the folder {str(output.parent)!r} does not exist; create it "
            "first, or write into an existing folder"
        )
    package_dirs = _package_dirs(args.package)
    repairs = repairs_of(args)
    config = ConvertConfig(
        scene=SCENES[args.scene],
        package_dirs=package_dirs,
        repair_inertia=repairs.repair_inertia,
        default_effort=repairs.default_effort,
        default_velocity=repairs.default_velocity,
        mesh_cache_dir=str(cache_dir_for(args.output)),  # meshes_converted/ beside the MJCF
    )
    report = validate(
        args.urdf,
        engine=CONVERTER_ENGINE,
        package_dirs=package_dirs,
        native=False,
        repair_inertia=repairs.repair_inertia,
        default_limits=config.default_limits(),
    )
    if not report.ok:
        print(report.format())
        return _invalid(args.urdf, report)
    xml = to_mjcf(args.urdf, config)  # a ConversionError is a named error (mjx_arm.cli.main)
    write_atomic(relative_files(xml, output.parent).encode(), output)
    print(_summary(args.output))
    return EXIT_OK


def relative_files(xml: str, folder: Path) -> str:
    """``xml`` (an MJCF) with each absolute ``file="..."`` (a mesh, a texture) written relative
    to ``folder``, where the MJCF goes, so that the MJCF and its meshes move together (MuJoCo
    reads such a path from the MJCF's folder). A path that shares no folder with ``folder``
    but the root (or a drive) stays absolute."""
    import os
    import re
    from xml.sax.saxutils import escape, unescape

    base = os.path.realpath(folder)

    def relative(match: re.Match) -> str:
        path = os.path.realpath(unescape(match.group(1), {"&quot;": '"'}))
        try:
            shared = os.path.commonpath([path, base])
        except ValueError:  # another drive (Windows): no relative path
            return match.group(0)
        if shared == os.path.dirname(shared):  # only the root in common
            return match.group(0)
        path = os.path.relpath(path, base)
        return f'file="{escape(path, {chr(34): "&quot;"})}"'

    return re.sub(r'\bfile="(/[^"]*|[A-Za-z]:[\\/][^"]*)"', relative, xml)


def _summary(mjcf_path: str) -> str:
    import mujoco

    model = mujoco.MjModel.from_xml_path(mjcf_path)
    joints = [model.joint(i).name for i in range(model.njnt) if model.jnt_type[i] != 0]
    lines = [
        f"wrote {mjcf_path}",
        f"  bodies {model.nbody}, joints {len(joints)}, velocity actuators {model.nu}, "
        f"sensors {model.nsensor}, timestep {model.opt.timestep:.6f} s",
        f"  joint damping {', '.join(f'{d:g}' for d in model.dof_damping)}",
    ]
    return "\n".join(lines)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``validate`` and ``convert`` to ``sub``."""
    p = sub.add_parser(
        "validate",
        help="validate a URDF (XML/tree, engine compatibility, physics)",
        description=cmd_validate.__doc__,
    )
    p.add_argument("urdf", help="path of the URDF file")
    p.add_argument(
        "--engine",
        choices=[*engine_names("urdf_reader"), "all"],
        default="all",
        help="engine(s) to check compatibility with and load into (default: all)",
    )
    p.add_argument(
        "--package",
        action="append",
        metavar="NAME=DIR",
        help="directory of a package:// name (repeatable)",
    )
    add_repair_arguments(p, "the check")
    p.set_defaults(func=cmd_validate)

    p = sub.add_parser(
        "convert", help="convert a URDF to an MJX-ready MJCF", description=cmd_convert.__doc__
    )
    p.add_argument("urdf", help="path of the URDF file")
    p.add_argument("-o", "--output", required=True, help="MJCF file to write")
    p.add_argument(
        "--scene",
        choices=sorted(SCENES),
        default="none",
        help="add the task scene (floor, table, target; lift: a free cube) around the arm",
    )
    p.add_argument(
        "--package",
        action="append",
        metavar="NAME=DIR",
        help="directory of a package:// name (repeatable)",
    )
    add_repair_arguments(p, "the conversion")
    p.set_defaults(func=cmd_convert)
