"""The robustness benchmark's settings (:mod:`mjx_arm.bench.robustness`): its perturbations,
each with its stated range and where that range comes from, the sweep points and the goals.

Where the ranges come from (the ``source`` of each :class:`Perturbation`):

- UR5e data sheet (Universal Robots, "UR5e technical specifications"): rated payload 5 kg,
  pose repeatability +-0.03 mm (ISO 9283), joint speeds 180 deg/s, built-in F/T sensor force
  precision 3.5 N and accuracy 4.0 N. Repeatability is far below anything a policy notices;
  the zero offsets of an arm whose kinematics were never calibrated are not (joint bias
  below).
- Isaac Lab's UR10e reach sim-to-real recipe: actuator stiffness x0.9-1.1 and damping x0.75-1.5
  (our velocity servo's gain acts as the damping of a PD servo on velocity), joint friction
  0-0.1 N m, initial joints +-0.125 rad, at 60 Hz.
- mjlab's domain randomisation (mujocolab.github.io/mjlab, "Domain Randomization"): geom
  friction, body mass and inertia, geom size, joint parameters, PD gains, encoder bias,
  actuator delay and observation noise, drawn per environment at reset.
- What system identification of a velocity-servoed arm typically misses: viscous joint damping
  (a factor of 2 either way), the control loop's timing (a real RTDE loop at 30 Hz jitters by a
  few ms and delays commands by 1-3 periods under load), the table's height measured by hand
  (+-2 cm) and an object pose from a camera (+-1-2 cm).

Each perturbation has a ``stated`` range (the goal: success >= 0.9 at every point in it) and
may sweep a little beyond it (marked in the report) to show where the policy breaks.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from mjx_arm.bench.settings import setting
from mjx_arm.envs.physics_config import NOMINAL, RandomizationConfig
from mjx_arm.settings import check_range

ENGINES = ("mujoco-batch", "mjx")
GOAL_POINT = 0.9  # success at every point of each stated range
GOAL_JOINT = 0.85  # success under the joint draw
JOINT = "joint draw"


@dataclass(frozen=True)
class Perturbation:
    """One perturbation and its sweep.

    Attributes:
        name: identifier (JSON key, plot label).
        field: the :class:`RandomizationConfig` field it sets.
        kind: how a value becomes the field: "range" (``(v, v)``), "scalar" (``v``) or
            "latency" (``latency_prob = 1`` and ``latency_steps = (v, v)``; 0 is no delay).
        unit: unit of the values.
        values: the sweep points (the nominal value among them).
        stated: the range the goals apply to, ``(low, high)``.
        source: where the stated range comes from.
        gripper_only: only for a gripper task (the cube).
    """

    name: str
    field: str
    kind: str
    unit: str
    values: tuple[float, ...]
    stated: tuple[float, float]
    source: str
    gripper_only: bool = False

    def config(self, value: float, base: RandomizationConfig = NOMINAL) -> RandomizationConfig:
        """``base`` with this perturbation fixed at ``value``."""
        if self.kind == "latency":
            k = round(value)
            return (
                base.replace(latency_prob=0.0)
                if k == 0
                else base.replace(latency_prob=1.0, latency_steps=(k, k))
            )
        if self.kind == "range":
            return base.replace(**{self.field: (float(value), float(value))})
        return base.replace(**{self.field: float(value)})

    def joint_changes(self) -> dict[str, Any]:
        """This perturbation's part of the joint draw: uniform over its stated range."""
        low, high = self.stated
        if self.kind == "latency":
            return {"latency_prob": 1.0, "latency_steps": (int(low), int(high))}
        if self.kind == "range":
            return {self.field: (float(low), float(high))}
        return {self.field: float(high)}  # a noise scale or half-width: its largest value

    def inside(self, value: float) -> bool:
        """Whether ``value`` lies in the stated range."""
        return self.stated[0] - 1e-12 <= value <= self.stated[1] + 1e-12


ISAAC = "Isaac Lab UR10e reach recipe"
SYSID = "what system identification typically misses"
DATASHEET = "UR5e data sheet"

SYMMETRIC_2CM = (-0.02, -0.01, -0.005, 0.0, 0.005, 0.01, 0.02)  # m, or rad of joint bias
FT_BIAS_VALUES = (-6.0, -4.0, -2.0, -1.0, 0.0, 1.0, 2.0, 4.0, 6.0)  # N

PERTURBATIONS: tuple[Perturbation, ...] = (
    Perturbation("servo_gain", "gain", "range", "x", (0.6, 0.75, 1.0, 1.25, 1.5), (0.75, 1.5),
                 f"{ISAAC}: damping x0.75-1.5, stiffness x0.9-1.1"),
    Perturbation("joint_damping", "damping", "range", "x", (0.5, 1.0, 1.5, 2.0, 3.0), (0.5, 2.0),
                 f"{SYSID}: viscous damping within a factor of 2"),
    Perturbation("joint_friction", "frictionloss", "range", "N m", (0.0, 0.05, 0.1, 0.5, 1.0),
                 (0.0, 0.1), f"{ISAAC}: joint friction 0-0.1 N m"),
    Perturbation("payload", "payload", "range", "kg", (0.0, 0.5, 1.0, 2.5, 5.0), (0.0, 5.0),
                 f"{DATASHEET}: rated payload 5 kg"),
    Perturbation("cube_mass", "cube_mass", "range", "x", (0.5, 1.0, 1.5, 2.0, 3.0), (0.5, 2.0),
                 "mjlab: object mass; a cube of 25-400 g against the task's 50-200 g",
                 gripper_only=True),
    Perturbation("cube_friction", "cube_friction", "range", "x", (0.5, 0.7, 0.85, 1.0, 1.2),
                 (0.7, 1.2), "mjlab: geom friction; a real cube's friction is known to +-30 %",
                 gripper_only=True),
    Perturbation("latency", "latency_steps", "latency", "steps", (0, 1, 2, 3), (0, 3),
                 f"mjlab: actuator delay; {SYSID}: 0-3 control periods (0-100 ms at 30 Hz)"),
    Perturbation("joint_noise", "joint_noise", "scalar", "rad", (0.0, 0.001, 0.005, 0.01),
                 (0.0, 0.005), "mjlab: observation noise; encoders are far finer than this"),
    Perturbation("joint_bias", "joint_bias", "range", "rad", SYMMETRIC_2CM,
                 (-0.01, 0.01), f"mjlab: encoder bias; {SYSID}: an uncalibrated arm's zero"),
    Perturbation("ft_noise", "ft_force_noise", "scalar", "N", (0.0, 1.0, 2.0, 3.5, 5.0), (0.0, 3.5),
                 f"{DATASHEET}: F/T force precision 3.5 N"),
    Perturbation("ft_bias", "ft_force_bias", "range", "N", FT_BIAS_VALUES,
                 (-4.0, 4.0), f"{DATASHEET}: F/T force accuracy 4.0 N"),
    Perturbation("ctrl_jitter", "ctrl_jitter", "scalar", "fraction", (0.0, 0.05, 0.1, 0.2),
                 (0.0, 0.1), f"{SYSID}: +-3 ms on a 33 ms period"),
    Perturbation("table_height", "table_height", "range", "m", SYMMETRIC_2CM,
                 (-0.02, 0.02), f"{SYSID}: a table measured by hand"),
    Perturbation("pose_error", "box_offset", "scalar", "m", (0.0, 0.005, 0.01, 0.02),
                 (0.0, 0.01), f"{SYSID}: an object pose from a camera (uniform in +-value, x/y)"),
)  # fmt: skip


def perturbations_for(gripper: bool) -> tuple[Perturbation, ...]:
    """The perturbations of a task with (or without) a gripper."""
    return tuple(p for p in PERTURBATIONS if gripper or not p.gripper_only)


def joint_config(perturbations: tuple[Perturbation, ...]) -> RandomizationConfig:
    """Every perturbation drawn at once, uniform over its stated range (the joint draw,
    :data:`ROBUST`)."""
    changes: dict[str, Any] = {}
    for p in perturbations:
        changes.update(p.joint_changes())
    return NOMINAL.replace(**changes)


@dataclass(frozen=True)
class RobustnessConfig:
    """Settings of ``mjx-arm bench robustness`` (each field is a flag)."""

    engine: str = setting("mujoco-batch", "batched engine: C MuJoCo (CPU) or MJX (GPU)", ENGINES)
    episodes: int = setting(64, "episodes per sweep point")
    joint_episodes: int = setting(0, "episodes of the joint draw (0: 4x --episodes)")
    seed: int = setting(0, "seed of the batch's PRNG key")
    impl: str = setting("auto", "MJX implementation (mjx engine)", ("auto", "jax", "warp"))
    max_batch: int = setting(4096, "envs stepped at once (points are split into chunks)")

    def __post_init__(self) -> None:
        check_range(self, ("episodes", "max_batch"), low=1, high=2**16)
        check_range(self, "joint_episodes", low=0, high=2**16)
        check_range(self, "seed", low=0, high=2**31 - 1)

    @staticmethod
    def quick() -> RobustnessConfig:
        """A small run: 8 episodes per point."""
        return RobustnessConfig(episodes=8, joint_episodes=16)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class Point:
    """One sweep point: a perturbation (or the joint draw) at a value, and its config."""

    perturbation: str
    value: float | None
    config: RandomizationConfig
    inside: bool


def sweep_points(perturbations: tuple[Perturbation, ...]) -> list[Point]:
    """Every perturbation at each of its values, then the joint draw."""
    points = [
        Point(p.name, float(v), p.config(v), p.inside(v)) for p in perturbations for v in p.values
    ]
    return [*points, Point(JOINT, None, joint_config(perturbations), True)]
