"""Typed configuration of a task: timing, action scaling, sampling, reward weights, success.

One :class:`TaskConfig` drives every engine (CPU MuJoCo, PyBullet, MJX), so the numbers below are
the contract. Each task's preset lives in its own file (:mod:`mjx_arm.task.reach`,
:mod:`mjx_arm.task.touch`); :func:`task_config` picks one by name.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from mjx_arm.inputs import ConfigError
from mjx_arm.settings import check_range, check_types, config_fields
from mjx_arm.task.observation import JOINT_ENCODINGS
from mjx_arm.task.registry import get_task, is_task, task_names

# The speed limits (rad/s) a joint's command is scaled from (TaskConfig.joint_speeds): the arms
# measured so far (URDF limits of 2.2 to 3.2 rad/s) command action_scale times their own limit;
# a 0.6 rad/s arm is not slowed to a quarter of the others, and a joint whose URDF says 10000
# rad/s does not get a command of thousands.
V_LOW, V_HIGH = 2.0, 3.5


@dataclass(frozen=True)
class RewardConfig:
    """Weights of the named reward terms; the reward is ``sum(weight * term)``.

    The seed preset is
    ``-10*(1-exp(-d/0.1)) + 500*contact - 5*(#joints beyond limits) - 0.1*sum(|qdot|)``.
    Terms (see :mod:`mjx_arm.task.reward`):
    ``distance`` = 1 - exp(-d / distance_length), ``contact`` = 1 when the tool presses the target
    inside the force band, ``joint_limit`` = number of joints beyond ``soft_limit`` of their range,
    ``joint_velocity`` = ``sum |qdot|`` (rad/s), ``success`` = 1 on the success step,
    ``nonfinite`` = 1 when the physics diverged (a NaN or infinite state, or a runaway joint
    speed: see ``TaskConfig.divergence_speed_factor``),
    ``force_excess`` = (F - F_max) / F_max where the contact force F is above the band, else 0,
    ``approach_speed`` = (how fast d shrinks)^2 (m^2/s^2) while d < ``approach_radius``,
    ``action_rate`` = sum (a_t - a_{t-1})^2 over the six action entries,
    ``overforce`` = 1 on a step whose contact force is above the band,
    ``proximity`` = exp(-d / proximity_length): 1 at the target, 0.37 one length away (a
    near-field pull that ``distance``'s longer length scale lacks),
    ``streak`` = how far a press inside the band has held on: 0 on a one-step tap, 1 once it
    has held ``success_hold_steps`` steps running (:func:`mjx_arm.task.reward.streak`),
    ``strike`` = 1 on the step whose reading ends the episode as a strike (a protective stop:
    :meth:`mjx_arm.task.spec.Task.strikes`),
    ``press`` = how near the middle of the force band a press within ``success_distance`` is:
    1 at the middle, 0 at either end and outside (:func:`mjx_arm.task.reward.force_band_peak`;
    ``contact`` pays the whole band alike).

    A task with terms of its own (Lift's ``lift``, ``grasp``, ...) declares them in its file:
    a frozen subclass that adds one weight field per term and names them in
    :attr:`task_terms` (:attr:`mjx_arm.task.spec.Task.reward_type`). Its terms follow these in
    the sum.
    """

    task_terms: ClassVar[tuple[str, ...]] = ()

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
    strike: float = 0.0
    press: float = 0.0
    distance_length: float = 0.1
    proximity_length: float = 0.01
    soft_limit: float = 0.95
    approach_radius: float = 0.1

    @classmethod
    def term_names(cls) -> tuple[str, ...]:
        """Every term of this reward in the order they are summed: :data:`REWARD_TERMS`, then
        the task's own."""
        return REWARD_TERMS + cls.task_terms

    def weights(self) -> dict[str, float]:
        """Weight of each named term."""
        return {name: getattr(self, name) for name in self.term_names()}


# The terms of every task's reward, in the order they are summed (a task's own follow).
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
    "strike",
    "press",
)


@dataclass(frozen=True)
class TaskConfig:
    """Everything that defines a task, identical in every engine.

    Attributes:
        task: a registered task name (:mod:`mjx_arm.task.registry`): "reach" (point target, no
            contact), "touch" (press the 5 cm box) or one added by a task file.
        ctrl_dt: control period (s); one action and one observation per period.
        sim_dt: physics step (s); ``ctrl_dt / sim_dt`` substeps per control step.
        action_scale: joint velocity target = action * speed, with speed =
            ``action_scale * v_max`` of each joint's URDF velocity limit, that limit read as
            at least :data:`V_LOW` and at most :data:`V_HIGH`, and never above the limit
            itself (:meth:`joint_speeds`).
        episode_steps: control steps before truncation (150 = 5 s).
        terminate_on_success: end the episode on the first success step.
        home_qpos: joint angles (rad) episodes start around; () takes the arm's home pose
            (:class:`mjx_arm.arm.config.ArmConfig`). An env fills it in from its arm.
        init_noise: half-width (rad) of the uniform noise added to ``home_qpos`` at reset.
        target_low, target_high: box (m, base frame) the target is drawn from uniformly, for
            the shipped arm. For touch only x and y are used: the box stands on the table at
            z = 0.
        workspace_scale: the target box is scaled by this factor about the base; 0 takes the
            arm's reach over the shipped arm's (1.0 for the shipped arm). An env fills it in.
        object_scale: a gripper task's object (Lift's cube) over its shipped size, its edge
            and its mass alike (:meth:`mjx_arm.task.lift.Lift.object_start`); 0 takes the arm's (1.0
            but for a gripper that holds only a smaller cube, :mod:`mjx_arm.arm.setup`). An env
            fills it in.
        grasp_closure: how closed (0 open, 1 closed) a gripper task's gripper must be for its
            pads' press to count as a grasp (:meth:`mjx_arm.task.lift.Lift.measures`): where
            they stand :data:`~mjx_arm.task.lift.GRASP_SLACK` wider than the cube; 0 takes the
            arm's (:func:`mjx_arm.arm.setup.grasp_closure`). An env fills it in.
        success_distance: d (m) below which the ee point counts as at the target.
        force_band: (min, max) contact force norm (N) of a successful touch.
        success_hold_steps: consecutive control steps the success condition must hold (near the
            target, and for Touch the force inside the band) before the episode succeeds.
        fail_on_overforce: a force reading above the band at any step of the episode rules out
            success for the rest of it.
        pay_after_overforce: whether the terms that pay a press (``contact``, ``press`` and
            ``streak``) keep paying once a reading above the band has ruled success out
            (``fail_on_overforce``). True (as before the field): they do, so pressing over the
            band once and then holding a press in it for the rest of the episode can pay more
            than success. False: they pay nothing for the rest of that episode.
        terminate_on_overforce: end the episode at the first reading above ``strike_force``
            (a protective stop).
        strike_force: contact force norm (N) that ends the episode when
            ``terminate_on_overforce``; 0 takes the top of ``force_band``. Any reading above the
            band still rules success out when ``fail_on_overforce``.
        variant: "seed" (the seed document's task) or "gentle" (Touch's default: hold, no strike).
        force_clip: bound (N and N m) of each contact_force component.
        joint_encoding: how ``joint_angles`` encodes the joint angles
            (:class:`mjx_arm.task.observation.JointCoding`): "centred" (each limited joint
            relative to the middle of its range, so no jump inside a range) or "wrapped" (every
            angle in [-pi, pi]: how configs recorded before the field was added read).
        divergence_speed_factor: the physics has diverged when a joint turns faster than this
            multiple of its URDF velocity limit (or any value is NaN or infinite). The velocity
            servos keep the joints near their limits, so a joint ten times faster means the
            integration ran away: the episode ends with ``info["diverged"]`` and the
            ``nonfinite`` reward term (PyBullet caps joint speeds at 100 rad/s, so its runaway
            shows as speed, not as NaN).
        solver_iterations, ls_iterations: the MuJoCo models' constraint solver iterations and
            Newton line-search iterations, in MJX and C MuJoCo alike; 0 takes the converter's
            (2 and 4: :class:`mjx_arm.urdf.convert_config.ConvertConfig`). PyBullet ignores
            them.
        reward: weights of the reward terms.
    """

    task: str = "touch"
    ctrl_dt: float = 1.0 / 30.0
    sim_dt: float = 1.0 / 240.0
    action_scale: float = 0.5
    episode_steps: int = 150
    terminate_on_success: bool = True
    home_qpos: tuple[float, ...] = ()
    init_noise: float = 0.05
    target_low: tuple[float, float, float] = (0.35, -0.25, 0.05)
    target_high: tuple[float, float, float] = (0.65, 0.25, 0.45)
    workspace_scale: float = 0.0
    object_scale: float = 0.0
    grasp_closure: float = 0.0
    success_distance: float = 0.05
    force_band: tuple[float, float] = (1.0, 50.0)
    success_hold_steps: int = 1
    fail_on_overforce: bool = False
    pay_after_overforce: bool = True
    terminate_on_overforce: bool = False
    strike_force: float = 0.0
    variant: str = "seed"
    force_clip: float = 100.0
    joint_encoding: str = "centred"
    divergence_speed_factor: float = 10.0
    solver_iterations: int = 0
    ls_iterations: int = 0
    reward: RewardConfig = field(default_factory=RewardConfig)

    def __post_init__(self) -> None:
        check_types(self)
        if not is_task(self.task):
            raise ConfigError(f"task must be one of {list(task_names())}, got {self.task!r}")
        object.__setattr__(self, "reward", task_reward(self.task, self.reward))
        check_types(self.reward)
        check_range(self, ("ctrl_dt", "sim_dt", "action_scale", "success_distance"), above=0)
        check_range(self, ("force_clip", "divergence_speed_factor"), above=0)
        check_range(self, ("init_noise", "strike_force"), low=0)
        check_range(self, "episode_steps", low=1, high=100_000)  # up to about an hour
        check_range(self, ("solver_iterations", "ls_iterations"), low=0, high=1000)
        ratio = self.ctrl_dt / self.sim_dt
        if abs(ratio - round(ratio)) > 1e-6 or not 1 <= round(ratio) <= 1000:
            raise ConfigError(
                f"ctrl_dt {self.ctrl_dt} is not a whole multiple of sim_dt {self.sim_dt} "
                "(1 to 1000 physics steps per control step)"
            )
        if not 0 <= self.force_band[0] < self.force_band[1]:
            raise ConfigError(
                f"force_band must be (low, high), 0 <= low < high, got {self.force_band}"
            )
        if any(lo > hi for lo, hi in zip(self.target_low, self.target_high, strict=True)):
            raise ConfigError("target_low must be <= target_high in x, y and z")
        if self.workspace_scale < 0:
            raise ConfigError("workspace_scale must be >= 0 (0: from the arm)")
        if not 0 <= self.object_scale <= 1:
            raise ConfigError("object_scale must be in [0, 1] (0: from the arm)")
        if not 0 <= self.grasp_closure < 1:
            raise ConfigError("grasp_closure must be in [0, 1) (0: from the arm)")
        if self.success_hold_steps < 1:
            raise ConfigError("success_hold_steps must be >= 1")
        if not self.divergence_speed_factor > 1:
            raise ConfigError("divergence_speed_factor must be > 1")
        if self.joint_encoding not in JOINT_ENCODINGS:
            raise ConfigError(
                f"joint_encoding must be one of {JOINT_ENCODINGS}, got {self.joint_encoding!r}"
            )

    def joint_speeds(self, v_max) -> np.ndarray:
        """Joint velocity targets (rad/s) of a full action, ``(n,)``, from the URDF limits
        ``v_max (n,)``: ``min(action_scale * clip(v_max, V_LOW, V_HIGH), v_max)``."""
        v_max = np.asarray(v_max, dtype=np.float64)
        return np.minimum(self.action_scale * np.clip(v_max, V_LOW, V_HIGH), v_max)

    @property
    def n_substeps(self) -> int:
        """Physics steps per control step."""
        return round(self.ctrl_dt / self.sim_dt)

    def target_box(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """``(low, high)`` of the target box (m, base frame), scaled by ``workspace_scale``."""
        scale = self.workspace_scale or 1.0
        low = tuple(scale * v for v in self.target_low)
        return low, tuple(scale * v for v in self.target_high)

    def for_arm(
        self,
        home_qpos: tuple[float, ...],
        reach_scale: float,
        episode_steps: int = 0,
        object_scale: float = 1.0,
        grasp_closure: float = 0.0,
    ) -> TaskConfig:
        """This config with the arm's home pose, workspace scale, object scale and grasp
        closure where it leaves them empty, and an episode of at least ``episode_steps`` (0: as
        it is).

        Raises:
            ValueError: a ``home_qpos`` given here that does not fit the arm's joint count.
        """
        home = self.home_qpos or tuple(float(q) for q in home_qpos)
        if len(home) != len(home_qpos):
            raise ValueError(
                f"home_qpos has {len(home)} angles; the arm has {len(home_qpos)} joints"
            )
        return self.replace(
            home_qpos=home,
            workspace_scale=self.workspace_scale or reach_scale,
            object_scale=self.object_scale or object_scale,
            grasp_closure=self.grasp_closure or grasp_closure,
            episode_steps=max(self.episode_steps, episode_steps),
        )

    @property
    def spec(self) -> Any:
        """The task's :class:`~mjx_arm.task.spec.Task` (its sampling, success and contact rules)."""
        return get_task(self.task)

    @property
    def uses_contact(self) -> bool:
        """True for tasks whose success needs a contact force."""
        return self.spec.uses_contact

    def replace(self, **changes: Any) -> TaskConfig:
        """Return a copy with some fields changed (``reward`` takes a dict or a RewardConfig;
        a list, as ``--set task.force_band=[1,30]`` gives, becomes the field's tuple)."""
        changes = {k: tuple(v) if isinstance(v, list) else v for k, v in changes.items()}
        if isinstance(changes.get("reward"), dict):
            changes["reward"] = dataclasses.replace(self.reward, **changes["reward"])
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict of every field."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TaskConfig:
        """Inverse of :meth:`to_dict`; a config recorded before ``joint_encoding`` existed
        reads as ``wrapped``, the encoding it was trained with."""
        data = {"joint_encoding": "wrapped", **data}
        weights = data.pop("reward", {})
        fields = config_fields(cls, data, "task config")
        kind = get_task(fields["task"]).reward_type if is_task(fields.get("task")) else RewardConfig
        if isinstance(weights, dict):  # before tasks declared their own terms, every config
            known = {f.name for f in dataclasses.fields(kind)}  # held Lift's at weight 0
            weights = {k: v for k, v in weights.items() if k in known or v != 0}
        reward = kind(**config_fields(kind, weights, "reward"))
        return cls(reward=reward, **fields)


def task_reward(task: str, reward: RewardConfig) -> RewardConfig:
    """``reward`` as the weights of task ``task``'s reward type
    (:attr:`~mjx_arm.task.spec.Task.reward_type`): the weights it shares with it kept, the
    task's own terms at weight 0 where ``reward`` lacks them, and the weights of terms the task
    does not have left out (they weighed terms that are 0 in that task: a config switched to
    another task with ``replace(task=...)`` scores as before).
    """
    kind = get_task(task).reward_type
    if type(reward) is kind:
        return reward
    known = {f.name for f in dataclasses.fields(kind)}
    return kind(**{k: v for k, v in dataclasses.asdict(reward).items() if k in known})


def task_config(name: str, **overrides: Any) -> TaskConfig:
    """The preset of task ``name`` (any case) from its task file, with overrides.

    ``variant`` among the overrides picks a variant where the task has several (Touch:
    "gentle" or "seed").
    """
    return get_task(name.lower()).config(**overrides)
