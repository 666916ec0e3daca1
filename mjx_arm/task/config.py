"""Typed configuration of a task: timing, action scaling, sampling, reward weights, success.

One :class:`TaskConfig` drives every engine (CPU MuJoCo, PyBullet, MJX), so the numbers below are
the contract. Presets: :func:`reach_config` and :func:`touch_config`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from mjx_arm.names import TASKS

# The arm's home pose: tool pointing down, about 0.37 m above the table, in front of the base.
HOME_QPOS = (0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0)


@dataclass(frozen=True)
class RewardConfig:
    """Weights of the named reward terms; the reward is ``sum(weight * term)``.

    The seed preset is ``-10*(1-exp(-d/0.1)) + 500*contact - 5*(#joints beyond limits)
    - 0.1*sum(|qdot|)``. Terms (see :mod:`mjx_arm.task.reward`):
    ``distance`` = 1 - exp(-d / distance_length), ``contact`` = 1 when the tool presses the target
    inside the force band, ``joint_limit`` = number of joints beyond ``soft_limit`` of their range,
    ``joint_velocity`` = sum |qdot| (rad/s), ``success`` = 1 on the success step,
    ``nonfinite`` = 1 when the physics diverged (a NaN or infinite state, or a runaway joint
    speed: see ``TaskConfig.divergence_speed_factor``),
    ``force_excess`` = (F - F_max) / F_max where the contact force F is above the band, else 0,
    ``approach_speed`` = (how fast d shrinks)^2 (m^2/s^2) while d < ``approach_radius``,
    ``action_rate`` = sum (a_t - a_{t-1})^2 over the six action entries,
    ``overforce`` = 1 on a step whose contact force is above the band,
    ``proximity`` = exp(-d / proximity_length): 1 at the target, 0.37 one length away (a
    near-field pull that ``distance``'s longer length scale lacks),
    ``streak`` = how far a press inside the band has held on: 0 on a one-step tap, 1 once it
    has held ``success_hold_steps`` steps running (:func:`mjx_arm.task.reward.streak`).
    """

    distance: float = -10.0
    contact: float = 500.0
    joint_limit: float = -5.0
    joint_velocity: float = -0.1
    success: float = 0.0
    nonfinite: float = -100.0
    force_excess: float = 0.0
    approach_speed: float = 0.0
    action_rate: float = 0.0
    overforce: float = 0.0
    proximity: float = 0.0
    streak: float = 0.0
    distance_length: float = 0.1
    proximity_length: float = 0.01
    soft_limit: float = 0.95
    approach_radius: float = 0.1

    def weights(self) -> dict[str, float]:
        """Weight of each named term."""
        return {name: getattr(self, name) for name in REWARD_TERMS}


REWARD_TERMS = (
    "distance",
    "contact",
    "joint_limit",
    "joint_velocity",
    "success",
    "nonfinite",
    "force_excess",
    "approach_speed",
    "action_rate",
    "overforce",
    "proximity",
    "streak",
)

# Touch's default reward ("gentle"): gentle contact is the optimum.
# - The seed's distance charge guides the tool from afar; ``proximity`` (length 1 cm) pays up to
#   +10 a step in the last centimetres, so resting the tip on the box beats hovering above it.
#   With the velocity servo the steady force grows with the commanded speed into the box, so
#   from a resting tip the band (1-50 N) is a small push away.
# - Success (a 3-step hold in the band, no reading over it) pays 1000: more than resting at the
#   target for the rest of the episode (10 / (1 - 0.97) = 333 at the fast and cpu presets'
#   discount), and more than tapping the box for the in-band contact pay (20 a step).
# - A reading over the band costs its excess (graded, so the policy learns how hard it pressed)
#   and rules success out; a strike over 100 N also ends the episode. Closing in fast near the
#   box and jerky actions cost a little.
GENTLE_REWARD = RewardConfig(
    streak=50.0,
    proximity=10.0,
    contact=20.0,
    success=1000.0,
    force_excess=-100.0,
    approach_speed=-10.0,
    action_rate=-0.05,
    overforce=-20.0,
)


@dataclass(frozen=True)
class TaskConfig:
    """Everything that defines a task, identical in every engine.

    Attributes:
        task: "reach" (point target, no contact) or "touch" (press the 5 cm box).
        ctrl_dt: control period (s); one action and one observation per period.
        sim_dt: physics step (s); ``ctrl_dt / sim_dt`` substeps per control step.
        action_scale: joint velocity target = action * action_scale * v_max (URDF velocity).
        episode_steps: control steps before truncation (150 = 5 s).
        terminate_on_success: end the episode on the first success step.
        home_qpos: joint angles (rad) episodes start around.
        init_noise: half-width (rad) of the uniform noise added to ``home_qpos`` at reset.
        target_low, target_high: box (m, base frame) the target is drawn from uniformly. For
            touch only x and y are used: the box stands on the table at z = 0.
        success_distance: d (m) below which the ee point counts as at the target.
        force_band: (min, max) contact force norm (N) of a successful touch.
        success_hold_steps: consecutive control steps the success condition must hold (near the
            target, and for Touch the force inside the band) before the episode succeeds.
        fail_on_overforce: a force reading above the band at any step of the episode rules out
            success for the rest of it.
        terminate_on_overforce: end the episode at the first reading above ``strike_force``
            (a protective stop).
        strike_force: contact force norm (N) that ends the episode when
            ``terminate_on_overforce``; 0 takes the top of ``force_band``. Any reading above the
            band still rules success out when ``fail_on_overforce``.
        variant: "seed" (the seed document's task) or "gentle" (Touch's default: hold, no strike).
        force_clip: bound (N and N m) of each contact_force component.
        divergence_speed_factor: the physics has diverged when a joint turns faster than this
            multiple of its URDF velocity limit (or any value is NaN or infinite). The velocity
            servos keep the joints near their limits, so a joint ten times faster means the
            integration ran away: the episode ends with ``info["diverged"]`` and the
            ``nonfinite`` reward term (PyBullet caps joint speeds at 100 rad/s, so its runaway
            shows as speed, not as NaN).
        reward: weights of the reward terms.
    """

    task: str = "touch"
    ctrl_dt: float = 1.0 / 30.0
    sim_dt: float = 1.0 / 240.0
    action_scale: float = 0.5
    episode_steps: int = 150
    terminate_on_success: bool = True
    home_qpos: tuple[float, ...] = HOME_QPOS
    init_noise: float = 0.05
    target_low: tuple[float, float, float] = (0.35, -0.25, 0.05)
    target_high: tuple[float, float, float] = (0.65, 0.25, 0.45)
    success_distance: float = 0.05
    force_band: tuple[float, float] = (1.0, 50.0)
    success_hold_steps: int = 1
    fail_on_overforce: bool = False
    terminate_on_overforce: bool = False
    strike_force: float = 0.0
    variant: str = "seed"
    force_clip: float = 100.0
    divergence_speed_factor: float = 10.0
    reward: RewardConfig = field(default_factory=RewardConfig)

    def __post_init__(self) -> None:
        if self.task not in TASKS:
            raise ValueError(f"task must be one of {TASKS}, got {self.task!r}")
        ratio = self.ctrl_dt / self.sim_dt
        if abs(ratio - round(ratio)) > 1e-6 or round(ratio) < 1:
            raise ValueError(
                f"ctrl_dt {self.ctrl_dt} is not a whole multiple of sim_dt {self.sim_dt}"
            )
        if len(self.home_qpos) != 6:
            raise ValueError("home_qpos needs 6 joint angles")
        if self.success_hold_steps < 1:
            raise ValueError("success_hold_steps must be >= 1")
        if not self.divergence_speed_factor > 1:
            raise ValueError("divergence_speed_factor must be > 1")

    @property
    def n_substeps(self) -> int:
        """Physics steps per control step."""
        return round(self.ctrl_dt / self.sim_dt)

    @property
    def uses_contact(self) -> bool:
        """True for tasks whose success needs a contact force."""
        return self.task == "touch"

    def replace(self, **changes: Any) -> TaskConfig:
        """Return a copy with some fields changed (``reward`` takes a dict or a RewardConfig)."""
        if isinstance(changes.get("reward"), dict):
            changes["reward"] = dataclasses.replace(self.reward, **changes["reward"])
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict of every field."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TaskConfig:
        """Inverse of :meth:`to_dict`."""
        data = dict(data)
        reward = RewardConfig(**data.pop("reward", {}))
        for key in ("home_qpos", "target_low", "target_high", "force_band"):
            if key in data:
                data[key] = tuple(data[key])
        return cls(reward=reward, **data)


def reach_config(**overrides: Any) -> TaskConfig:
    """Reach: bring the tool tip within 2 cm of a point in the air; no contact term."""
    base = TaskConfig(
        task="reach",
        success_distance=0.02,
        target_low=(0.35, -0.25, 0.10),
        target_high=(0.65, 0.25, 0.45),
        reward=RewardConfig(contact=0.0),
    )
    return base.replace(**overrides)


# Gentle Touch commands at most 0.15 of each joint's URDF speed (27 deg/s on a UR5e class arm;
# one joint turning the tool at half a metre moves it at about 0.24 m/s, the order of the
# 250 mm/s reduced speed of ISO 10218-1). Why: the velocity servo presses with a steady force
# of about 1.2 kN per m/s of tool speed commanded into the box (the same in MuJoCo and
# PyBullet), so at the seed's 0.5 the 1-50 N band is an action of about 0.001-0.05 along the
# pressing direction, finer than PPO's exploration noise: policies learn to hover. At 0.15 the
# band is 0.004-0.18 and Touch trains in both the C batch and MJX (README, "Gentle Touch").
GENTLE_ACTION_SCALE = 0.15


def touch_config(variant: str = "gentle", **overrides: Any) -> TaskConfig:
    """Touch: press the top of a 5 cm box with 1-50 N, within 5 cm of its centre.

    Args:
        variant: "gentle" (default): the force must stay in the band for 3 control steps, a
            reading above the band rules success out for the episode, one above 100 N (a
            strike) ends it, the reward is :data:`GENTLE_REWARD` and the joints move at most
            :data:`GENTLE_ACTION_SCALE` of their URDF speed. "seed": the seed
            document's task (success on the first in-band step, no force or speed terms).
        overrides: fields to change.
    """
    if variant == "seed":
        base = TaskConfig(task="touch", variant="seed")
    elif variant == "gentle":
        base = TaskConfig(
            task="touch",
            variant="gentle",
            success_hold_steps=3,
            fail_on_overforce=True,
            terminate_on_overforce=True,
            strike_force=100.0,
            action_scale=GENTLE_ACTION_SCALE,
            reward=GENTLE_REWARD,
        )
    else:
        raise ValueError(f"unknown touch variant {variant!r}; choose 'gentle' or 'seed'")
    return base.replace(**overrides)


def task_config(name: str, **overrides: Any) -> TaskConfig:
    """The preset of task ``name`` ("reach" or "touch", any case), with overrides.

    ``variant`` among the overrides picks Touch's variant ("gentle" or "seed"); Reach has one.
    """
    key = name.lower()
    if key == "reach":
        if overrides.get("variant", "seed") != "seed":
            raise ValueError("reach has a single variant, 'seed'")
        return reach_config(**{k: v for k, v in overrides.items() if k != "variant"})
    if key == "touch":
        return touch_config(**overrides)
    raise ValueError(f"unknown task {name!r}; choose one of {sorted(TASKS)}")
