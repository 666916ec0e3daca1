"""A run's task settings: the typed :class:`~mjx_arm.task.config.TaskConfig` a training config
holds (``TrainConfig.task_settings``), and the ``--set task.FIELD=VALUE`` changes to it.

A change names a field of the task config (``task.action_scale=0.2``), a weight of the task's
reward (``task.reward.approach_speed=-50``; the terms are the task's own,
:attr:`mjx_arm.task.spec.Task.reward_type`) or the preset's variant (``task.variant=seed``, which
starts from that variant's preset). Values are read as JSON where they parse (a list becomes the
field's tuple), else as text.
"""

from __future__ import annotations

import dataclasses
import json
from typing import Any

from mjx_arm.inputs import ConfigError
from mjx_arm.task.config import RewardConfig, TaskConfig, task_config
from mjx_arm.task.registry import get_task, is_task


def task_changes(task: str, settings: TaskConfig | None, changes: dict[str, Any]) -> TaskConfig:
    """``settings`` (None: the task's preset) with ``changes`` to its fields; a ``variant``
    among them other than the settings' starts from that variant's preset, and ``reward``
    takes a dict of weights.

    Raises:
        ConfigError: a change that is not a task field, or of the wrong type or range; a
            variant the task does not have.
    """
    changes = dict(changes)
    variant = changes.pop("variant", None)
    try:
        if settings is None or settings.task != task or variant not in (None, settings.variant):
            settings = task_config(task, **({"variant": variant} if variant else {}))
        return settings.replace(**changes)
    except ConfigError as err:
        raise ConfigError(f"task settings: {err}") from err
    except (TypeError, ValueError) as err:  # an unknown field, a bad variant
        shown = {**({"variant": variant} if variant else {}), **changes}
        raise ConfigError(f"task settings {shown}: {err}") from err


def set_task_field(changes: dict[str, Any], name: str, text: str, task: str) -> None:
    """Put ``task.NAME=text`` into ``changes`` (``reward.TERM`` into its ``reward`` dict;
    the terms are those of ``task``).

    Raises:
        ConfigError: NAME is not a field of the task config or of the task's reward.
    """
    try:
        value = json.loads(text)
    except json.JSONDecodeError:
        value = text
    head, dot, term = name.partition(".")
    if dot and head == "reward":
        kind = get_task(task).reward_type if is_task(task) else RewardConfig
        terms = {f.name for f in dataclasses.fields(kind)}
        if term not in terms:
            raise ConfigError(f"unknown reward key 'task.{name}'; known: {sorted(terms)}")
        changes["reward"] = {**changes.get("reward", {}), term: value}
        return
    fields = {f.name for f in dataclasses.fields(TaskConfig)}
    if name not in fields:
        raise ConfigError(f"unknown task key 'task.{name}'; known: {sorted(fields)}")
    changes[name] = value
