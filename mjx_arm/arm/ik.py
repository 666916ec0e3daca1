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

import math
from dataclasses import dataclass
from typing import NamedTuple

import mujoco
import numpy as np

DOWN = np.array([0.0, 0.0, -1.0])
LIMIT_MARGIN = 0.10  # rad, or 5% of a narrower range: poses stay this far inside the limits
HOME_STARTS = 24  # seeded IK starts for a home pose
HOME_CANDIDATES = 6  # distinct home poses kept, best-conditioned first
PENETRATION = 1e-3  # m: a contact deeper than this is a collision
TARGET_TILT = np.radians(15.0)  # a task target counts as reached tool-down within this tilt
COLLISION_GROUP = 3  # the converter's group of collision shapes
RAY_START = 0.5  # m: rays for the tool's surface start this far out along the tool axis
PROTRUSION_TURNS = 6  # turns of the pressed square about the tool axis (over a quarter turn)
DEEPEST_SPAN = 0.3  # m: the square searched for the tool's deepest point
DEEPEST_RAYS = 61  # rays a side over it (5 mm apart)
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
        self,
        target: np.ndarray,
        q0: np.ndarray,
        prefer: np.ndarray | None = None,
        tool_down: bool = True,
    ) -> IkResult:
        """Joint angles that put the ee site at ``target (3,)`` with the tool down.

        Stops once within a tenth of the tolerances, or when the error has not shrunk by 1%
        over :data:`STALL_ITERATIONS` iterations (a target out of reach, or a limit in the way).

        Args:
            target: the point (m, base frame).
            q0: the start, ``(n,)``; clipped into the box first.
            prefer: the pose the redundant directions are pulled towards (default: ``q0``).
            tool_down: ask for the tool pointing down; False asks for the point alone (the
                result's ``converged`` then ignores the tilt).
        """
        q = np.clip(np.asarray(q0, float), self.lower, self.upper)
        prefer = q.copy() if prefer is None else np.asarray(prefer, float)
        best, since, polish = np.inf, 0, False
        # first with the pull to ``prefer``, then polished without it (from POLISH_FROM, or
        # once the pull stalls): the damped inverse's null space is not exact, and the pull
        # would hold the solution off by a millimetre or so
        for iteration in range(MAX_ITERATIONS):
            axis, err_p, err_o, error = self._errors(q, target, tool_down)
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
            step = self._step(axis, err_p, err_o if tool_down else None, pull)
            q = np.clip(q + step, self.lower, self.upper)
        return self._result(q, target, tool_down)

    def _errors(
        self, q: np.ndarray, target: np.ndarray, tool_down: bool
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """At ``q (n,)`` (the data left at that pose): the tool axis ``(3,)``, the position
        error ``(3,)`` to ``target``, the tilt error ``(3,)`` (zero without ``tool_down``) and
        the norm of both."""
        pos, axis = self.pose(q)
        err_p = target - pos
        err_o = _cross(axis, DOWN) if tool_down else np.zeros(3)
        return axis, err_p, err_o, float(np.sqrt(err_p @ err_p + err_o @ err_o))

    def _result(self, q: np.ndarray, target: np.ndarray, tool_down: bool) -> IkResult:
        """The result at the final ``q (n,)``: its errors and whether they are within the
        tolerances (the tilt only with ``tool_down``)."""
        pos, axis = self.pose(q)
        position_error, tilt = float(np.linalg.norm(target - pos)), _tilt(axis)
        converged = position_error < POSITION_TOL and (tilt < TILT_TOL or not tool_down)
        return IkResult(q, position_error, tilt, converged)

    def _step(self, axis, err_p, err_o, pull) -> np.ndarray:
        """One damped least-squares step ``(n,)`` at the pose the data holds, with ``pull
        (n,)`` (or None) in its null space; ``err_o`` None asks for the position alone."""
        jp, jr = self._jacobian_here()
        if err_o is None:
            jac, err = jp, err_p
        else:
            # only the tilt of the tool axis is asked for: drop the spin about it
            jo = jr - np.outer(axis, axis @ jr)
            jac, err = np.concatenate([jp, jo]), np.concatenate([err_p, err_o])
        gram = jac @ jac.T
        gram[np.diag_indices(len(err))] += DAMPING**2
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


class ToolDownSolver:
    """Tool-down poses of one arm: IK inside its limits less a margin, with a collision check.

    Args:
        model: the arm in a scene with the table and self-collision on, so a pose that folds
            the arm into itself or into the table shows as a contact.
        joint_names: the n arm joints; the last one turns the tool (:func:`tool_axis`).
        lower, upper: the joints' limits (rad), ``(n,)`` each.
        site: the ee site.
        tool: the tool axis in the ee site's frame, ``(3,)`` unit; None finds it
            (:func:`tool_axis`).
    """

    def __init__(self, model, joint_names, lower, upper, site: str = "ee", tool=None) -> None:
        self.lower, self.upper = joint_box(np.asarray(lower), np.asarray(upper))
        self.middle = 0.5 * (self.lower + self.upper)
        up = np.array([0.0, 0.0, 1.0])
        self.ik = ToolDownIk(model, tuple(joint_names), site, self.lower, self.upper, up)
        self.last_joint = joint_names[-1]
        if tool is None:
            tool = tool_axis(self.ik, self.middle, self.last_joint)
        self.ik.tool = np.asarray(tool, float)
        self._full_turn = (np.asarray(upper) - np.asarray(lower)) > 2 * math.pi + 1e-6
        self._static = model.body_weldid == 0

    def canonical(self, q: np.ndarray) -> np.ndarray:
        """``q (n,)`` with each joint of a range over a full turn moved by whole turns to the
        angle nearest the middle of its range."""
        turns = np.round((self.middle - q) / (2 * math.pi)) * self._full_turn
        shifted = q + 2 * math.pi * turns
        inside = (shifted >= self.lower) & (shifted <= self.upper)
        return np.where(inside, shifted, q)

    def collides(self, q: np.ndarray) -> bool:
        """Whether the arm at ``q (n,)`` penetrates itself or the table by over 1 mm.

        Contacts between two static bodies, between a body and its parent, or between the
        first moving link and anything static do not count: a base welded to the world becomes
        part of it (MuJoCo does not filter a link against the world body), and the first link
        overlaps the base by design in some URDFs.
        """
        model, data = self.ik.model, self.ik.data
        data.qpos[self.ik.qadr] = q
        mujoco.mj_fwdPosition(model, data)
        parent = model.body_parentid
        for contact in data.contact[: data.ncon]:
            one, two = model.geom_bodyid[contact.geom]
            if contact.dist >= -PENETRATION or (self._static[one] and self._static[two]):
                continue
            first = (self._static[one] and self._static[parent[two]]) or (
                self._static[two] and self._static[parent[one]]
            )
            if not first and parent[one] != two and parent[two] != one:
                return True
        return False

    def tool_reach(self, q: np.ndarray) -> float:
        """How far (m) the collision shapes moved by the last arm joint stick out past the ee
        point along the tool axis, at ``q (n,)``: what touches a surface below the ee first."""
        model, data = self.ik.model, self.ik.data
        _, axis = self.ik.pose(q)
        ee = data.site_xpos[self.ik.site_id]
        wrist = model.jnt_bodyid[model.joint(self.last_joint).id]
        reach = 0.0
        signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
        for geom in range(model.ngeom):
            if not (model.geom_contype[geom] or model.geom_conaffinity[geom]):
                continue
            if not _below(model, int(model.geom_bodyid[geom]), int(wrist)):
                continue
            centre, half = model.geom_aabb[geom, :3], model.geom_aabb[geom, 3:]
            rot = data.geom_xmat[geom].reshape(3, 3)
            corners = data.geom_xpos[geom] + (centre + signs * half) @ rot.T
            reach = max(reach, float(((corners - ee) @ axis).max()))
        return reach

    def tool_protrusion(self, q: np.ndarray, half_width: float, turn: float = 0.0) -> float | None:
        """Where the tool meets a flat surface pressed square against it: how far (m) its
        collision shapes within ``half_width`` of the tool axis (a square across it) reach
        past the ee point along the tool axis, at ``q (n,)``. Negative where they stay behind
        it (an open hand around the ee point); None where no shape lies within the square.

        Rays (5 x 5 over the square) come back along the tool axis from half a metre out and
        stop at the first collision shape of the arm (MuJoCo's ``mj_ray`` over group 3).
        ``turn`` (rad) turns the square about the axis.
        """
        model, data = self.ik.model, self.ik.data
        ee, axis = self.ik.pose(q)
        across = np.linalg.svd(axis[None, :])[2][1:]  # two unit vectors across the axis
        c, s = math.cos(turn), math.sin(turn)
        across = np.array([c * across[0] + s * across[1], c * across[1] - s * across[0]])
        wrist = int(model.jnt_bodyid[model.joint(self.last_joint).id])
        groups = np.zeros(6, np.uint8)
        groups[COLLISION_GROUP] = 1
        geom, best = np.zeros(1, np.int32), None
        steps = np.linspace(-half_width, half_width, 5)
        for u in steps:
            for v in steps:
                start = ee + RAY_START * axis + u * across[0] + v * across[1]
                dist = mujoco.mj_ray(model, data, start, -axis, groups, 0, -1, geom)
                if dist < 0 or not _below(model, int(model.geom_bodyid[geom[0]]), wrist):
                    continue
                reach = RAY_START - dist
                best = reach if best is None else max(best, reach)
        return best

    def deepest_point(self, q: np.ndarray) -> np.ndarray | None:
        """The point of the tool that reaches furthest along the tool axis, in the ee site's
        frame ``(3,)``, at ``q (n,)``: rays along the axis over a square :data:`DEEPEST_SPAN`
        wide (:data:`DEEPEST_RAYS` a side), the deepest hit on a shape moved by the last arm
        joint, the one nearest the axis among those within 1 mm of it; None where no ray hits
        one."""
        model, data = self.ik.model, self.ik.data
        ee, axis = self.ik.pose(q)
        rotation = data.site_xmat[self.ik.site_id].reshape(3, 3).copy()
        across = np.linalg.svd(axis[None, :])[2][1:]
        wrist = int(model.jnt_bodyid[model.joint(self.last_joint).id])
        groups = np.zeros(6, np.uint8)
        groups[COLLISION_GROUP] = 1
        geom, hits = np.zeros(1, np.int32), []
        steps = np.linspace(-0.5 * DEEPEST_SPAN, 0.5 * DEEPEST_SPAN, DEEPEST_RAYS)
        for u in steps:
            for v in steps:
                start = ee + RAY_START * axis + u * across[0] + v * across[1]
                dist = mujoco.mj_ray(model, data, start, -axis, groups, 0, -1, geom)
                if dist >= 0 and _below(model, int(model.geom_bodyid[geom[0]]), wrist):
                    hits.append((RAY_START - dist, math.hypot(u, v), u, v))
        if not hits:
            return None
        deepest = max(h[0] for h in hits)
        depth, _, u, v = min((h for h in hits if h[0] > deepest - 1e-3), key=lambda h: h[1])
        return rotation.T @ (depth * axis + u * across[0] + v * across[1])

    def tool_contact(self, q: np.ndarray, half_width: float) -> tuple[float | None, float]:
        """:meth:`tool_protrusion` of the unturned square at ``q (n,)``, and its spread (m):
        how much it changes as the square turns about the tool axis (:data:`PROTRUSION_TURNS`
        turns over a quarter turn, the square's symmetry). The spread is near zero for a tool
        whose face meets the box alike at any turn, several centimetres for shapes beside the
        axis that straddle the box at one turn and land on it at another; 0 where no turn
        finds a shape."""
        turns = np.linspace(0.0, math.pi / 2, PROTRUSION_TURNS, endpoint=False)
        reaches = [self.tool_protrusion(q, half_width, float(t)) for t in turns]
        found = [reach for reach in reaches if reach is not None]
        return reaches[0], (max(found) - min(found) if found else 0.0)

    def homes(self, point: np.ndarray) -> list[np.ndarray]:
        """Distinct collision-free tool-down poses at ``point (3,)`` from seeded starts (the
        middle of the limits first), best-conditioned first, at most HOME_CANDIDATES."""
        rng = np.random.default_rng(0)
        found: list[tuple[float, np.ndarray]] = []
        for k in range(HOME_STARTS):
            start = self.middle if k == 0 else rng.uniform(self.lower, self.upper)
            result = self.ik.solve(point, start, prefer=self.middle)
            if not result.converged:
                continue
            q = self.canonical(result.q)
            if any(np.abs(q - other).max() < 0.05 for _, other in found) or self.collides(q):
                continue
            found.append((self.ik.manipulability(q), q))
        found.sort(key=lambda item: -item[0])
        return [q for _, q in found[:HOME_CANDIDATES]]

    def reach_from(
        self, home: np.ndarray, points: np.ndarray, tool_down: bool = True
    ) -> list[np.ndarray | None]:
        """Poses at each of ``points (m, 3)``, each solved from ``home``; None where the IK
        does not converge inside the limits.

        ``tool_down``: the tool pointing down, within :data:`TARGET_TILT` (what a contact
        task presses with): where the exact pose is out of the limits, the point alone is
        solved from the nearest try and kept if the tool tilts no more than that.
        """
        out = []
        for point in points:
            result = self.ik.solve(point, home, prefer=home, tool_down=tool_down)
            if tool_down and not result.converged:
                result = self.ik.solve(point, result.q, tool_down=False)
                if result.tilt > TARGET_TILT:
                    result = result._replace(converged=False)
            out.append(result.q if result.converged else None)
        return out


def _below(model: mujoco.MjModel, body: int, root: int) -> bool:
    """Whether ``body`` is ``root`` or hangs below it in the kinematic tree."""
    while body > 0:
        if body == root:
            return True
        body = int(model.body_parentid[body])
    return body == root


def joint_box(lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The joint limits ``(n,)`` shrunk by :data:`LIMIT_MARGIN` (or 5% of a narrower range),
    and bounded to +-2 pi."""
    lower, upper = np.maximum(lower, -2 * math.pi), np.minimum(upper, 2 * math.pi)
    margin = np.minimum(LIMIT_MARGIN, 0.05 * (upper - lower))
    return lower + margin, upper - margin
