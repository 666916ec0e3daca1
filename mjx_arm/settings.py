"""``--set KEY=VALUE`` settings, parsed in one place for every command that takes them.

A setting names a field of a (nested) frozen dataclass config, ``field`` or ``group.field``; its
text is parsed by the field's type (bool, int, float, str, tuples, else JSON). Commands add the
option with :func:`add_set_argument` and apply it with :func:`apply_settings`; the training
config also routes ``task.*`` keys to the task (``mjx_arm.train.config``).

Values are checked in one place, whichever way a config is built: :func:`check_types` checks
every field against its type hint (a config's ``__post_init__`` calls it), :func:`config_fields`
does the same for a loaded file's fields and :func:`check_range` states a field's bounds. Each
problem is a :class:`~mjx_arm.inputs.ConfigError` that names the field.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import math
import types
import typing
from collections.abc import Callable
from typing import Any

from mjx_arm.inputs import ConfigError


def split_setting(item: str) -> tuple[list[str], str]:
    """``"a.b=1"`` -> ``(["a", "b"], "1")``.

    Raises:
        ConfigError: no ``=`` in ``item``.
    """
    key, sep, text = item.partition("=")
    if not sep:
        raise ConfigError(f"--set expects KEY=VALUE, got {item!r}")
    return key.strip().split("."), text.strip()


def coerce(text: str, kind: Any) -> Any:
    """Parse a setting's text for a field of type ``kind``.

    Raises:
        ConfigError: the text is not a value of that type.
    """
    try:
        return _parse(text, kind)
    except (ValueError, OverflowError, RecursionError):
        raise ConfigError(f"{text!r} is not {_describe(kind)}") from None


def _parse(text: str, kind: Any) -> Any:
    if isinstance(kind, str):  # an alias such as Range, unresolved
        kind = tuple
    if kind is bool:
        if text.lower() in ("1", "true", "yes", "on"):
            return True
        if text.lower() in ("0", "false", "no", "off"):
            return False
        raise ValueError(text)
    if kind is int:
        value = float(text)
        if not value.is_integer():
            raise ValueError(text)
        return int(value)
    if kind in (float, str):
        return kind(text)
    if typing.get_origin(kind) is tuple or kind is tuple:
        args = typing.get_args(kind)
        number = {float: float, str: str}.get(args[0] if args else int, int)
        return tuple(number(v.strip()) for v in text.strip("()[] ").split(",") if v.strip())
    return json.loads(text)


def did_you_mean(name: str, known: Any) -> str:
    """`` (did you mean 'x'?)`` for the known name closest to a mistyped one, else ""."""
    import difflib

    close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.75)
    return f" (did you mean {close[0]!r}?)" if close else ""


def set_path(
    config: Any, path: list[str], text: str, label: str = "setting", group: str = ""
) -> Any:
    """A copy of the dataclass ``config`` with the field at ``path`` set from ``text``.

    ``group`` is the dotted path of ``config`` inside the outer config, ending in ``.``: an
    unknown field's message names its group, with the closest known field of that group as a
    suggestion (``'impll' (did you mean 'impl'?) in 'physics'``).

    Raises:
        ConfigError: an unknown field (the message lists the known ones), a group set as a
            value, a value given fields, a value of the wrong type or out of range.
    """
    hints = field_types(type(config))
    if path[0] not in hints:
        where = f" in {group.rstrip('.')!r}" if group else ""
        hint = did_you_mean(path[0], hints)
        raise ConfigError(
            f"unknown {label} {path[0]!r}{hint}{where}; choose one of {sorted(hints)}"
        )
    current = getattr(config, path[0])
    if dataclasses.is_dataclass(current):
        if len(path) == 1:
            raise ConfigError(f"{path[0]!r} is a group; set one of its fields ({path[0]}.NAME)")
        value = set_path(current, path[1:], text, label, f"{group}{path[0]}.")
    elif len(path) > 1:
        raise ConfigError(f"{path[0]!r} has no fields")
    else:
        value = coerce(text, hints[path[0]])
        check_value(value, hints[path[0]], path[0])
    try:
        return dataclasses.replace(config, **{path[0]: value})
    except ConfigError:
        raise
    except ValueError as err:  # a config's own range check (__post_init__)
        raise ConfigError(str(err)) from err


def apply_settings(config: Any, items: list[str], label: str = "setting") -> Any:
    """``config`` with every ``KEY=VALUE`` of ``items`` set, in order (the last one wins).

    Raises:
        ConfigError: a bad item; the message starts with ``--set ITEM:``.
    """
    for item in items:
        path, text = split_setting(item)
        try:
            config = set_path(config, path, text, label)
        except ConfigError as err:
            raise ConfigError(f"--set {item}: {err}") from err
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


def add_field_flags(
    parser: argparse.ArgumentParser, config: Callable[[], type], names: tuple[str, ...]
) -> None:
    """Add ``--NAME VALUE`` for each field in ``names`` of the dataclass ``config()`` returns
    (called only when a flag is given or its help shown: a config module may be slow to
    import): a shortcut for ``--set NAME=VALUE``, its value checked as the class checks it, its
    help the field's entry in the ``Attributes:`` of the class's docstring.
    :func:`field_flag_settings` turns the flags given into settings."""
    for name in names:
        parser.add_argument(
            f"--{name.replace('_', '-')}",
            action=_FieldFlag,
            dest=f"field_{name}",
            metavar=name.upper(),
            config=config,
            field=name,
        )


def field_flag_settings(args: argparse.Namespace, names: tuple[str, ...]) -> list[str]:
    """``NAME=VALUE`` of each flag of :func:`add_field_flags` given in ``args``."""
    given = {name: getattr(args, f"field_{name}", None) for name in names}
    return [f"{name}={value}" for name, value in given.items() if value is not None]


class LazyHelpAction(argparse._StoreAction):
    """A stored option whose help is made by ``help_text()`` when it is shown, for a help
    read from a module that is slow to import (argparse builds every command's parser)."""

    def __init__(self, *args: Any, help_text: Callable[[], str], **kwargs: Any) -> None:
        self._help_text = help_text
        super().__init__(*args, **kwargs)

    @property
    def help(self) -> str:  # type: ignore[override]
        return self._help_text()

    @help.setter
    def help(self, _value: object) -> None:  # argparse sets it; the property gives it
        pass


class LinesHelpFormatter(argparse.HelpFormatter):
    """argparse's help, each line of a help text wrapped on its own (a help may list its
    choices one per line)."""

    def _split_lines(self, text: str, width: int) -> list[str]:
        wrap = super()._split_lines  # (a comprehension has no super() of its own)
        return [part for line in text.splitlines() for part in wrap(line, width)]


class _FieldFlag(LazyHelpAction):
    """The ``--NAME VALUE`` of a config field (:func:`add_field_flags`): the value, checked as
    the config class checks the field (type and range), is kept as its text; the help is read
    from the class when shown."""

    def __init__(self, *args: Any, config: Callable[[], type], field: str, **kwargs: Any):
        self._config, self._field = config, field
        super().__init__(*args, help_text=self._field_help, **kwargs)

    def _field_help(self) -> str:
        doc = attribute_doc(self._config(), self._field)
        return f"{doc} Short for --set {self._field}=VALUE (default: the preset's)"

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        try:  # the field's type and range, as the config class checks them
            set_path(self._config()(), [self._field], values)
        except ConfigError as err:
            parser.error(f"argument {option_string}: {err}")
        setattr(namespace, self.dest, values)


def attribute_doc(cls: type, name: str) -> str:
    """The text of ``name`` in the ``Attributes:`` section of ``cls``'s docstring, its lines
    joined ("" when it has none)."""
    import inspect
    import re

    doc = inspect.cleandoc(cls.__doc__ or "")
    found = re.search(rf"^ +{re.escape(name)}: (.+(?:\n {{8,}}\S.*)*)", doc, re.MULTILINE)
    return " ".join(found.group(1).split()) if found else ""


def config_fields(
    cls: type, data: Any, what: str, error: type[Exception] = ConfigError
) -> dict[str, Any]:
    """The keyword arguments of frozen dataclass ``cls`` from a JSON-loaded dict (the inverse of
    ``dataclasses.asdict`` for flat configs): lists become tuples, unknown keys are an error,
    and each value is checked against its field's type (:func:`check_value`).

    Args:
        cls: the config class.
        data: the loaded fields (not changed).
        what: the config's name in the error message ("physics config").
        error: the exception class to raise.

    Raises:
        error: not a dict, a key that is not a field of ``cls`` (the known ones listed), or a
            value of the wrong type.
    """
    if not isinstance(data, dict):
        raise error(f"{what} must be a table of fields, not {type(data).__name__}")
    hints = field_types(cls)
    unknown = sorted(str(k) for k in set(data) - set(hints))
    if unknown:
        raise error(f"unknown {what} keys: {unknown}; known: {sorted(hints)}")
    out, wrong = {}, []
    for key, value in data.items():
        value = tuple(value) if isinstance(value, list) else value
        if isinstance(value, dict) and not takes_table(hints[key]):
            kind = getattr(hints[key], "__name__", hints[key])
            wrong.append(f"{key} must be {kind}, not a table")
        elif not isinstance(value, dict):  # a nested section: its own from_dict checks it
            try:
                check_value(value, hints[key], key)
            except ConfigError as err:
                wrong.append(str(err))
        out[key] = value
    if wrong:
        raise error(f"{what}: {'; '.join(wrong)}")
    return out


# --------------------------------------------------------------------------- type checks


def takes_table(hint: Any) -> bool:
    """Whether a field of type ``hint`` may hold a table (a dict): a nested config (a
    dataclass), a dict type or Any, alone or in a union."""
    if hint is Any or hint is dict or dataclasses.is_dataclass(hint):
        return True
    if typing.get_origin(hint) is dict:
        return True
    return any(takes_table(arg) for arg in typing.get_args(hint) if arg is not type(None))


@functools.cache
def field_types(cls: type) -> dict[str, Any]:
    """Field name -> resolved type hint of the dataclass ``cls``."""
    hints = typing.get_type_hints(cls)
    return {f.name: hints.get(f.name, Any) for f in dataclasses.fields(cls)}


def check_types(config: Any, prefix: str = "") -> None:
    """Check every field of the dataclass ``config`` against its type hint; for a config's
    ``__post_init__``, so that every way of building it (a file, ``--set``, code) is checked.

    Args:
        config: the dataclass instance.
        prefix: put before each field's name in a message ("physics.").

    Raises:
        ConfigError: the first field whose value is not of its type (or a non-finite float).
    """
    for name, kind in field_types(type(config)).items():
        check_value(getattr(config, name), kind, prefix + name)


def check_value(value: Any, kind: Any, name: str) -> None:
    """Check one value against a type hint: bool, int, float (finite; an int is fine), str,
    tuples of those (``tuple[float, ...]`` or fixed length), dicts, dataclasses, unions.

    Raises:
        ConfigError: ``value`` is not a ``kind``.
    """
    if not _fits(value, kind):
        raise ConfigError(f"{name} must be {_describe(kind)}, got {value!r}")


def _fits(value: Any, kind: Any) -> bool:
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if kind is Any or isinstance(kind, typing.TypeVar):
        return True
    if origin in (typing.Union, types.UnionType):
        return any(_fits(value, a) for a in args)
    if kind is bool:
        return isinstance(value, bool)
    if kind is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if kind is float:
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        return ok and math.isfinite(value)
    if origin is tuple or kind is tuple:
        return _fits_tuple(value, args)
    if origin is dict or kind is dict:
        return isinstance(value, dict)
    if isinstance(kind, type):
        return isinstance(value, kind)
    return True  # a hint this check does not know: accepted


def _fits_tuple(value: Any, args: tuple) -> bool:
    if not isinstance(value, tuple):
        return False
    if not args:
        return True
    if len(args) == 2 and args[1] is Ellipsis:
        return all(_fits(v, args[0]) for v in value)
    return len(value) == len(args) and all(_fits(v, a) for v, a in zip(value, args, strict=True))


def _describe(kind: Any) -> str:
    """``kind`` in words, for a message ("a list of numbers")."""
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    names = {bool: "true or false", int: "an integer", float: "a finite number", str: "a text"}
    if kind in names:
        return names[kind]
    if origin is tuple or kind is tuple or isinstance(kind, str):
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {_describe(args[0]).removeprefix('a ').removeprefix('an ')}s"
        return f"a list of {len(args)} values" if args else "a list"
    if origin is dict or kind is dict:
        return "a table (dict)"
    return f"a {getattr(kind, '__name__', kind)}"


def check_range(
    config: Any,
    names: str | tuple[str, ...],
    low: float | None = None,
    high: float | None = None,
    above: float | None = None,
    prefix: str = "",
) -> None:
    """Check fields of ``config``: each ``>= low``, ``<= high`` and ``> above`` (None: no bound);
    a tuple field must have entries, each in range. ``prefix`` goes before each name in a
    message ("physics.").

    Raises:
        ConfigError: a field out of range, named with its bounds.
    """
    for field_name in (names,) if isinstance(names, str) else names:
        value, name = getattr(config, field_name), prefix + field_name
        values = value if isinstance(value, tuple) else (value,)
        if not values:
            raise ConfigError(f"{name} must list at least one value, got ()")
        if any(not _within(v, low, high, above) for v in values):
            bounds = (
                f">= {low:g}" if low is not None else "",
                f"> {above:g}" if above is not None else "",
                f"<= {high:g}" if high is not None else "",
            )
            span = " and ".join(b for b in bounds if b)
            each = "each entry of " if isinstance(value, tuple) else ""
            raise ConfigError(f"{each}{name} must be {span}, got {value!r}")


def _within(v: float, low: float | None, high: float | None, above: float | None) -> bool:
    return (
        (low is None or v >= low) and (high is None or v <= high) and (above is None or v > above)
    )
