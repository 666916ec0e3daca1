"""The repair flags of every command that loads an arm (``convert``, ``validate``, ``arm``,
``train``, ``warmup``, ``eval``): one definition, mapped onto the arm config's fields of the same
names (:mod:`mjx_arm.urdf.repair`), which a run saves and its policy files record.
"""

from __future__ import annotations

import argparse
from typing import Protocol, Self, TypeVar

from mjx_arm.inputs import float_in
from mjx_arm.urdf.repair import LIMIT_ATTRS, UrdfRepairs


class Repairable(Protocol):
    """A config with the repair fields (:class:`mjx_arm.arm.config.ArmConfig`)."""

    def replace(self, **changes: object) -> Self: ...


C = TypeVar("C", bound=Repairable)

_UNITS = {"effort": "N m or N", "velocity": "rad/s or m/s"}


def add_repair_arguments(parser: argparse.ArgumentParser, where: str) -> None:
    """Add ``--repair-inertia``, ``--default-effort`` and ``--default-velocity``.

    Args:
        parser: the command's parser.
        where: what the flags set, for their help (``"the arm"``, ``"the conversion"``).
    """
    parser.add_argument(
        "--repair-inertia",
        action="store_true",
        help="replace inertia tensors that break the triangle inequality by the nearest valid "
        f"one, in every engine (sets repair_inertia of {where})",
    )
    for attr in LIMIT_ATTRS:
        parser.add_argument(
            f"--default-{attr}",
            type=float_in(0.0),
            metavar="VALUE",
            help=f"{attr} limit ({_UNITS[attr]}) of every moving joint whose URDF gives none, "
            f"in every engine (sets default_{attr} of {where}; default: none, such a joint is "
            "an error)",
        )


def repairs_of(args: argparse.Namespace) -> UrdfRepairs:
    """The repairs the flags ask for (a flag not given: none)."""
    return UrdfRepairs(
        bool(args.repair_inertia), args.default_effort or 0.0, args.default_velocity or 0.0
    )


def with_repair_arguments(arm: C, args: argparse.Namespace) -> C:
    """``arm`` with the repairs of the flags given; the others as the arm (file) has them."""
    changes: dict[str, object] = {"repair_inertia": True} if args.repair_inertia else {}
    for attr in LIMIT_ATTRS:
        value = getattr(args, f"default_{attr}")
        if value is not None:
            changes[f"default_{attr}"] = value
    return arm.replace(**changes) if changes else arm


def given_repair_flags(args: argparse.Namespace) -> list[str]:
    """The repair flags given on the command line, as typed (``--repair-inertia``, ...)."""
    flags = ["--repair-inertia"] if args.repair_inertia else []
    return flags + [
        f"--default-{attr}" for attr in LIMIT_ATTRS if getattr(args, f"default_{attr}") is not None
    ]
