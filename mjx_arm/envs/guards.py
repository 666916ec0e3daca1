"""Guards of the Gymnasium envs against misuse: one env entered by two threads at once, and
``reset`` options that would start an episode the contract cannot observe.

An engine's state (MuJoCo's ``MjData``, PyBullet's client) is not safe to step from two threads:
two ``mj_step`` calls on one ``MjData`` crash the process (SIGSEGV). Every public method that
touches the physics is entered through a non-blocking re-entrant lock (:class:`SingleThreadEnv`):
a second thread that calls in while the first is inside gets :class:`ConcurrentEnvUseError`
at once, and the first finishes undisturbed. The lock only refuses overlap: an env handed from
one thread to another between calls works as before. The check costs well under a microsecond
of a step of tens of microseconds.
"""

from __future__ import annotations

import functools
import math
import threading
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from mjx_arm.task.observation import POSITION_BOUND

# The methods entered under the lock, wherever a subclass defines them.
GUARDED = ("reset", "step", "render", "get_ee_pose", "apply_action")


class ConcurrentEnvUseError(RuntimeError):
    """A second thread entered an env while another thread was inside it."""


class InvalidResetOptionError(ValueError, TypeError):
    """A ``reset(options=...)`` value that is not what the contract takes (wrong shape, not
    real numbers, NaN or inf, out of range); both a ValueError and a TypeError."""


def exclusive(method: Callable) -> Callable:
    """``method`` entered under its env's lock; another thread inside raises
    :class:`ConcurrentEnvUseError` instead of waiting or corrupting the physics."""
    if getattr(method, "_exclusive", False):
        return method

    @functools.wraps(method)
    def guarded(self, *args, **kwargs):
        lock = self._in_use
        if not lock.acquire(False):
            raise ConcurrentEnvUseError(
                f"{method.__name__}() called from thread {threading.current_thread().name!r} "
                f"while another thread is inside this {type(self).__name__}: an env serves one "
                "thread at a time (make one env per thread, or a vector env)"
            )
        try:
            return method(self, *args, **kwargs)
        finally:
            lock.release()

    guarded._exclusive = True
    return guarded


class SingleThreadEnv:
    """Base of the envs: the :data:`GUARDED` methods of every subclass are :func:`exclusive`,
    over one re-entrant lock per env (a subclass's ``step`` calling ``super().step`` holds it
    once more, in the same thread)."""

    def __new__(cls, *args: Any, **kwargs: Any):
        self = super().__new__(cls)
        self._in_use = threading.RLock()  # before __init__: no thread sees an env without it
        return self

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        for name in GUARDED:
            if name in cls.__dict__:
                setattr(cls, name, exclusive(cls.__dict__[name]))


def _real_vector(value: Any, name: str, size: int) -> np.ndarray:
    """``value`` as float64 ``(size,)`` of finite real numbers.

    Raises:
        InvalidResetOptionError: another shape, not real numbers, NaN or inf.
    """
    try:
        array = np.asarray(value)
    except (ValueError, TypeError) as exc:
        raise InvalidResetOptionError(f"options[{name!r}] is not an array: {exc}") from None
    if array.dtype.kind not in "biuf" or array.shape != (size,):
        raise InvalidResetOptionError(
            f"options[{name!r}] must be {size} real numbers, got shape {array.shape} "
            f"({array.dtype})"
        )
    array = array.astype(np.float64)
    if not np.isfinite(array).all():
        raise InvalidResetOptionError(f"options[{name!r}] holds NaN or inf: {array.tolist()}")
    return array


def reset_target(value: Any) -> np.ndarray:
    """The target body's position (m) of ``reset(options={"target": value})``, ``(3,)``.

    Raises:
        InvalidResetOptionError: not 3 finite real numbers, or a coordinate beyond
            +-:data:`~mjx_arm.task.observation.POSITION_BOUND` m, where the observation's
            ``target_rel`` could not hold it.
    """
    target = _real_vector(value, "target", 3)
    if np.abs(target).max() > POSITION_BOUND:
        raise InvalidResetOptionError(
            f"options['target'] = {target.tolist()} m is outside the +-{POSITION_BOUND} m in "
            "each axis the observation bounds positions to (beyond every arm's reach)"
        )
    return target


def _positive(value: Any, name: str, low: float, inclusive: bool) -> np.ndarray:
    """A finite real number above (or, ``inclusive``, at least) ``low``, as a float64 0-d array."""
    number = _real_vector(np.reshape(value, (1,)) if np.ndim(value) == 0 else value, name, 1)[0]
    if number < low or (number == low and not inclusive):
        bound = f">= {low}" if inclusive else f"> {low}"
        raise InvalidResetOptionError(f"options[{name!r}] must be {bound}, got {number}")
    return np.asarray(number)


def reset_object(obj: Any, options: Mapping[str, Any]) -> Any:
    """A gripper task's drawn object start ``obj`` (:class:`~mjx_arm.task.grip.ObjectStart`)
    with the ``object_quat`` (w x y z, not zero), ``object_mass`` (kg, > 0) and
    ``object_friction`` (>= 0) the options give.

    Raises:
        InvalidResetOptionError: a value of the wrong shape, not finite or out of range.
    """
    changes = {}
    if "object_quat" in options:
        quat = _real_vector(options["object_quat"], "object_quat", 4)
        if not math.hypot(*quat) > 0:
            raise InvalidResetOptionError("options['object_quat'] must not be all zeros")
        changes["quat"] = quat
    if "object_mass" in options:
        changes["mass"] = _positive(options["object_mass"], "object_mass", 0.0, False)
    if "object_friction" in options:
        changes["friction"] = _positive(options["object_friction"], "object_friction", 0.0, True)
    return obj._replace(**changes)


def reset_overrides(options: Mapping[str, Any] | None, body: np.ndarray, obj: Any):
    """``(target body position, object start)`` of a reset: the drawn ``body`` and ``obj``,
    with the values ``options`` gives, checked (:func:`reset_target`, :func:`reset_object`)."""
    if not options:
        return body, obj
    if "target" in options:
        body = reset_target(options["target"])
    if obj is not None:
        obj = reset_object(obj, options)
    return body, obj
