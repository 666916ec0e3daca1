"""An array namespace for one env at a time: the step rules on Python scalars.

The rules (:mod:`mjx_arm.task.rules`, :mod:`mjx_arm.task.reward`, the tasks) are written once
against an array namespace ``xp``. Under ``jax.numpy`` one call covers a batch; a CPU env scores
one step at a time, on scalars, where numpy's cost per call (about 1 us for ``np.where`` of two
floats, 0.2 us for ``np.exp`` against 0.06 us for ``math.exp``) was most of a step.

:data:`SCALAR_XP` has numpy's names. A function whose arguments are all scalars (Python's
``float``, ``int`` and ``bool``, and numpy's ``float64``, a ``float``) answers with plain
Python (operators, :mod:`math`) and returns Python scalars; the elementwise functions the
rules apply to joint vectors (``abs``, ``subtract``, ``greater``, ``matmul``) also take one
env's vector as a Python list and answer with lists (or a float). Any other argument (arrays,
other numpy scalars) goes to numpy unchanged, as does every name not defined here. The values are
numpy's: IEEE arithmetic in the same order (``math.sqrt`` is exact as ``np.sqrt`` is;
``math.exp`` matched ``np.exp`` bit for bit on float64 in the tests, and is within an ulp of it
wherever numpy takes its own SIMD ``exp``); NaN propagates as in numpy, and an overflowing
``exp`` is ``inf``. The CPU envs pick it once, at construction; the same rule functions serve
``numpy`` batches and ``jax.numpy``.
"""

from __future__ import annotations

import math
import operator
from typing import Any

import numpy as np

_SCALAR = (float, int)  # Python's float, int, bool; numpy's float64 (a float subclass)
_ZERO_D = (float, int, np.generic)  # every scalar, numpy's included


class ScalarNamespace:
    """numpy with a plain Python path for scalar arguments (see the module docstring)."""

    def __getattr__(self, name: str) -> Any:
        return getattr(np, name)

    def __repr__(self) -> str:
        return "<array namespace: numpy with Python scalars>"

    @staticmethod
    def where(cond, a, b):
        """``a`` where ``cond`` else ``b``."""
        if isinstance(cond, bool) and isinstance(a, _SCALAR) and isinstance(b, _SCALAR):
            return a if cond else b
        return np.where(cond, a, b)

    @staticmethod
    def logical_not(x):
        """``not x``."""
        return (not x) if isinstance(x, _SCALAR) else np.logical_not(x)

    @staticmethod
    def logical_and(a, b):
        """``a and b``, as a bool."""
        if isinstance(a, _SCALAR) and isinstance(b, _SCALAR):
            return bool(a) and bool(b)
        return np.logical_and(a, b)

    @staticmethod
    def maximum(a, b):
        """The larger of ``a`` and ``b``; NaN where either is NaN (``a``'s first)."""
        if isinstance(a, _SCALAR) and isinstance(b, _SCALAR):
            return a if (a >= b or a != a) else b
        return np.maximum(a, b)

    @staticmethod
    def minimum(a, b):
        """The smaller of ``a`` and ``b``; NaN where either is NaN (``a``'s first)."""
        if isinstance(a, _SCALAR) and isinstance(b, _SCALAR):
            return a if (a <= b or a != a) else b
        return np.minimum(a, b)

    def clip(self, x, low, high):
        """``minimum(maximum(x, low), high)`` (``np.clip``'s values)."""
        if isinstance(x, _SCALAR) and isinstance(low, _SCALAR) and isinstance(high, _SCALAR):
            x = x if (x >= low or x != x) else low
            return x if (x <= high or x != x) else high
        return self.minimum(self.maximum(x, low), high)

    @staticmethod
    def exp(x):
        """e to the ``x``; ``inf`` on overflow."""
        if not isinstance(x, _SCALAR):
            return np.exp(x)
        try:
            return math.exp(x)
        except OverflowError:
            return math.inf

    @staticmethod
    def sqrt(x):
        """The square root of ``x``; NaN below zero."""
        if not isinstance(x, _SCALAR):
            return np.sqrt(x)
        return math.sqrt(x) if x >= 0 else math.nan

    @staticmethod
    def vecdot(a, b):
        """``np.vecdot``; two 1-D arrays through ``ndarray.dot`` (numpy's vecdot and dot run
        the same inner product; dot skips the gufunc machinery)."""
        if a.ndim == 1 and b.ndim == 1 and a.dtype == b.dtype:
            return a.dot(b)
        return np.vecdot(a, b)

    @staticmethod
    def abs(x):
        """``|x|``; a list entry by entry."""
        return list(map(abs, x)) if isinstance(x, list) else abs(x)

    @staticmethod
    def subtract(a, b):
        """``a - b``; a list entry by entry."""
        if isinstance(a, list):
            return list(map(operator.sub, a, b))
        return np.subtract(a, b)

    @staticmethod
    def greater(a, b):
        """``a > b``; a list entry by entry."""
        if isinstance(a, list):
            return list(map(operator.gt, a, b))
        return np.greater(a, b)

    @staticmethod
    def matmul(a, b):
        """``a @ b``; a list ``a`` with a vector ``b``: their inner product as a float, summed
        left to right (as numpy's dot sums a short vector)."""
        if isinstance(a, list):
            b = b.tolist() if isinstance(b, np.ndarray) else b
            return float(sum(map(operator.mul, a, b)))
        return np.matmul(a, b)

    @staticmethod
    def zeros(shape=(), dtype=float):
        """Zeros of ``shape``: a Python ``0.0`` (or ``False``, ``0``) for a scalar."""
        if shape == () and dtype in (float, bool, int):
            return dtype(0)
        return np.zeros(shape, dtype)

    @staticmethod
    def zeros_like(x, dtype=None):
        """Zeros shaped like ``x``: a Python ``0.0`` (or ``False``) for a scalar."""
        if isinstance(x, _SCALAR):
            return (float if dtype is None else dtype)(0)
        return np.zeros_like(x, dtype=dtype)

    @staticmethod
    def stack(arrays, axis=0):
        """``np.stack``; scalars into a 1-D array with one ``np.array`` call (``np.stack``
        costs several microseconds on four scalars)."""
        if axis in (0, -1) and all(isinstance(a, _ZERO_D) for a in arrays):
            return np.array(arrays)
        return np.stack(arrays, axis=axis)

    @staticmethod
    def cross(a, b):
        """``np.cross``; two float64 ``(3,)`` vectors in Python floats (``np.cross`` costs
        tens of microseconds on them; the products and differences are its own)."""
        if a.shape == b.shape == (3,) and a.dtype == b.dtype == np.float64:
            (a0, a1, a2), (b0, b1, b2) = a.tolist(), b.tolist()
            return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])
        return np.cross(a, b)


SCALAR_XP = ScalarNamespace()
