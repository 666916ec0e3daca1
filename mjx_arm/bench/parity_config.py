"""Settings of the parity run and the constants they check against.

Kept apart from :mod:`mjx_arm.bench.parity` so that the command line can be built without
importing MuJoCo (which fails on a bad ``MUJOCO_GL``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from mjx_arm.bench.settings import setting
from mjx_arm.engines import engine, engine_names
from mjx_arm.envs.physics_config import IMPLS
from mjx_arm.inputs import MAX_SEED
from mjx_arm.settings import check_range

# The engines with parity hooks, in registry order (mujoco, mjx, pybullet).
ENGINES = engine_names("parity")

# Bottom-face centres (m) of the box in the pressing check, the first ``press_boxes`` are used.
BOX_POSITIONS = (
    (0.5, 0.05, 0.0),
    (0.4, -0.2, 0.0),
    (0.6, 0.2, 0.0),
    (0.45, 0.1, 0.0),
    (0.55, -0.1, 0.0),
    (0.4, 0.2, 0.0),
    (0.6, -0.2, 0.0),
    (0.5, 0.0, 0.0),
)
PRESS_GAIN = 2.0  # 1/s: the recording controller's ee velocity per metre of error
CONTACT_N = 1.0  # a tared force above this (N) in free motion means the arm touched something
FREE_SCENARIOS = ("hold", "constant")  # jitter runs in free space (the Reach scene)
JITTER_SCENARIOS = (*FREE_SCENARIOS, "press")
DAMPING = {"converted": 1.0, "zeroed": 0.0}


@dataclass(frozen=True)
class ParityConfig:
    """Settings of the parity run. Saved in the result JSON; the CLI flags come from here."""

    engines: tuple[str, ...] = setting(ENGINES, "engines to compare", ENGINES)
    impls: tuple[str, ...] = setting(("auto",), "MJX implementations (one MJX run each)", IMPLS)
    fk_poses: int = setting(100, "random joint configurations for forward kinematics")
    sequences: int = setting(128, "open-loop action sequences")
    seconds: float = setting(2.0, "length of each open-loop and jitter run (s)")
    hold_steps: int = setting(5, "control steps each random action level is held")
    amplitude: float = setting(0.5, "largest |action| of the open-loop sequences")
    press_boxes: int = setting(8, "box positions in the pressing check (at most 8)")
    press_seconds: float = setting(3.0, "length of each press (s); contact starts near 1.6 s")
    press_depth: float = setting(0.01, "how far below the box top the ee is driven (m)")
    press_average_steps: int = setting(10, "control steps averaged for the steady press force")
    jitter_window: float = setting(0.75, "end of each run the jitter figures use (s)")
    jitter_command: tuple[float, ...] = setting(
        (0.3, 0.0, 0.0, 0.3, 0.3, 0.3),
        "the constant action of the jitter check, one per joint (repeated or cut to fit an "
        "arm of another joint count)",
    )
    arm: str = setting("", "the arm: a URDF or an arm file (.toml/.json); '' is the shipped arm")
    goal_time: float = setting(1.0, "time (s) at which divergence goals are checked")
    goal_fk_m: float = setting(1e-6, "goal: largest FK difference of any pair (m)")
    goal_mjx_rad: float = setting(1e-2, "goal: median MJX vs C MuJoCo joint divergence (rad)")
    goal_pybullet_rad: float = setting(
        5e-2, "goal: median joint divergence of a pair with PyBullet (rad)"
    )
    seed: int = setting(0, "seed of the random poses and actions")

    def __post_init__(self) -> None:
        check_range(self, ("fk_poses", "sequences", "hold_steps", "press_average_steps"), low=1)
        check_range(self, ("fk_poses", "sequences"), high=100_000)
        check_range(self, ("seconds", "press_seconds", "jitter_window"), above=0, high=600)
        check_range(self, ("amplitude",), above=0, high=1)
        check_range(self, ("press_depth", "goal_fk_m", "goal_mjx_rad", "goal_pybullet_rad"), low=0)
        check_range(self, "seed", low=0, high=MAX_SEED)
        unknown = set(self.engines) - set(ENGINES)
        if unknown or not self.engines:
            raise ValueError(f"engines must be some of {ENGINES}, got {self.engines}")
        chosen = sum(engine(name).impl_choice for name in self.engines)  # one run per impl
        runs = len(self.engines) + chosen * (len(self.impls) - 1)
        if runs < 2:
            raise ValueError("parity needs two engines (or MJX with two impls) to compare")
        if not 0 < self.goal_time <= self.seconds:
            raise ValueError("goal_time must lie in (0, seconds]")
        if not 1 <= self.press_boxes <= len(BOX_POSITIONS):
            raise ValueError(f"press_boxes must be 1..{len(BOX_POSITIONS)}")
        if not self.jitter_command:
            raise ValueError("jitter_command needs at least one action")

    @classmethod
    def quick(cls, **changes: Any) -> ParityConfig:
        """A small run for tests: few poses, sequences and boxes, short runs."""
        small = {"fk_poses": 8, "sequences": 8, "seconds": 1.0, "press_boxes": 2}
        return cls(**{**small, "press_seconds": 2.0, "jitter_window": 0.3, **changes})

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return dataclasses.asdict(self)
