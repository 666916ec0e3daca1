"""The task setup of an arm, derived from its model: home pose, task area and timing.

No arm needs a hand-written file to train. What an arm brings by itself (its ee point at the
tool's working point, its servo gain) is derived in :mod:`mjx_arm.arm.info`; what a task needs
of it is derived here, for a task config and an arm:

- **task area**: the task's target box (:meth:`TaskConfig.target_box`) scaled about the base
  by ``workspace_scale``. It starts at the arm's reach scale (its horizontal reach over the
  shipped arm's) and changes in steps of 10% (:data:`SCALE_STEPS`, smaller first) until every
  target of a 3 x 3 x 3 grid over the box (as the task places it: Touch's box on the table,
  Lift's cube) is reachable with the tool pointing down from the home pose, within the joint
  limits less a margin.
- **home pose**: the tool pointing down, :data:`HOME_HEIGHT` above the table (lower where no
  pose holds the tool down that high: :data:`HOME_HEIGHTS`) over the middle of the task area,
  found by tool-down inverse kinematics (:mod:`mjx_arm.arm.ik`) from seeded starts; among the
  poses free of self-collision and of the table, the one that reaches the most grid targets
  wins, then the best-conditioned (manipulability). Angles of joints with a range over a full
  turn are taken nearest the middle of the range. Where the slowest home-to-target motion from
  that height would lengthen the episode, the lower heights are tried too, and the highest home
  whose motions fit the task's episode wins (a small or slow arm's home at 0.2 m can sit a
  wrist swing of 1.5 rad from the box; nearer the table, its moves are shorter). Touch's
  home that would sit less than :data:`PRESS_CLEARANCE` above the box top (a small arm's) is
  raised to the highest tool-down height below the next height tried: the tool needs that room
  to slow down before it presses (the SO-101's tip 7 mm above the box struck it at 54-72 N).
- **episode**: the time the home-to-target motions take at the task's commanded joint speeds
  (:meth:`TaskConfig.joint_speeds`); an episode shorter than :data:`EPISODE_TIME_FACTOR` times
  the slowest motion is lengthened.

An explicit ``home_qpos`` (the task config's or the arm file's) and the shipped arms' measured
homes are kept as they are, with the reach scale; the area is still checked from them.
:func:`mjx_arm.arm.verdict.task_verdict` says whether an arm can do a task and why not.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from mjx_arm.arm.ik import ToolDownSolver
from mjx_arm.arm.info import HOME_HEIGHT, ArmInfo, tool_down_solver
from mjx_arm.arm.points import task_arm
from mjx_arm.task import sampling
from mjx_arm.task.config import TaskConfig
from mjx_arm.task.lift import GRASP_SLACK
from mjx_arm.urdf.grippers import held_cube_half
from mjx_arm.urdf.scene_shapes import CUBE_HALF, box_half_width, box_top_offset

# Fractions of the reach scale tried, nearest 1 first: smaller areas for arms that cannot hold
# the tool down far out, larger ones for arms that cannot reach down near their base (or, as
# the SO-101 with its 10 cm jaw, up near it: its Reach area covers at 1.3).
SCALE_STEPS = (1.0, 0.9, 1.1, 0.8, 1.2, 0.7, 1.3, 0.6, 1.4, 0.5)
# m: the home heights tried, highest first; an arm of a reach scale below 1 then tries them
# times its reach scale, where that is lower (the SO-101, reach scale 0.38, holds its tool down
# only up to about 8 cm)
HOME_HEIGHTS = (HOME_HEIGHT, 0.15, 0.10)
# m: room above Touch's box top that a home leaves for slowing down before the press; a home
# nearer the box is raised as far as a tool-down pose allows, to RAISE_TOLERANCE
PRESS_CLEARANCE, RAISE_TOLERANCE = 0.03, 0.002
MIN_OBJECT_SCALE = 0.5  # a gripper that holds only a cube smaller than this fraction cannot Lift
EPISODE_TIME_FACTOR = 2.0  # an episode lasts at least this many times the slowest motion


@dataclass(frozen=True)
class ArmSetup:
    """What a task needs of an arm, and how it was found.

    Attributes:
        home_qpos: home joint angles (rad), ``(n,)``.
        home_source: "task config", "arm file", "shipped arm" or "derived".
        workspace_scale: the task box's scale (1.0 for the shipped arm).
        reach_scale: the arm's reach scale, where the search started.
        tool_axis: the tool axis in the ee frame, ``(3,)``.
        reached: grid targets reachable tool-down from home, of ``targets``.
        targets: the grid targets tried.
        travel_time: the slowest home-to-target motion at the task's speeds (s).
        episode_steps: the episode's control steps for this arm (the task's, or longer).
        manipulability: of the home pose (m^3).
        tool_reach: how far the tool's collision shapes stick out past the ee point along the
            tool axis (m), anywhere.
        contact_offset: how far past the ee point the tool meets the Touch box's top face
            pressed square against it (m; negative: behind it; None: no shape on the axis).
        contact_spread: how much that changes as the box turns about the tool axis (m):
            shapes beside the axis that straddle the box at one turn and land on it at another.
        object_scale: a gripper task's cube over the shipped one (:func:`object_scale`).
        grasp_closure: how closed a gripper task's gripper must be to hold its cube
            (:func:`grasp_closure`; 0: no gripper task).
        notes: what the derivation had to do or could not do, one line each.
    """

    home_qpos: tuple[float, ...]
    home_source: str
    workspace_scale: float
    reach_scale: float
    tool_axis: tuple[float, float, float]
    reached: int
    targets: int
    travel_time: float
    episode_steps: int
    manipulability: float
    tool_reach: float = 0.0
    contact_offset: float | None = 0.0
    contact_spread: float = 0.0
    object_scale: float = 1.0
    grasp_closure: float = 0.0
    notes: tuple[str, ...] = field(default=())

    def fill(self, task: TaskConfig) -> TaskConfig:
        """``task`` with what this setup derived where it leaves it empty
        (:meth:`~mjx_arm.task.config.TaskConfig.for_arm`)."""
        return task.for_arm(
            self.home_qpos,
            self.workspace_scale,
            self.episode_steps,
            self.object_scale,
            self.grasp_closure,
        )

    @property
    def covers_area(self) -> bool:
        """Every grid target is reachable with the tool down."""
        return self.reached == self.targets


def grid_targets(task: TaskConfig) -> np.ndarray:
    """The target points (m) of a 3 x 3 x 3 grid of draws over the task's box, as the task
    places them (repeated points dropped), ``(m, 3)``."""
    axis = np.array([0.0, 0.5, 1.0])
    u3 = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    body = sampling.target_body_pos(np, u3, task)
    points = sampling.target_point(np, body, task)
    return np.unique(np.round(points, 6), axis=0)


def arm_setup(arm: ArmInfo, task: TaskConfig) -> ArmSetup:
    """The setup of ``task`` on ``arm`` with the task's ee point
    (:func:`~mjx_arm.arm.points.task_arm`) and cube (:func:`object_scale`), cached per arm and
    task config; see the module."""
    arm = task_arm(arm, task)
    task = task.replace(object_scale=object_scale(arm, task))
    return _setup_cached(arm, task.replace(grasp_closure=grasp_closure(arm, task)))


def object_scale(arm: ArmInfo, task: TaskConfig) -> float:
    """``task``'s ``object_scale`` where it sets one, else the arm's: a gripper task's cube
    shrinks to what the arm's gripper holds (:attr:`~mjx_arm.arm.gripper.Gripper.cube_half`:
    it opens :data:`~mjx_arm.urdf.grippers.CUBE_CLEARANCE` wider, and a jaw holds it square;
    1.0 where the shipped cube fits, and for the other tasks), never below
    :data:`MIN_OBJECT_SCALE`."""
    if task.object_scale or not task.spec.gripper or arm.gripper is None:
        return task.object_scale or 1.0
    half = arm.gripper.cube_half or held_cube_half(arm.gripper.opening)
    return float(np.clip(half / CUBE_HALF, MIN_OBJECT_SCALE, 1.0))


def grasp_closure(arm: ArmInfo, task: TaskConfig) -> float:
    """``task``'s ``grasp_closure`` where it sets one, else the closure (0 open, 1 closed) at
    which ``arm``'s pads stand :data:`~mjx_arm.task.lift.GRASP_SLACK` wider apart than the
    task's cube (:attr:`~mjx_arm.arm.gripper.Gripper.closure_gaps`, at ``task``'s
    ``object_scale``); 0 for the other tasks and where the table says nothing."""
    if task.grasp_closure or not task.spec.gripper or arm.gripper is None:
        return task.grasp_closure
    table = arm.gripper.closure_gaps
    if not table:
        return 0.0
    closures, gaps = (np.asarray(column) for column in zip(*table, strict=True))
    wide = 2.0 * CUBE_HALF * (task.object_scale or 1.0) + GRASP_SLACK
    return round(float(np.interp(wide, gaps[::-1], closures[::-1])), 4)


@functools.cache
def _setup_cached(arm: ArmInfo, task: TaskConfig) -> ArmSetup:
    solver = tool_down_solver(arm)
    home, source = given_home(arm, task)
    scales = [task.workspace_scale] if task.workspace_scale else _scales(arm, home)
    best: tuple | None = None
    for scale in scales:
        trial = _try_scale(arm, solver, task.replace(workspace_scale=scale), home)
        if trial is None:
            continue
        if best is None or trial[0] > best[0]:
            best = trial
        if trial[0] == trial[1]:  # every target reached
            break
    if best is None:
        return _unreachable(arm, task, solver, scales[-1], home, source)
    reached, targets, q_home, poses, scale = best
    return _finish(arm, task, solver, q_home, source, scale, reached, targets, poses)


def _scales(arm: ArmInfo, home: np.ndarray | None) -> list[float]:
    """The workspace scales to try: the reach scale alone where the home is given (the arm
    file's or the shipped arm's choice stands), else shrinking fractions of it."""
    if home is not None:
        return [arm.reach_scale]
    return [arm.reach_scale * f for f in SCALE_STEPS]


def given_home(arm: ArmInfo, task: TaskConfig) -> tuple[np.ndarray | None, str]:
    """The home pose given for ``task`` on ``arm`` and where it comes from: the task config's,
    the arm file's, the shipped arm's measured one, or (None, "derived")."""
    if task.home_qpos:
        return np.asarray(task.home_qpos, float), "task config"
    if arm.config.home_qpos:
        return np.asarray(arm.config.home_qpos, float), "arm file"
    shipped = shipped_home(arm, task)
    if shipped is not None:
        return np.asarray(shipped, float), "shipped arm"
    return None, "derived"


def shipped_home(arm: ArmInfo, task: TaskConfig) -> tuple[float, ...] | None:
    """The measured home of a shipped arm (Lift's for the gripper tasks), else None."""
    from mjx_arm.arm.config import SHIPPED_HOME_QPOS, is_shipped
    from mjx_arm.task.lift import LIFT_HOME

    if not is_shipped(arm.config):
        return None
    return LIFT_HOME if task.spec.gripper else SHIPPED_HOME_QPOS


def _try_scale(arm: ArmInfo, solver: ToolDownSolver, task: TaskConfig, home: np.ndarray | None):
    """(reached, targets, home, poses, scale) of the best home at ``task``'s scale, or None
    where no tool-down home exists over the area's middle.

    At each height the home that reaches the most grid targets wins (the best-conditioned
    among equals); a lower height's home replaces a higher one's only where it reaches more
    targets, or as many with its slowest motion inside the task's episode
    (:func:`_fits_episode`) where the higher one's is not.
    """
    points = grid_targets(task)
    low, high = points[:, :2].min(axis=0), points[:, :2].max(axis=0)
    centre = 0.5 * (low + high)
    floor = _press_floor(task)
    groups = [[home]] if home is not None else _home_groups(solver, centre, arm.reach_scale, floor)
    best, best_rank = None, None
    for homes in groups:
        trial = _best_home(solver, task, points, homes)
        rank = (trial[0], _fits_episode(task, _travel_time(arm, task, trial[2], trial[3])))
        if best_rank is None or rank > best_rank:
            best, best_rank = trial, rank
        if best_rank == (len(points), True):
            break  # a home at this height reaches every target within the episode
    return best


def _best_home(solver: ToolDownSolver, task: TaskConfig, points: np.ndarray, homes: list):
    """(reached, targets, home, poses, scale) of the first of ``homes`` that reaches the most
    of ``points (m, 3)``."""
    best = None
    for q_home in homes:
        poses = solver.reach_from(q_home, points, tool_down=task.uses_contact)
        reached = sum(p is not None for p in poses)
        if best is None or reached > best[0]:
            best = (reached, len(points), q_home, poses, task.workspace_scale)
    return best


def _press_floor(task: TaskConfig) -> float:
    """The lowest home height (m) that leaves :data:`PRESS_CLEARANCE` above the task's box
    top; 0.0 for a task without the box."""
    return box_top_offset() + PRESS_CLEARANCE if task.spec.scene.box else 0.0


def _home_groups(
    solver: ToolDownSolver, centre: np.ndarray, reach_scale: float, floor: float = 0.0
) -> Iterator[list[np.ndarray]]:
    """Tool-down homes over ``centre (2,)`` (x, y) at each of :func:`home_heights` that has
    any, highest first (a small arm, or a long tool, may not hold the tool down higher up);
    each height is solved only when asked for. A height below ``floor`` (m) whose next height
    up has no home is first raised as high as a tool-down home allows (:func:`_raised`)."""
    above = None  # the last height tried, which had no home
    for height in home_heights(reach_scale):
        homes = solver.homes(np.array([*centre, height]))
        if homes and above is not None and height < floor:
            raised = _raised(solver, centre, height, min(above, floor))
            if raised:
                yield raised
        if homes:
            yield homes
        above = None if homes else height


def _raised(
    solver: ToolDownSolver, centre: np.ndarray, low: float, high: float
) -> list[np.ndarray]:
    """Tool-down homes over ``centre (2,)`` at the highest height found between ``low`` (m,
    which has homes) and ``high`` (bisection to :data:`RAISE_TOLERANCE`); [] where none is
    above ``low`` by that much."""
    best: list[np.ndarray] = []
    while high - low > RAISE_TOLERANCE:
        middle = 0.5 * (low + high)
        homes = solver.homes(np.array([*centre, middle]))
        if homes:
            low, best = middle, homes
        else:
            high = middle
    return best


def home_heights(reach_scale: float) -> tuple[float, ...]:
    """The home heights (m) an arm of ``reach_scale`` tries, highest first:
    :data:`HOME_HEIGHTS`, then (a reach scale below 1) those times the reach scale that are
    lower than the lowest of them."""
    scaled = [h * reach_scale for h in HOME_HEIGHTS if h * reach_scale < min(HOME_HEIGHTS)]
    return HOME_HEIGHTS + tuple(scaled)


def _travel_time(arm: ArmInfo, task: TaskConfig, q_home: np.ndarray, poses: list) -> float:
    """The slowest home-to-target motion (s) at the task's joint speeds: the largest
    ``|q - q_home| / speed`` over the reached poses and the joints (0.0 where none)."""
    speeds = task.joint_speeds(arm.v_max)
    moves = [np.abs(p - q_home) / speeds for p in poses if p is not None]
    return float(max(m.max() for m in moves)) if moves else 0.0


def _fits_episode(task: TaskConfig, travel: float) -> bool:
    """Whether an episode of the task's length lasts :data:`EPISODE_TIME_FACTOR` times a
    motion of ``travel`` seconds."""
    return math.ceil(EPISODE_TIME_FACTOR * travel / task.ctrl_dt) <= task.episode_steps


def _finish(arm, task, solver, q_home, source, scale, reached, targets, poses) -> ArmSetup:
    """The setup from the chosen home and scale: travel time, episode length and notes."""
    travel = _travel_time(arm, task, q_home, poses)
    needed = math.ceil(EPISODE_TIME_FACTOR * travel / task.ctrl_dt)
    steps = max(task.episode_steps, needed)
    notes = _notes(arm, task, solver, q_home, scale)
    if reached < targets:
        notes.append(f"{targets - reached} of {targets} grid targets not reachable tool-down")
    if steps > task.episode_steps:
        notes.append(
            f"episode lengthened to {steps} steps ({steps * task.ctrl_dt:.1f} s): the slowest "
            f"move from home takes {travel:.1f} s at the commanded speeds"
        )
    return ArmSetup(
        home_qpos=tuple(float(q) for q in q_home),
        home_source=source,
        workspace_scale=float(scale),
        reach_scale=arm.reach_scale,
        tool_axis=tuple(float(v) for v in solver.ik.tool),
        reached=reached,
        targets=targets,
        travel_time=travel,
        episode_steps=steps,
        manipulability=solver.ik.manipulability(q_home),
        tool_reach=solver.tool_reach(q_home),
        **_contact(solver, q_home),
        object_scale=task.object_scale,
        grasp_closure=task.grasp_closure,
        notes=tuple(notes),
    )


def _notes(arm, task, solver, q_home, scale) -> list[str]:
    """What scaling the derivation did: the task area, the home height, the cube."""
    notes = []
    if abs(scale - arm.reach_scale) > 1e-9:
        change = "shrunk" if scale < arm.reach_scale else "grown"
        notes.append(
            f"task area {change} to {scale / arm.reach_scale:.0%} of the reach scale: at the "
            "reach scale some targets are not reachable from home"
        )
    height = float(solver.ik.pose(np.asarray(q_home, float))[0][2])
    if height < min(HOME_HEIGHTS) - 0.01:
        notes.append(
            f"home {height:.2f} m above the table: none holds the tool down at "
            f"{min(HOME_HEIGHTS):.2f} m or higher (heights tried times the reach scale)"
        )
    elif height < HOME_HEIGHT - 0.01:
        notes.append(f"home {height:.2f} m above the table: none holds the tool down higher")
    floor = _press_floor(task)
    if height < floor - 0.001:
        room = height - box_top_offset()
        notes.append(
            f"home {room * 100:.1f} cm above the box, less than the "
            f"{PRESS_CLEARANCE * 100:.0f} cm wanted to slow down before the press (a derived "
            "home is raised as far as a tool-down pose allows)"
        )
    if task.spec.gripper and task.object_scale < 1.0:
        from mjx_arm.task.lift import cube_half

        notes.append(
            f"cube of {200 * cube_half(task):.1f} cm (x{task.object_scale:.2f}, mass "
            f"x{task.object_scale:.2f}): what the gripper holds (it opens "
            f"{arm.gripper.opening * 100:.1f} cm)"
        )
    return notes


def _unreachable(arm, task, solver, scale, home, source) -> ArmSetup:
    """The setup of an arm with no tool-down pose over the task area: the given home, else
    the middle of the limits, and a note that says so."""
    q = home if home is not None else solver.middle
    targets = len(grid_targets(task.replace(workspace_scale=scale)))
    return ArmSetup(
        home_qpos=tuple(float(v) for v in q),
        home_source=source if home is not None else "middle of the limits",
        workspace_scale=float(scale),
        reach_scale=arm.reach_scale,
        tool_axis=tuple(float(v) for v in solver.ik.tool),
        reached=0,
        targets=targets,
        travel_time=0.0,
        episode_steps=task.episode_steps,
        manipulability=solver.ik.manipulability(q),
        tool_reach=solver.tool_reach(q),
        **_contact(solver, q),
        notes=("no tool-down pose over the task area: the arm cannot reach it tool-down",),
    )


def _contact(solver, q: np.ndarray) -> dict[str, float | None]:
    """The ``contact_offset`` and ``contact_spread`` of an :class:`ArmSetup` at ``q (n,)``."""
    offset, spread = solver.tool_contact(q, box_half_width())
    return {"contact_offset": offset, "contact_spread": spread}
