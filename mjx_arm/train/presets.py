"""Training presets: named starting points of a :class:`~mjx_arm.train.config.TrainConfig`.

``--preset`` picks one; a task changes a preset's budget for itself (its ``budgets``), and
``--set`` changes any field on top (:func:`load_config`: the preset, then a config file, then
``--set``). What each preset is for, and how ``fast`` was chosen, is in docs/training.md.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from mjx_arm.arm.config import ArmConfig
from mjx_arm.envs.physics_config import LATENCY, SELECTED, RandomizationConfig
from mjx_arm.inputs import ConfigError, read_json_object
from mjx_arm.names import PRESET_NAMES
from mjx_arm.paths import asset
from mjx_arm.task.registry import get_task, is_task, task_names
from mjx_arm.train.config import SECTIONS, TrainConfig, apply_overrides
from mjx_arm.train.task_settings import task_changes

# The seed document's PPO settings mapped onto a GPU batch, on the seed document's task (Touch
# succeeds on the first in-band step; no force or speed terms: PRESET_VARIANTS) and without
# randomisation.
SEED = TrainConfig()

# Fastest to a solved task on one GPU: 8192 envs (Warp's throughput flattens out above that),
# each 10-step rollout (81,920 transitions) feeding 4 epochs of 32 minibatches, about 1,560
# gradient steps per million env steps (16 minibatches of 1,024 left gentle Touch at zero
# success for 40M+ steps on most seeds). Discount 0.97: these tasks end in under 2 s when solved.
# It stops at the first evaluation at the task's ``solved_at`` (STOPS_WHEN_SOLVED): a run that
# trained on past it towards 0.97 could fall back under it before its budget ran out (2 of 53
# fresh Touch seeds did, docs/training.md).
FAST = TrainConfig(
    num_timesteps=10_000_000,
    num_envs=8192,
    unroll_length=10,
    batch_size=256,
    num_minibatches=32,
    num_updates_per_batch=4,
    learning_rate=1e-3,
    discounting=0.97,
    entropy_cost=1e-3,
    num_evals=21,
    num_eval_envs=1024,
    stop_at_success=0.95,
)

# A small CPU run: the README's main job and the CI learning test (Reach); Touch takes a larger
# batch and budget (its Task.budgets).
CPU = TrainConfig(
    num_timesteps=300_000,
    num_envs=64,
    unroll_length=10,
    batch_size=64,
    num_minibatches=8,
    num_updates_per_batch=4,
    learning_rate=1e-3,
    discounting=0.97,
    num_evals=6,
    num_eval_envs=64,
)

# ``fast`` trained under a randomisation chosen by measurement, per task (Task.budgets):
# Touch under :data:`mjx_arm.envs.physics_config.LATENCY`, Lift under ``SELECTED`` (why: see
# there). Evaluation during training stays nominal. Its own preset, beside ``fast`` rather than
# in it: it costs more than the 1.5x of ``fast``'s steps to solve that a default may cost
# (Touch about 2.4x, Lift about 1.6x; docs/robustness.md). Reach takes LATENCY, not measured.
# It stops at 0.97, as measured in docs/robustness.md.
ROBUST_FAST = FAST.replace(randomization=LATENCY, stop_at_success=0.97)

PRESETS = {"seed": SEED, "fast": FAST, "cpu": CPU, "robust": ROBUST_FAST}
assert tuple(PRESETS) == PRESET_NAMES

# Presets that stop a run at the first evaluation at the task's ``solved_at`` (a task's budget
# may still name its own ``stop_at_success``).
STOPS_WHEN_SOLVED = ("fast",)

# The task variant a preset picks (the task's default variant elsewhere).
PRESET_VARIANTS = {"seed": "seed"}

# The training draws a task's budget names (mjx_arm.task.spec.Budget.randomization).
RANDOMIZATIONS = {"latency": LATENCY, "selected": SELECTED}


def preset_config(name: str, task: str | None = None, variant: str | None = None) -> TrainConfig:
    """Preset ``name`` for ``task`` (default: the preset's own task), with the task's budget
    for that preset (:attr:`mjx_arm.task.spec.Task.budgets`), its stop at the task's
    ``solved_at`` (:data:`STOPS_WHEN_SOLVED`), its default arm and its preset of ``variant``
    (None: the variant the preset picks, else the task's default).

    Raises:
        ConfigError: an unknown preset or task, or a variant the task does not have.
    """
    if name not in PRESETS:
        raise ConfigError(f"unknown preset {name!r}; choose one of {sorted(PRESETS)}")
    config = PRESETS[name]
    task = task or config.task
    if not is_task(task):
        raise ConfigError(f"task must be one of {list(task_names())}, got {task!r}")
    spec = get_task(task)
    budget = spec.budgets.get(name)
    changes = budget.changes() if budget else {}
    if name in STOPS_WHEN_SOLVED:
        changes.setdefault("stop_at_success", spec.solved_at)
    if "randomization" in changes:
        changes["randomization"] = _randomization(changes["randomization"])
    if "force_scale" in changes:
        scale = changes.pop("force_scale")
        changes["normalizer"] = dataclasses.replace(config.normalizer, force_scale=scale)
    if spec.default_arm:
        changes["arm"] = ArmConfig(urdf=str(asset(spec.default_arm)))
    task_fields = dict(changes.pop("task", {}))
    variant = variant or PRESET_VARIANTS.get(name)
    settings = task_changes(task, None, {"variant": variant, **task_fields})
    return config.replace(task=task, task_settings=settings, **changes)


def _randomization(name: str) -> RandomizationConfig:
    if name not in RANDOMIZATIONS:
        raise ConfigError(f"unknown randomization {name!r}; choose one of {list(RANDOMIZATIONS)}")
    return RANDOMIZATIONS[name]


def _named(data: dict[str, Any], overrides: list[str], key: str) -> str | None:
    """The value of ``key`` (``task`` or ``task.variant``) a config file or the overrides name
    (the last override wins), or None."""
    value = data.get(key)
    for item in overrides:
        name, _, text = item.partition("=")
        if name.strip() == key:
            value = text.strip()
    if value is not None and not isinstance(value, str):
        what = key.rpartition(".")[2]  # task or variant
        raise ConfigError(f"{key} must be a {what}'s name (a string), not {type(value).__name__}")
    return value


def load_config(
    preset: str = "seed", file: str | Path | None = None, overrides: list[str] | None = None
) -> TrainConfig:
    """Resolve a config: the preset for the task named (:func:`preset_config`), then a JSON
    file, then ``--set`` overrides.

    Raises:
        InputError: the file cannot be read, or a field (of the file or an override) is
            unknown, of the wrong type or out of range; the message names the file or item.
    """
    data: dict[str, Any] = {}
    if file is not None:
        data = read_json_object(file, "config file")
        data = data.get("train", data)
        if not isinstance(data, dict):
            raise ConfigError(f"config file {str(file)!r}: 'train' must be a table of fields")
    overrides = overrides or []
    variant = _named({}, overrides, "task.variant")
    config = preset_config(preset, _named(data, overrides, "task"), variant)
    if file is not None:
        config = _merge_file(config, data, file)
    config = apply_overrides(config, overrides)
    config.validate()
    return config


def _merge_file(config: TrainConfig, data: dict[str, Any], file: str | Path) -> TrainConfig:
    """``config`` with the fields of a config file (sections merged field by field; the
    file's ``task_settings`` are changes to the preset's, its ``task_overrides`` changes to
    the task's default preset, as before ``task_settings`` existed)."""
    merged = config.to_dict()
    if "task_settings" in data and "task_overrides" in data:
        raise ConfigError(f"config file {str(file)!r}: give task_settings or task_overrides")
    for key, value in data.items():
        if key in SECTIONS and isinstance(value, dict):
            merged[key] = {**merged[key], **value}
        elif key == "task_settings":
            merged["task_overrides"] = value
        elif key == "task_overrides":
            merged.pop("task_settings")
            merged[key] = value
        else:
            merged[key] = value
    try:
        return TrainConfig.from_dict(merged)
    except ConfigError as err:
        raise ConfigError(f"config file {str(file)!r}: {err}") from err
