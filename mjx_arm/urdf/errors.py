"""Errors raised by the URDF pipeline."""

from __future__ import annotations

from typing import TypeVar

from mjx_arm.inputs import InputError

_E = TypeVar("_E", bound=InputError)


class UrdfError(InputError, ValueError):
    """A URDF that cannot be used, with a message that names the element and the fix."""


class ConversionError(UrdfError):
    """A URDF that MuJoCo's importer or compiler rejects, or that lacks what conversion needs."""


def one_line(text: object) -> str:
    """``text`` (an exception, a message) on one line: its non-empty lines joined by ``; ``."""
    return "; ".join(part.strip() for part in str(text).splitlines() if part.strip())


def report_error(kind: type[_E], report) -> _E:
    """A ``kind`` error whose message is a failed validation's whole report and whose
    :attr:`~mjx_arm.inputs.InputError.headline` is its one-line summary (path, error count,
    the first errors) and the errors' fix where they share one (two links whose inertia needs
    the same repair), else where every fix is."""
    err = kind(report.format())
    fixes = {finding.fix for finding in report.errors}
    fix = fixes.pop() if len(fixes) == 1 else "mjx-arm validate gives every fix"
    err.headline = f"{report.path}: {report.summary()}; {fix}"
    return err
