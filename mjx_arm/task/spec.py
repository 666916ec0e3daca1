"""The small interface every task implements, written once against an array namespace ``xp``.

A task owns its config preset, where its target is drawn, what counts as success on one step and
what its contact force means (a strike, a force above the band, the contact reward terms). Every
engine (the CPU MuJoCo and PyBullet envs, the MJX batch and the C batch) asks the task, so a new
task is one new file: a subclass of :class:`Task` registered with
:func:`mjx_arm.task.registry.register_task`.

The defaults describe a point target in free space that nothing touches (Reach); a contact task
overrides the force methods (see :mod:`mjx_arm.task.touch`). Every method works on one env
(scalars and ``(3,)`` vectors) and on batches (leading shape ``(...)``), in numpy and under
``jax.jit``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, ClassVar

from mjx_arm import names
from mjx_arm.task.config import RewardConfig, TaskConfig
from mjx_arm.urdf.scene_shapes import REACH_SCENE, SceneSpec


@dataclass(frozen=True)
class Budget:
    """What a training preset changes for one task (:attr:`Task.budgets`); None keeps the
    preset's value. The fields are those of ``mjx_arm.train.config.TrainConfig``.

    Attributes:
        num_timesteps, num_evals, num_envs, batch_size, stop_at_success, eval_from_step,
            eval_gate: as in the preset.
        randomization: the training draw by name (``mjx_arm.train.config.RANDOMIZATIONS``).
        force_scale: the observation normaliser's fixed scale of the wrist wrench, N
            (``normalizer.force_scale``).
        task: task config fields this preset sets for the task, name -> value (on top of the
            variant's preset; ``--set task.FIELD=...`` still changes them).
    """

    num_timesteps: int | None = None
    num_evals: int | None = None
    num_envs: int | None = None
    batch_size: int | None = None
    stop_at_success: float | None = None
    eval_from_step: int | None = None
    eval_gate: float | None = None
    randomization: str | None = None
    force_scale: float | None = None
    task: Mapping[str, Any] | None = None

    def changes(self) -> dict[str, Any]:
        """The fields this budget sets, name -> value."""
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        return {name: value for name, value in values.items() if value is not None}


class Task:
    """One task of the contract.

    Attributes:
        name: the registry name and ``TaskConfig.task`` value (lower case).
        scene: what the scene around the arm holds (table, target box or marker, a free
            cube), as data every engine builds from: one of
            :data:`mjx_arm.urdf.scene_shapes.SCENES` or a :class:`SceneSpec` of the task's own.
        uses_contact: whether the success condition reads the contact force.
        gripper: the task drives a parallel gripper: the arm must have one, the action has one
            more entry (the driven finger's speed, positive closes) and every engine fills the
            reading's ``grip`` vector (:mod:`mjx_arm.task.grip`).
        servo_dt: the step (s) the model's servo gains are computed for; 0 takes ``sim_dt``.
        extra_obs: observation keys after the contract's four, ``(key, size)`` in order.
        object_uniforms: uniform draws per episode for the object (:meth:`object_start`),
            after the target's three.
        reward_type: the task's reward weights: :class:`RewardConfig`, or a subclass in the
            task's file that adds the task's own terms (:meth:`task_terms` computes them).
        budgets: what each training preset changes for this task, preset name ->
            :class:`Budget` (a preset not named trains the task as it stands).
        default_arm: the arm the task's presets and envs take when none is given: an asset
            file (``assets/``), or "" for the shipped arm.
        metrics: the :meth:`measures` the batched envs report as training metrics, measure
            name -> metric name.
        solved_at: the evaluation success at which a run counts as solved: the ``fast``
            preset stops there (``stop_at_success``) and ``bench seeds`` counts a seed solved
            from there unless given ``--threshold``.
    """

    name: ClassVar[str]
    scene: ClassVar[SceneSpec] = REACH_SCENE
    uses_contact: ClassVar[bool] = False
    gripper: ClassVar[bool] = False
    servo_dt: ClassVar[float] = 0.0
    extra_obs: ClassVar[tuple[tuple[str, int], ...]] = ()
    object_uniforms: ClassVar[int] = 0
    reward_type: ClassVar[type[RewardConfig]] = RewardConfig
    budgets: ClassVar[Mapping[str, Budget]] = {}
    default_arm: ClassVar[str] = ""
    metrics: ClassVar[Mapping[str, str]] = {}
    solved_at: ClassVar[float] = 0.95

    @property
    def env_id(self) -> str:
        """The task's Gymnasium id, ``mjx_arm/Name-v0``."""
        return names.env_id(self.name)

    def config(self, **overrides: Any) -> TaskConfig:
        """The task's preset :class:`TaskConfig` with ``overrides`` applied."""
        raise NotImplementedError

    def target_body_pos(self, xp: Any, u3, cfg: TaskConfig):
        """Where the target body goes (m, base frame), from uniform draws ``u3 (..., 3)``: the
        config's target box, scaled to the arm's reach."""
        low, high = (xp.asarray(v) for v in cfg.target_box())
        return low + u3 * (high - low)

    def target_point(self, xp: Any, body_pos, cfg: TaskConfig):
        """The point the ee must reach (m), ``(..., 3)``, given the target body's position."""
        return body_pos

    def object_start(self, xp: Any, u, cfg: TaskConfig):
        """The free object a gripper task places (:class:`mjx_arm.task.grip.ObjectStart`),
        from the episode's draws after the joints' (``u (..., 3 + object_uniforms)``: the
        target's three, then the object's); None where the task has none."""
        return None

    def grip_observation(self, xp: Any, ee_pos, ee_quat, grip, cfg: TaskConfig):
        """The :attr:`extra_obs` entries of a reading, ``(..., k)``, from the ee pose and the
        ``grip`` vector (gripper tasks only)."""
        raise NotImplementedError

    def measures(self, xp: Any, ee_pos, ee_quat, grip, cfg: TaskConfig) -> dict[str, Any]:
        """Named per-step measures that :meth:`holds` and :meth:`task_terms` read (gripper
        tasks; empty otherwise)."""
        return {}

    @property
    def reward_terms(self) -> tuple[str, ...]:
        """The task's own reward terms (after the shared ones): ``reward_type.task_terms``."""
        return self.reward_type.task_terms

    def task_terms(self, xp: Any, extra: dict[str, Any], zero) -> dict[str, Any]:
        """The task's own raw reward terms (:attr:`reward_terms`) from :meth:`measures`, each
        ``(...)`` (``zero``: a zero array of the batch shape); 0 by default."""
        return dict.fromkeys(self.reward_terms, zero)

    def holds(self, xp: Any, distance, force_norm, cfg: TaskConfig, extra=None):
        """The success condition of one step (bool ``(...)``): the ee within
        ``success_distance`` of the target point. An episode succeeds once this has held
        ``success_hold_steps`` steps running. ``extra``: :meth:`measures`."""
        return distance < cfg.success_distance

    def over_band(self, xp: Any, force_norm, cfg: TaskConfig):
        """Whether this step's contact force is above what the task allows, bool ``(...)``."""
        return xp.zeros_like(force_norm, dtype=bool)

    def strikes(self, xp: Any, force_norm, cfg: TaskConfig):
        """Whether this step's contact force ends the episode (a protective stop): bool
        ``(...)``, or ``False`` for all (it is or-ed into the termination flags)."""
        return False

    def contact_terms(self, xp: Any, near, force_norm, cfg: TaskConfig) -> tuple[Any, Any]:
        """The raw ``contact`` and ``force_excess`` reward terms, each ``(...)``.

        Args:
            near: the ee is within ``success_distance`` of the target (bool ``(...)``).
            force_norm: tared contact force norm (N), ``(...)``.
        """
        zero = 0.0 * force_norm
        return zero, zero

    def __repr__(self) -> str:
        return f"<task {self.name} ({self.env_id})>"
