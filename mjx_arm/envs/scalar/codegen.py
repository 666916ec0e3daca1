"""The step rules of one task, traced once into one straight-line Python function.

:func:`mjx_arm.task.rules.score_step` is written once against an array namespace. On one env's
Python floats (:data:`~mjx_arm.envs.scalar.xp.SCALAR_XP`) every step still walks the rules'
layers: a few dozen Python calls, each asking what its arguments are, to compute about a hundred
float operations. :func:`compile_score` runs the same rules once on traced values that record
each operation, and writes them out as the body of one function: the same operations on the same
Python floats in the same order, the layers and type tests gone. Its values are the scalar
namespace's, bit for bit (the tests compare the two on every task); it takes Python floats,
bools and lists of floats only.

What the trace writes for each namespace function is SCALAR_XP's own rule on scalars (a
conditional expression for ``where``, ``maximum`` and ``minimum`` with numpy's NaN rule, the
namespace's ``exp`` and ``sqrt`` themselves, ``sum`` for ``matmul`` and for the weighted total).
Python's operators (``+``, ``<``, ``&`` ...) are written as they were applied. A rule that
branches on a traced value, or calls a function the trace does not know, cannot be traced:
:func:`compile_score` then raises :class:`Untraceable`, and :func:`step_scorers` keeps the
namespace path (:func:`~mjx_arm.envs.scalar.step.score_generic`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from typing import Any

from mjx_arm.envs.scalar.step import StepInput, StepOutcome, score_generic
from mjx_arm.envs.scalar.xp import SCALAR_XP
from mjx_arm.task import reward as reward_lib
from mjx_arm.task import rules
from mjx_arm.task.config import TaskConfig

Scorer = Callable[[StepInput], StepOutcome]

_PLAIN = (bool, int, float)


class Untraceable(Exception):
    """The rules branch on a traced value or call what the trace does not know."""


class _Trace:
    """The lines of the function being written and the constants it refers to by name."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self.names: dict[str, Any] = {}
        self.known: dict[str, _Value] = {}  # expression -> its local: computed once

    def emit(self, expression: str) -> _Value:
        """The local holding ``expression``: a new one, or the one that already holds it (every
        recorded operation is a pure function of its operands)."""
        if expression not in self.known:
            name = f"v{len(self.known)}"
            self.lines.append(f"{name} = {expression}")
            self.known[expression] = _Value(self, name)
        return self.known[expression]

    def text(self, x: Any) -> str:
        """Source text of an operand: a traced value's local, a finite Python scalar's literal,
        any other constant (infinities, NaN, numpy scalars, functions) by a name bound to it."""
        if isinstance(x, _Value):
            return x.ref()
        if type(x) in _PLAIN and (type(x) is not float or math.isfinite(x)):
            return repr(x)
        for name, value in self.names.items():
            if value is x:
                return name
        name = f"c{len(self.names)}"
        self.names[name] = x
        return name


def _binary(op: str, reflected: bool = False) -> Callable:
    def method(self: _Value, other: Any) -> Any:
        if not isinstance(other, (_Value, *_PLAIN)):
            return NotImplemented
        a, b = (other, self) if reflected else (self, other)
        t = self.trace
        return t.emit(f"{t.text(a)} {op} {t.text(b)}")

    return method


class _Value:
    """A traced Python scalar: operators record themselves; asking for its truth fails."""

    __slots__ = ("name", "trace")

    def __init__(self, trace: _Trace, name: str) -> None:
        self.trace, self.name = trace, name

    def ref(self) -> str:
        """The local that holds the value."""
        return self.name

    def __bool__(self) -> bool:
        raise Untraceable("the rules branch on a traced value")

    def __float__(self) -> float:
        raise Untraceable("the rules convert a traced value")

    __index__ = __int__ = __float__

    def __neg__(self) -> _Value:
        return self.trace.emit(f"-{self.ref()}")

    def __abs__(self) -> _Value:
        return self.trace.emit(f"abs({self.ref()})")

    def __radd__(self, other: Any) -> Any:
        if type(other) is int and other == 0:  # builtin sum(): kept as one sum() call
            return _Sum(self.trace, [self])
        return _binary("+", reflected=True)(self, other)

    __add__ = _binary("+")
    __sub__, __rsub__ = _binary("-"), _binary("-", True)
    __mul__, __rmul__ = _binary("*"), _binary("*", True)
    __truediv__, __rtruediv__ = _binary("/"), _binary("/", True)
    __and__, __rand__ = _binary("&"), _binary("&", True)
    __or__, __ror__ = _binary("|"), _binary("|", True)
    __lt__, __le__ = _binary("<"), _binary("<=")
    __gt__, __ge__ = _binary(">"), _binary(">=")
    __eq__, __ne__ = _binary("=="), _binary("!=")  # type: ignore[assignment]
    __hash__ = None  # type: ignore[assignment]


class _Sum(_Value):
    """``sum(items)`` (from ``0``): written as one ``sum`` call once something reads it, so the
    traced function adds as Python's ``sum`` adds."""

    __slots__ = ("items",)

    def __init__(self, trace: _Trace, items: list[Any]) -> None:
        super().__init__(trace, "")
        self.items = items

    def ref(self) -> str:
        if not self.name:
            items = "".join(f"{self.trace.text(x)}, " for x in self.items)
            self.name = self.trace.emit(f"sum(({items}))").name
        return self.name

    def __add__(self, other: Any) -> Any:
        if not self.name and isinstance(other, (_Value, float)):
            return _Sum(self.trace, [*self.items, other])
        return _binary("+")(self, other)


def _traced(*args: Any) -> _Trace | None:
    """The trace of the first traced argument, or None when every argument is a constant."""
    return next((a.trace for a in args if isinstance(a, _Value)), None)


class _TraceNamespace:
    """:data:`SCALAR_XP`'s functions on traced scalars and lists of them: each records the
    scalar rule SCALAR_XP applies; constants alone are answered by SCALAR_XP itself."""

    def __getattr__(self, name: str) -> Any:
        raise Untraceable(f"the trace has no {name!r}")

    @staticmethod
    def where(cond: Any, a: Any, b: Any) -> Any:
        if not isinstance(cond, _Value):
            if type(cond) is not bool:
                raise Untraceable("where on a constant that is not a bool")
            return a if cond else b
        t = cond.trace
        return t.emit(f"{t.text(a)} if {t.text(cond)} else {t.text(b)}")

    @staticmethod
    def logical_not(x: Any) -> Any:
        t = _traced(x)
        return SCALAR_XP.logical_not(x) if t is None else t.emit(f"not {t.text(x)}")

    @staticmethod
    def logical_and(a: Any, b: Any) -> Any:
        t = _traced(a, b)
        if t is None:
            return SCALAR_XP.logical_and(a, b)
        return t.emit(f"bool({t.text(a)}) and bool({t.text(b)})")

    @staticmethod
    def maximum(a: Any, b: Any) -> Any:
        return _extremum(a, b, ">=", SCALAR_XP.maximum)

    @staticmethod
    def minimum(a: Any, b: Any) -> Any:
        return _extremum(a, b, "<=", SCALAR_XP.minimum)

    def clip(self, x: Any, low: Any, high: Any) -> Any:
        return self.minimum(self.maximum(x, low), high)

    @staticmethod
    def exp(x: Any) -> Any:
        return _call(SCALAR_XP.exp, x)

    @staticmethod
    def sqrt(x: Any) -> Any:
        return _call(SCALAR_XP.sqrt, x)

    @staticmethod
    def abs(x: Any) -> Any:
        return list(map(abs, x)) if isinstance(x, list) else abs(x)

    @staticmethod
    def subtract(a: Any, b: Any) -> Any:
        if isinstance(a, list):
            return [x - y for x, y in zip(a, b, strict=True)]
        return a - b

    @staticmethod
    def greater(a: Any, b: Any) -> Any:
        if isinstance(a, list):
            return [x > y for x, y in zip(a, b, strict=True)]
        return a > b

    @staticmethod
    def matmul(a: Any, b: Any) -> Any:
        if not isinstance(a, list):
            raise Untraceable("matmul of a traced value that is not a list")
        b = b.tolist() if hasattr(b, "tolist") else list(b)
        products = [x * y for x, y in zip(a, b, strict=True)]
        t = _traced(*products)
        if t is None:
            return SCALAR_XP.matmul(a, b)
        items = "".join(f"{t.text(p)}, " for p in products)
        return t.emit(f"float(sum(({items})))")

    @staticmethod
    def zeros(shape: tuple = (), dtype: Any = float) -> Any:
        return SCALAR_XP.zeros(shape, dtype)

    @staticmethod
    def zeros_like(x: Any, dtype: Any = None) -> Any:
        return SCALAR_XP.zeros_like(0.0 if isinstance(x, _Value) else x, dtype)


def _extremum(a: Any, b: Any, keep: str, scalar: Callable) -> Any:
    """SCALAR_XP's ``maximum`` (``keep`` ``>=``) or ``minimum`` (``<=``): ``a`` where it wins
    or is NaN, else ``b``."""
    t = _traced(a, b)
    if t is None:
        return scalar(a, b)
    x, y = t.text(a), t.text(b)
    return t.emit(f"{x} if ({x} {keep} {y} or {x} != {x}) else {y}")


def _call(fn: Callable, x: Any) -> Any:
    """``fn(x)``, called when the traced function runs (a constant: now)."""
    t = _traced(x)
    if t is None:
        return fn(x)
    name = t.text(fn)
    return t.emit(f"{name}({t.text(x)})")


TRACE_XP = _TraceNamespace()


def compile_score(
    cfg: TaskConfig,
    n_joints: int,
    band: reward_lib.JointBand,
    diverged: bool,
    extra_keys: Sequence[str] = (),
) -> Scorer:
    """:func:`~mjx_arm.task.rules.score_step` of ``cfg`` on one env's Python floats, as one
    function.

    Args:
        cfg: the task configuration.
        n_joints: joints of the arm.
        band: the joint-limit band as lists of n floats (a constant of the env).
        diverged: which kind of step the function scores (a constant of the function: the env
            keeps one of each).
        extra_keys: the names of the task's measures in the order ``StepInput.measures`` holds
            them (:meth:`mjx_arm.task.spec.Task.measures`; empty: none).

    Returns:
        ``score(step) -> outcome``: a :class:`~mjx_arm.envs.scalar.step.StepInput` (n joints,
        ``len(extra_keys)`` measures) in, its :class:`~mjx_arm.envs.scalar.step.StepOutcome`
        out (``terms`` a new dict), each value the value and type
        :func:`~mjx_arm.envs.scalar.step.score_generic` gives. Its source is its ``source``.

    Raises:
        Untraceable: the task's rules cannot be traced.
    """
    trace = _Trace()
    value = {name: _Value(trace, name) for name in _INPUTS}
    qpos = [_Value(trace, f"q{j}") for j in range(n_joints)]
    qvel = [_Value(trace, f"w{j}") for j in range(n_joints)]
    extra = {key: _Value(trace, f"m{i}") for i, key in enumerate(extra_keys)} or None
    try:
        score = rules.score_step(
            TRACE_XP, cfg, reward_lib.Progress(value["hold"], value["over"]),
            value["prev_distance"], value["change"], value["distance"], value["force"],
            qpos, qvel, band, diverged, extra,
        )  # fmt: skip
    except Untraceable:
        raise
    except Exception as error:  # e.g. a traced value hashed or indexed
        raise Untraceable(f"the rules of {cfg.task!r} do not trace: {error}") from error
    return _define(trace, score, n_joints, len(extra_keys), cfg.task)


# the locals the traced function unpacks its StepInput into (the progress as hold, over)
_INPUTS = ("hold", "over", "prev_distance", "change", "distance", "force")


def _unpack(names: Sequence[str], source: str) -> list[str]:
    """The line ``a, b, = source`` (none where ``names`` is empty)."""
    return [f"{''.join(f'{name}, ' for name in names)}= {source}"] if names else []


def _define(trace: _Trace, score: rules.StepScore, n_joints: int, n_measures: int, task: str):
    """The Python function ``score(step)`` of the recorded ``trace`` that returns ``score``'s
    values as a StepOutcome (see :func:`compile_score`)."""
    text = trace.text
    terms = "".join(f"{key!r}: {text(v)}, " for key, v in score.terms.items())
    hold, over = text(score.progress.hold), text(score.progress.over)
    out = f"{text(score.success)}, {text(score.over)}, {{{terms}}}, {text(score.reward)}"
    head = "(hold, over), prev_distance, change, distance, force, qpos, qvel, measures"
    source = "\n    ".join(
        [
            "def score(step):",
            f"{head} = step",
            *_unpack([f"q{j}" for j in range(n_joints)], "qpos"),
            *_unpack([f"w{j}" for j in range(n_joints)], "qvel"),
            *_unpack([f"m{i}" for i in range(n_measures)], "measures"),
            *trace.lines,
            f"return _Outcome(_Progress({hold}, {over}), {out}, {text(score.done)})",
        ]
    )
    namespace = {**trace.names, "_Outcome": StepOutcome, "_Progress": reward_lib.Progress}
    exec(compile(source, f"<score_step of {task}>", "exec"), namespace)
    fn = namespace["score"]
    fn.source = source
    return fn


def step_scorers(
    cfg: TaskConfig, n_joints: int, band: reward_lib.JointBand, keys: Sequence[str] = ()
) -> tuple[Scorer, Scorer]:
    """The step rules of a task and arm as two functions of a StepInput, for a sane step and a
    diverged one: traced (:func:`compile_score`), or through ``SCALAR_XP``
    (:func:`~mjx_arm.envs.scalar.step.score_generic`) where the rules do not trace.

    Args:
        cfg: the task configuration.
        n_joints: joints of the arm.
        band: the joint-limit band as lists of n floats.
        keys: the names of the task's measures, in the order of ``StepInput.measures``.

    Returns:
        ``(sane, diverged)``, each ``score(step) -> StepOutcome``.
    """
    try:
        return (
            compile_score(cfg, n_joints, band, False, keys),
            compile_score(cfg, n_joints, band, True, keys),
        )
    except Untraceable:
        keys = tuple(keys)
        return (
            functools.partial(score_generic, cfg, band, False, keys),
            functools.partial(score_generic, cfg, band, True, keys),
        )
