"""Inverse kinematics with the tool pointing down, by damped least squares on MuJoCo's Jacobian.

Why not a library such as ``mink``: the problem here is small (one site, one position, one axis
direction, 5 to 7 joints, box limits), it runs a few hundred times per arm, and MuJoCo already
gives the Jacobian (``mj_jacSite``). Damped least squares with the joint limits clamped after
each step and a null-space pull towards a preferred pose converges in tens of iterations, needs
no QP solver and stays deterministic across machines.

The pose asked for: the ee site at a point (m, base frame) and the tool axis (a unit vector in
the ee frame, :func:`tool_axis`) pointing straight down; the rotation about the tool axis is
free.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import mujoco
import numpy as np

DOWN = np.array([0.0, 0.0, -1.0])
# Converged: within 1 mm of the point, the tool within 1 degree of vertical.
POSITION_TOL = 1e-3
TILT_TOL = np.radians(1.0)
MAX_ITERATIONS = 200
POLISH_FROM = 120  # iterations with the null-space pull; the rest polish without it
STALL_ITERATIONS = 10  # iterations without progress before a solve gives up
DAMPING = 0.05  # damped least squares' lambda (m, rad)
MAX_STEP = 0.25  # largest joint change of one iteration (rad)
NULL_GAIN = 0.2  # the pull towards the preferred pose, per iteration
NULL_WEIGHT = 0.01  # m per rad: the pull's share of the progress a solve is judged by


class IkResult(NamedTuple):
    """One solve: joint angles ``(n,)`` (rad), position error (m), tilt of the tool from
    vertical (rad), and whether both are within tolerance."""

    q: np.ndarray
    position_error: float
    tilt: float
    converged: bool


@dataclass
class ToolDownIk:
    """Tool-down IK on a compiled model of the arm, ids looked up once.

    Args:
        model: the arm's MuJoCo model (its scene may be there too).
        joint_names: the n arm joints.
        site: the ee site's name.
        lower, upper: the box the solution stays in (rad), ``(n,)`` each: the joint limits
            shrunk by a margin.
        tool: the tool axis in the ee site's frame, ``(3,)`` unit.
    """

    model: mujoco.MjModel
    joint_names: tuple[str, ...]
    site: str
    lower: np.ndarray
    upper: np.ndarray
    tool: np.ndarray

    def __post_init__(self) -> None:
        self.data = mujoco.MjData(self.model)
        joints = [self.model.joint(name) for name in self.joint_names]
        self.qadr = np.array([j.qposadr[0] for j in joints])
        self.dofadr = np.array([j.dofadr[0] for j in joints])
        self.site_id = self.model.site(self.site).id
        self._jacp = np.zeros((3, self.model.nv))
        self._jacr = np.zeros((3, self.model.nv))

    def pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Forward kinematics: the ee point ``(3,)`` and the tool axis in the world ``(3,)``."""
        self.data.qpos[self.qadr] = q
        mujoco.mj_kinematics(self.model, self.data)
        rot = self.data.site_xmat[self.site_id].reshape(3, 3)
        return self.data.site_xpos[self.site_id].copy(), rot @ self.tool

    def jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position and rotation Jacobians of the ee site at ``q``, ``(3, n)`` each (after
        :meth:`pose` at the same ``q``, or it computes the kinematics itself)."""
        self.pose(q)
        return self._jacobian_here()

    def _jacobian_here(self) -> tuple[np.ndarray, np.ndarray]:
        """The Jacobians at the pose the data holds (its kinematics computed)."""
        mujoco.mj_comPos(self.model, self.data)
        mujoco.mj_jacSite(self.model, self.data, self._jacp, self._jacr, self.site_id)
        return self._jacp[:, self.dofadr], self._jacr[:, self.dofadr]

    def manipulability(self, q: np.ndarray) -> float:
        """Yoshikawa's measure of the position Jacobian, ``sqrt(det(J J^T))`` (m^3)."""
        jp, _ = self.jacobian(q)
        return float(np.sqrt(max(np.linalg.det(jp @ jp.T), 0.0)))

    def solve(
        self, target: np.ndarray, q0: np.ndarray, prefer: np.ndarray | None = None
    ) -> IkResult:
        """Joint angles that put the ee site at ``target (3,)`` with the tool down.

        Stops once within a tenth of the tolerances, or when the error has not shrunk by 1%
        over :data:`STALL_ITERATIONS` iterations (a target out of reach, or a limit in the way).

        Args:
            target: the point (m, base frame).
            q0: the start, ``(n,)``; clipped into the box first.
            prefer: the pose the redundant directions are pulled towards (default: ``q0``).
        """
        q = np.clip(np.asarray(q0, float), self.lower, self.upper)
        prefer = q.copy() if prefer is None else np.asarray(prefer, float)
        best, since, polish = np.inf, 0, False
        # first with the pull to ``prefer``, then polished without it (from POLISH_FROM, or
        # once the pull stalls): the damped inverse's null space is not exact, and the pull
        # would hold the solution off by a millimetre or so
        for iteration in range(MAX_ITERATIONS):
            pos, axis = self.pose(q)
            err_p, err_o = target - pos, _cross(axis, DOWN)
            error = float(np.sqrt(err_p @ err_p + err_o @ err_o))
            if error < min(POSITION_TOL, TILT_TOL) / 10 and (polish or iteration > 0):
                break
            # while pulling, progress also counts the way to ``prefer``
            progress = error if polish else error + NULL_WEIGHT * np.abs(prefer - q).sum()
            best, since = (progress, 0) if progress < 0.99 * best else (best, since + 1)
            if since > STALL_ITERATIONS:
                if polish:
                    break
                polish, since, best = True, 0, np.inf
            polish = polish or iteration >= POLISH_FROM
            pull = None if polish else NULL_GAIN * (prefer - q)
            q = np.clip(q + self._step(axis, err_p, err_o, pull), self.lower, self.upper)
        pos, axis = self.pose(q)
        position_error, tilt = float(np.linalg.norm(target - pos)), _tilt(axis)
        converged = position_error < POSITION_TOL and tilt < TILT_TOL
        return IkResult(q, position_error, tilt, converged)

    def _step(self, axis, err_p, err_o, pull) -> np.ndarray:
        """One damped least-squares step ``(n,)`` at the pose the data holds, with ``pull
        (n,)`` (or None) in its null space."""
        jp, jr = self._jacobian_here()
        # only the tilt of the tool axis is asked for: drop the spin about it
        jo = jr - np.outer(axis, axis @ jr)
        jac = np.concatenate([jp, jo])
        err = np.concatenate([err_p, err_o])
        gram = jac @ jac.T
        gram[np.diag_indices(6)] += DAMPING**2
        step = jac.T @ np.linalg.solve(gram, err)
        if pull is not None:
            step += pull - jac.T @ np.linalg.solve(gram, jac @ pull)
        biggest = np.abs(step).max()
        return step * (MAX_STEP / biggest) if biggest > MAX_STEP else step


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of two ``(3,)`` vectors (numpy's general one is slow on small arrays)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def _tilt(axis: np.ndarray) -> float:
    """Angle (rad) between a unit vector ``(3,)`` and straight down."""
    return float(np.arccos(np.clip(axis @ DOWN, -1.0, 1.0)))


def tool_axis(ik: ToolDownIk, q: np.ndarray, last_joint: str) -> np.ndarray:
    """The tool axis in the ee site's frame, ``(3,)`` unit: from the last arm joint's anchor
    to the ee point where the two are at least 1 cm apart, else the last joint's axis, pointed
    away from the joint before it.

    The last joint of an arm turns the tool about its own axis (a flange), and the tool sticks
    out along it; where the ee point sits on the joint's anchor, the axis direction is taken.
    """
    model, data = ik.model, ik.data
    ik.pose(q)
    rot = data.site_xmat[ik.site_id].reshape(3, 3)
    ee = data.site_xpos[ik.site_id]
    joint = model.joint(last_joint).id
    mujoco.mj_kinematics(model, data)
    anchor, axis = data.xanchor[joint].copy(), data.xaxis[joint].copy()
    out = ee - anchor
    if np.linalg.norm(out) >= 0.01:
        direction = out / np.linalg.norm(out)
    else:
        before = model.jnt_bodyid[joint]
        parent_anchor = data.xpos[model.body_parentid[before]]
        direction = axis if axis @ (anchor - parent_anchor) >= 0 else -axis
    local = rot.T @ direction
    return local / np.linalg.norm(local)
