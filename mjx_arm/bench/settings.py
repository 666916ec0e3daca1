"""Command-line flags generated from a settings dataclass, so no flag is listed twice.

A field declared with :func:`setting` carries its help text (and choices); :func:`add_arguments`
makes one ``--field-name`` flag per field and :func:`from_arguments` applies the flags given.
"""

from __future__ import annotations

import argparse
import dataclasses
from dataclasses import field
from typing import Any

from mjx_arm.inputs import ConfigError
from mjx_arm.settings import check_value, field_types


def setting(default: Any, help_text: str, choices: tuple | None = None) -> Any:
    """A dataclass field with its command-line help (and the values it may take)."""
    return field(default=default, metadata={"help": help_text, "choices": choices})


def _show(value: Any) -> str:
    return " ".join(map(str, value)) if isinstance(value, tuple) else str(value)


def add_arguments(parser: argparse.ArgumentParser, cls: type) -> None:
    """One flag per field of the dataclass ``cls`` (default None: not given)."""
    for f in dataclasses.fields(cls):
        kwargs: dict[str, Any] = {
            "dest": f.name,
            "default": None,
            "help": f"{f.metadata.get('help', '')} (default: {_show(f.default)})",
        }
        if isinstance(f.default, bool):
            kwargs["action"] = argparse.BooleanOptionalAction
        elif isinstance(f.default, tuple):
            kwargs.update(nargs="+", type=type(f.default[0]))
        else:
            kwargs["type"] = type(f.default)
        if f.metadata.get("choices"):
            kwargs["choices"] = f.metadata["choices"]
        parser.add_argument("--" + f.name.replace("_", "-"), **kwargs)


def from_arguments(base: Any, args: argparse.Namespace) -> Any:
    """``base`` with every field that ``args`` gives replaced.

    Raises:
        ConfigError: a value the settings' own checks refuse (out of range, not finite).
    """
    changes = {}
    for f in dataclasses.fields(base):
        value = getattr(args, f.name, None)
        if value is not None:
            changes[f.name] = tuple(value) if isinstance(value, list) else value
    try:
        for name, value in changes.items():
            check_value(value, field_types(type(base))[name], "--" + name.replace("_", "-"))
        return dataclasses.replace(base, **changes)
    except ConfigError:
        raise
    except ValueError as err:  # the settings' __post_init__ range checks
        raise ConfigError(str(err)) from err
