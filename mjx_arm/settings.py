"""``--set KEY=VALUE`` settings, parsed in one place for every command that takes them.

A setting names a field of a (nested) frozen dataclass config, ``field`` or ``group.field``; its
text is parsed by the field's type (bool, int, float, str, tuples, else JSON). Commands add the
option with :func:`add_set_argument` and apply it with :func:`apply_settings`; the training
config also routes ``task.*`` keys to the task (``mjx_arm.train.config``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import typing
from typing import Any


def split_setting(item: str) -> tuple[list[str], str]:
    """``"a.b=1"`` -> ``(["a", "b"], "1")``.

    Raises:
        ValueError: no ``=`` in ``item``.
    """
    key, sep, text = item.partition("=")
    if not sep:
        raise ValueError(f"--set expects KEY=VALUE, got {item!r}")
    return key.strip().split("."), text.strip()


def coerce(text: str, kind: Any) -> Any:
    """Parse a setting's text for a field of type ``kind``.

    Raises:
        ValueError: the text is not a value of that type.
    """
    if isinstance(kind, str):  # an alias such as Range, unresolved
        kind = tuple
    if kind is bool:
        if text.lower() in ("1", "true", "yes", "on"):
            return True
        if text.lower() in ("0", "false", "no", "off"):
            return False
        raise ValueError(f"not a boolean: {text!r}")
    if kind in (int, float, str):
        return kind(float(text)) if kind is int else kind(text)
    if typing.get_origin(kind) is tuple or kind is tuple:
        args = typing.get_args(kind)
        number = float if args and args[0] is float else int
        return tuple(number(v) for v in text.strip("()[] ").split(",") if v.strip())
    return json.loads(text)


def set_path(config: Any, path: list[str], text: str, label: str = "setting") -> Any:
    """A copy of the dataclass ``config`` with the field at ``path`` set from ``text``.

    Raises:
        ValueError: an unknown field (the message lists the known ones), a group set as a
            value, a value given fields, or a value of the wrong type.
    """
    hints = typing.get_type_hints(type(config))
    if path[0] not in hints:
        raise ValueError(f"unknown {label} {path[0]!r}; choose one of {sorted(hints)}")
    current = getattr(config, path[0])
    if dataclasses.is_dataclass(current):
        if len(path) == 1:
            raise ValueError(f"{path[0]!r} is a group; set one of its fields ({path[0]}.NAME)")
        value = set_path(current, path[1:], text, label)
    elif len(path) > 1:
        raise ValueError(f"{path[0]!r} has no fields")
    else:
        value = coerce(text, hints[path[0]])
    return dataclasses.replace(config, **{path[0]: value})


def apply_settings(config: Any, items: list[str], label: str = "setting") -> Any:
    """``config`` with every ``KEY=VALUE`` of ``items`` set, in order (the last one wins)."""
    for item in items:
        path, text = split_setting(item)
        config = set_path(config, path, text, label)
    return config


def describe(config: Any, prefix: str = "") -> list[str]:
    """``name=value`` of every field (nested ones dotted), for a help text."""
    out = []
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if dataclasses.is_dataclass(value):
            out += describe(value, f"{prefix}{f.name}.")
        else:
            out.append(
                f"{prefix}{f.name}={value:g}"
                if isinstance(value, float)
                else f"{prefix}{f.name}={value}"
            )
    return out


def add_set_argument(parser: argparse.ArgumentParser, help_text: str) -> None:
    """Add ``--set KEY=VALUE ...`` (repeatable; the values collect into ``args.set``)."""
    parser.add_argument("--set", action="extend", nargs="+", metavar="KEY=VALUE", help=help_text)


def config_fields(
    cls: type, data: dict[str, Any], what: str, error: type[Exception] = ValueError
) -> dict[str, Any]:
    """The keyword arguments of frozen dataclass ``cls`` from a JSON-loaded dict (the inverse of
    ``dataclasses.asdict`` for flat configs): lists become tuples, unknown keys are an error.

    Args:
        cls: the config class.
        data: the loaded fields (not changed).
        what: the config's name in the error message ("physics config").
        error: the exception class to raise.

    Raises:
        error: a key that is not a field of ``cls``, with the known ones listed.
    """
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise error(f"unknown {what} keys: {unknown}; known: {sorted(known)}")
    return {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
