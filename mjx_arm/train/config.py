"""Typed training configuration, presets and ``--set key=value`` overrides.

PPO hyperparameters follow the seed document (learning_rate 3e-4, discount 0.99, gae_lambda
0.95, clipping 0.2, value loss coefficient 0.5, max_grad_norm 0.5, 10 updates per batch). Its
rollout settings were for 4 CPU envs (n_steps 2048 per env, minibatch 64, i.e. 8192 samples
per update in 128 minibatches). In the batched setting a rollout is ``num_envs`` envs times
``unroll_length`` steps, and an update uses ``batch_size * num_minibatches`` sequences of
``unroll_length`` steps; see :meth:`TrainConfig.samples_per_update`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mjx_arm.arm.config import ArmConfig
from mjx_arm.envs.physics_config import PhysicsConfig, RandomizationConfig
from mjx_arm.inputs import MAX_SEED, ConfigError, MissingInputError, read_json_object
from mjx_arm.names import BACKENDS
from mjx_arm.settings import check_range, check_types, config_fields, set_path, split_setting
from mjx_arm.task.config import TaskConfig, task_config
from mjx_arm.task.registry import is_task, task_names
from mjx_arm.train.normalizer import NormalizerConfig
from mjx_arm.train.schedule import ScheduleConfig
from mjx_arm.train.task_settings import set_task_field, task_changes

PARTITIONS = ("auto", "xla", "per_device")

# Nested sections of the config: name -> type (``--set physics.impl=warp``).
SECTIONS = {
    "physics": PhysicsConfig,
    "randomization": RandomizationConfig,
    "arm": ArmConfig,
    "schedule": ScheduleConfig,
    "normalizer": NormalizerConfig,
}

# Adam's update of a weight is about learning_rate in size whatever the gradient; the networks'
# weights start near 0.1, so a rate above 1 can never train.
MAX_LEARNING_RATE = 1.0


# The policy's action distributions (TrainConfig.policy_distribution).
POLICY_DISTRIBUTIONS = ("tanh_normal", "normal")


@dataclass(frozen=True)
class TrainConfig:
    """Everything a training run needs besides the task. Saved as JSON in the run directory.

    Attributes:
        task: a registered task's name ("reach", "touch", "lift", ...).
        task_settings: the task's config: its preset, with what the run changed
            (``--set task.action_scale=0.4``; ``task.variant=seed`` picks the seed document's
            Touch); None takes the task's default preset. Saved with every run; a run saved
            before it existed stored the changes as ``task_overrides``, read the same way.
        arm: the arm trained (URDF, end effector, joints, home pose; default: the shipped arm).
        backend: "auto", "mjx" or "mujoco" (C MuJoCo through a host callback, CPU).
        physics: the MJX implementation (jax or warp) and its buffers.
        randomization: domain randomisation of the training envs (evaluation stays nominal).
        num_timesteps: env steps to train for.
        num_envs: parallel envs in the rollout.
        unroll_length: steps per env per rollout (the PPO sequence length).
        batch_size: sequences per minibatch.
        num_minibatches: minibatches per update epoch.
        num_updates_per_batch: epochs over each rollout batch (the seed's n_epochs = 10).
        learning_rate, discounting, gae_lambda, clipping_epsilon, vf_loss_coefficient,
            max_grad_norm, entropy_cost, reward_scaling: PPO settings.
        clip_per_network: clip the policy's and the value's gradients to ``max_grad_norm``
            each, instead of one global norm over both (where the value's gradient is
            thousands of times the policy's, the shared clip shrinks the policy's step to
            nothing: docs/training.md, "A seed the value loss froze"). Off in every preset.
        schedule: how the learning rate moves (constant, or adapted to a KL target).
        kl_stop: an update takes no more gradient steps once a minibatch's KL between the
            rollout's policy and the current one, measured before its step, exceeds this (the
            rest of its minibatches are skipped, as Stable-Baselines3's ``target_kl`` does);
            0 never stops. Meant with ``normalizer.after_update``, without which the first
            step's KL already holds the normaliser's move.
        normalize_observations: running mean/std normalisation of observations.
        normalizer: its std floor and clip.
        policy_hidden, value_hidden: MLP layer sizes.
        policy_distribution: the policy's action distribution. "tanh_normal" (Brax's default):
            a Gaussian whose mean and std the MLP gives per state, its samples squashed by a
            tanh. "normal": a Gaussian whose mean the MLP gives, bounded to (-1, 1) (a soft
            sign), with one learned std per action entry for every state, its samples clipped
            to [-1, 1] by the env. Only "tanh_normal" policies export (:mod:`mjx_arm.policy`).
        num_evals: evaluations over the run (metrics are written at each).
        num_eval_envs: envs per evaluation (one episode each).
        eval_from_step: env steps before which the policy is not evaluated: neither the initial
            policy nor an epoch that ends before this step (its metrics row holds its training
            figures alone; it cannot stop the run or become its best). An evaluation takes as
            long as a few hundred thousand env steps and a policy under training solves nothing
            in its first epochs; the run's last epoch is always evaluated. 0: every epoch, and
            the initial policy, as Brax does.
        eval_gate: an epoch whose training episodes (those that ended in it, their actions
            sampled) succeeded at a rate under this is not evaluated either, nor is the initial
            policy; the run's last epoch always is. The training rate of each epoch is logged
            (``training/episode_success``) whether or not the gate is on. 0: off.
        checkpoint_every: save a checkpoint every this many evaluations (and at the end).
        env_state_every: the training envs' state (hundreds of MB for 8192 MJX envs) goes
            into every this many evaluations' checkpoint; a resume starts from the newest
            checkpoint that holds it, so it repeats at most this many epochs and then follows
            the run it continues exactly.
        stop_at_success: stop once an evaluation's success rate reaches this (its checkpoint
            is saved); 0 trains all ``num_timesteps``.
        keep_best: a run that ends on its budget (``stop_at_success`` not reached) saves the
            params of its best evaluation (the later one on a tie) as its final checkpoint,
            with ``params_step`` in the checkpoint's meta.json, so the run's policy is the
            best it evaluated rather than wherever PPO drifted last.
        seed: PRNG seed.
        deterministic: the same seed, config, GPU model and versions give the same run, bit
            for bit (:mod:`mjx_arm.train.determinism`: deterministic XLA ops and Warp atomics).
        devices: local devices to train on (0: all of them). The env batch is split evenly
            over them, so ``num_envs`` and ``batch_size`` must be multiples of the count.
        scale_with_devices: ``train --devices N`` (N > 1) multiplies ``num_envs``,
            ``batch_size``, ``num_timesteps`` and ``eval_from_step`` by N
            (:meth:`scaled_for_devices`): each GPU keeps the preset's envs and minibatch share,
            and a run takes as many updates and skips the evaluations of as many. Off by
            default: the preset's batch is split over the GPUs, so a run learns as on one
            GPU. On two H200s the grown batch needed 2.0x-2.6x the env steps and solved Touch
            later than the split one (docs/training.md, "Several devices").
        devices_lr_power: where the batch grows with N devices, ``learning_rate`` is
            multiplied by N to this power (1: the rate grows as the batch, the linear scaling
            rule; 0, the default: unchanged).
        devices_clip: where the batch grows with N devices, PPO's ``clipping_epsilon``
            becomes this (0, the default: unchanged). Both are off: on two H200s the rate
            doubled with the clip at 0.4 still needed twice one GPU's env steps on Touch and
            lost a seed to strikes (docs/training.md, "Several devices").
        partition: how the batched physics is spread over the devices: "xla" (XLA partitions
            the jitted env graph), "per_device" (``shard_map``: each device steps its own
            envs; needed for MuJoCo Warp, whose kernels XLA cannot partition) or "auto"
            (per_device on Warp, xla otherwise).
    """

    task: str = "reach"
    task_settings: TaskConfig | None = None
    arm: ArmConfig = field(default_factory=ArmConfig)
    backend: str = "auto"
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    randomization: RandomizationConfig = field(default_factory=RandomizationConfig)
    num_timesteps: int = 5_000_000
    num_envs: int = 2048
    unroll_length: int = 20
    batch_size: int = 256
    num_minibatches: int = 32
    num_updates_per_batch: int = 10
    learning_rate: float = 3e-4
    discounting: float = 0.99
    gae_lambda: float = 0.95
    clipping_epsilon: float = 0.2
    vf_loss_coefficient: float = 0.5
    max_grad_norm: float = 0.5
    clip_per_network: bool = False
    entropy_cost: float = 1e-3
    reward_scaling: float = 0.1
    schedule: ScheduleConfig = field(default_factory=ScheduleConfig)
    kl_stop: float = 0.0
    normalize_observations: bool = True
    normalizer: NormalizerConfig = field(default_factory=NormalizerConfig)
    policy_hidden: tuple[int, ...] = (128, 128, 128)
    value_hidden: tuple[int, ...] = (256, 256, 256)
    policy_distribution: str = "tanh_normal"
    num_evals: int = 10
    num_eval_envs: int = 128
    eval_from_step: int = 0
    eval_gate: float = 0.0
    checkpoint_every: int = 1
    env_state_every: int = 5
    stop_at_success: float = 0.0
    keep_best: bool = True
    seed: int = 0
    deterministic: bool = False
    devices: int = 0
    scale_with_devices: bool = False
    devices_lr_power: float = 0.0
    devices_clip: float = 0.0
    partition: str = "auto"

    def __post_init__(self) -> None:
        if self.task_settings is None and is_task(self.task):
            object.__setattr__(self, "task_settings", task_config(self.task))
        check_types(self)
        check_range(self, _POSITIVE_INTS, low=1)
        check_range(self, ("policy_hidden", "value_hidden"), low=1, high=MAX_LAYER)
        check_range(self, ("num_envs", "num_eval_envs", "batch_size"), high=MAX_BATCH)
        check_range(self, ("seed",), low=0, high=MAX_SEED)
        check_range(self, ("devices", "eval_from_step"), low=0)
        check_range(self, ("learning_rate", "clipping_epsilon", "max_grad_norm"), above=0)
        check_range(self, ("reward_scaling", "discounting"), above=0)
        check_range(
            self, ("discounting", "gae_lambda", "stop_at_success", "eval_gate"), low=0, high=1
        )
        check_range(self, ("vf_loss_coefficient", "entropy_cost", "kl_stop"), low=0)
        check_range(self, ("devices_lr_power", "devices_clip"), low=0)
        if self.policy_distribution not in POLICY_DISTRIBUTIONS:
            raise ConfigError(
                f"policy_distribution must be one of {list(POLICY_DISTRIBUTIONS)}, got "
                f"{self.policy_distribution!r}"
            )
        if self.learning_rate > MAX_LEARNING_RATE:
            raise ConfigError(
                f"learning_rate must be <= {MAX_LEARNING_RATE:g}, got {self.learning_rate:g}: "
                "Adam moves every weight by about learning_rate per update, so a larger rate "
                "replaces the network with noise at every update "
                f"(default {type(self).learning_rate:g})"
            )

    def samples_per_update(self) -> int:
        """Env steps consumed by one PPO update (one rollout batch)."""
        return self.batch_size * self.num_minibatches * self.unroll_length

    def scaled_for_devices(self, count: int) -> TrainConfig:
        """The config for ``count`` devices: envs, minibatch size, budget and the first
        evaluated step times ``count`` where ``scale_with_devices`` (else unchanged), the
        learning rate times ``count ** devices_lr_power`` and the clip ``devices_clip``."""
        if not self.scale_with_devices or count < 2:
            return self
        return self.replace(
            num_envs=self.num_envs * count,
            batch_size=self.batch_size * count,
            num_timesteps=self.num_timesteps * count,
            eval_from_step=self.eval_from_step * count,
            learning_rate=self.learning_rate * count**self.devices_lr_power,
            clipping_epsilon=self.devices_clip or self.clipping_epsilon,
        )

    def replace(self, **changes: Any) -> TrainConfig:
        """A copy with fields changed."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrainConfig:
        """Inverse of :meth:`to_dict`; unknown keys are an error. Sections missing from older
        files take their defaults; ``task_overrides`` (the task's changes to its preset, as
        configs stored them before ``task_settings``) is read onto the task's preset."""
        data = dict(data)
        if "max_devices" in data:  # the name in configs written before "devices"
            data.setdefault("devices", data.pop("max_devices"))
        overrides = data.pop("task_overrides", None)
        settings = data.pop("task_settings", None)
        data = config_fields(cls, data, "training config")
        for key, kind in SECTIONS.items():
            if isinstance(data.get(key), dict):
                data[key] = kind.from_dict(data[key])
        task = data.get("task", cls.task)
        if isinstance(settings, dict):
            settings = TaskConfig.from_dict(settings)
        if overrides is not None:
            if not isinstance(overrides, dict):
                raise ConfigError("task_overrides must be a table of task fields")
            settings = task_changes(task, settings, overrides)
        return cls(task_settings=settings, **data)

    def validate(self) -> None:
        """Check names, the task's settings, the arm's URDF and the batch arithmetic PPO
        requires (the field types and ranges are checked on construction).

        Raises:
            ConfigError: the first problem found.
        """
        if not is_task(self.task):
            raise ConfigError(f"task must be one of {list(task_names())}, got {self.task!r}")
        if self.backend not in BACKENDS:
            raise ConfigError(f"backend must be one of {BACKENDS}, got {self.backend!r}")
        if self.partition not in PARTITIONS:
            raise ConfigError(f"partition must be one of {PARTITIONS}, got {self.partition!r}")
        if self.arm.urdf and not self.arm.urdf_path.is_file():
            raise ConfigError(f"arm.urdf {self.arm.urdf!r} is not a file")
        if (self.batch_size * self.num_minibatches) % self.num_envs:
            raise ConfigError(
                f"batch_size * num_minibatches ({self.batch_size * self.num_minibatches}) must "
                f"be a multiple of num_envs ({self.num_envs})"
            )
        self.task_config()

    def task_config(self) -> TaskConfig:
        """The task's config, ``task_settings``.

        Raises:
            ConfigError: settings of another task than ``task``.
        """
        settings = self.task_settings
        if settings is None or settings.task != self.task:
            held = settings.task if settings else None
            raise ConfigError(f"task settings are of task {held!r}, not of {self.task!r}")
        return settings

    def check_devices(self, count: int) -> None:
        """Check that the batches split evenly over ``count`` devices.

        Raises:
            ConfigError: ``num_envs`` or ``batch_size`` is not a multiple of ``count``.
        """
        for name in ("num_envs", "batch_size"):
            if getattr(self, name) % count:
                raise ConfigError(
                    f"{name} ({getattr(self, name)}) must be a multiple of the device count "
                    f"({count}); change it with --set {name}=N or choose --devices"
                )


_POSITIVE_INTS = (
    "num_timesteps",
    "num_envs",
    "unroll_length",
    "batch_size",
    "num_minibatches",
    "num_updates_per_batch",
    "num_evals",
    "num_eval_envs",
    "checkpoint_every",
    "env_state_every",
)
MAX_BATCH = 2**20  # envs or sequences in one batch: beyond any accelerator's memory
MAX_LAYER = 2**14  # units in one hidden layer


def apply_overrides(config: TrainConfig, items: list[str]) -> TrainConfig:
    """Apply ``key=value`` overrides (:mod:`mjx_arm.settings`); ``task.KEY=value`` changes
    ``task_settings`` (:func:`task_changes`) and ``task.reward.TERM=value`` its reward
    weights. A ``task=`` naming another task starts from that task's default settings."""
    changes: dict[str, Any] = {}
    for item in items:
        path, text = split_setting(item)
        try:
            if path[0] == "task" and len(path) > 1:
                set_task_field(changes, ".".join(path[1:]), text, config.task)
            else:
                config = set_path(config, path, text, "config key")
        except ConfigError as err:
            raise ConfigError(f"--set {item}: {err}") from err
    if not changes and config.task_settings and config.task_settings.task == config.task:
        return config
    if not is_task(config.task):
        return config  # validate() names the unknown task
    return config.replace(task_settings=task_changes(config.task, config.task_settings, changes))


def saved_config(run_dir: str | Path) -> TrainConfig:
    """The training config a run directory saved (``config.json``), to resume it.

    Raises:
        InputError: no run directory or config.json, or one that is not a training config.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise MissingInputError(f"--resume {str(run_dir)!r}: no such run directory")
    path = run_dir / "config.json"
    if not (path.exists() or path.is_symlink()):  # anything else there: read, and named
        raise MissingInputError(
            f"--resume {str(run_dir)!r} is not a run directory (no config.json): no checkpoint "
            "to resume from"
        )
    saved = read_json_object(path, "run config", within=run_dir).get("train")
    if not isinstance(saved, dict):
        raise ConfigError(f"{path} has no 'train' table: not the config of a training run")
    try:
        return TrainConfig.from_dict(saved)
    except ConfigError as err:
        raise ConfigError(f"{path}: not a usable training config: {err}") from err
