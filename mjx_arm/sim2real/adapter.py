"""Joint velocity commands -> smooth joint position targets for a position-controlled arm."""

from __future__ import annotations

import math

import numpy as np


class VelocityToPositionAdapter:
    """Integrates joint velocity commands into position targets and low-pass filters them.

    Each :meth:`step` adds ``qdot * dt`` to a raw target that starts at the measured joint
    position, then moves the emitted target towards the raw one through a first-order low-pass
    filter of time constant ``tau``. The filter is discretised exactly (zero-order hold):
    ``y += (1 - exp(-dt / tau)) * (raw - y)``, so a jump of the raw target is followed to
    ``1 - exp(-t / tau)`` of its size after ``t`` seconds, for any ``dt``. ``tau = 0`` turns the
    filter off (the emitted target is the raw one).

    The raw target integrates the commands, not the measured position: a position-controlled
    arm follows it, and a lagging arm is pulled along instead of the lag piling up in the
    command. Optional bounds keep the raw target inside the joint limits, so a policy that
    pushes into a limit can back out of it at once (no integrator wind-up).

    Args:
        dt: control period (s), the time between two :meth:`step` calls.
        tau: time constant of the low-pass filter (s), >= 0.
        q0: measured joint position (rad) to start from, ``(n,)``.
        lower, upper: optional bounds (rad) of the raw target, ``(n,)`` each.

    Raises:
        ValueError: ``dt <= 0``, ``tau < 0``, or a non-finite ``q0``.
    """

    def __init__(
        self,
        dt: float,
        tau: float,
        q0: np.ndarray,
        lower: np.ndarray | None = None,
        upper: np.ndarray | None = None,
    ) -> None:
        if not dt > 0:
            raise ValueError(f"dt must be positive, got {dt}")
        if not tau >= 0:
            raise ValueError(f"tau must be >= 0, got {tau}")
        self.dt, self.tau = float(dt), float(tau)
        self.alpha = 1.0 - math.exp(-self.dt / self.tau) if self.tau > 0 else 1.0
        self.lower = None if lower is None else np.asarray(lower, dtype=np.float64)
        self.upper = None if upper is None else np.asarray(upper, dtype=np.float64)
        self.reset(q0)

    def reset(self, q: np.ndarray) -> np.ndarray:
        """Start again from the measured joint position ``q (n,)`` (rad), at rest.

        Returns:
            The target, ``q`` itself, ``(n,)``.
        """
        q = np.array(q, dtype=np.float64)
        if q.ndim != 1 or not np.isfinite(q).all():
            raise ValueError(f"q must be a finite vector, got {q!r}")
        self._raw = self._bounded(q)
        self._target = self._raw.copy()
        return self.target

    def step(self, qdot: np.ndarray) -> np.ndarray:
        """Integrate one velocity command ``qdot (n,)`` (rad/s) over ``dt``.

        Returns:
            The filtered position target (rad), ``(n,)``: a copy.

        Raises:
            ValueError: wrong shape, or NaN / inf entries.
        """
        qdot = np.asarray(qdot, dtype=np.float64)
        if qdot.shape != self._raw.shape:
            raise ValueError(f"qdot must have shape {self._raw.shape}, got {qdot.shape}")
        if not np.isfinite(qdot).all():
            raise ValueError(f"qdot contains NaN or inf: {qdot.tolist()}")
        self._raw = self._bounded(self._raw + qdot * self.dt)
        self._target += self.alpha * (self._raw - self._target)
        return self.target

    @property
    def target(self) -> np.ndarray:
        """The current filtered target (rad), ``(n,)``: a copy."""
        return self._target.copy()

    @property
    def raw_target(self) -> np.ndarray:
        """The integrated target before the filter (rad), ``(n,)``: a copy."""
        return self._raw.copy()

    def _bounded(self, q: np.ndarray) -> np.ndarray:
        if self.lower is not None:
            q = np.maximum(q, self.lower)
        if self.upper is not None:
            q = np.minimum(q, self.upper)
        return q
