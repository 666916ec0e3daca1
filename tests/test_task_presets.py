"""Every preset of every task resolves to the numbers it shipped with.

``tests/data/preset_configs.json`` holds ``preset_config(preset, task).to_dict()``, its task config
and each task variant's config as they were while budgets sat in a ``(preset, task)`` table of
the training config, reward weights in one list for every task and task settings in an untyped
``task_overrides`` dict. Since then a task declares its budgets, reward terms and scene in its
own file and the settings are a typed ``TaskConfig``: every number must be the same. The only
keys allowed to go are reward weights of terms a task no longer carries, and only at weight 0;
the only keys allowed to come are task fields added since, at their "from the arm" default
(:data:`ADDED_FIELDS`), training fields added since, at their default
(:data:`ADDED_TRAIN_FIELDS`, :data:`ADDED_NORMALIZER_FIELDS`), and reward terms added since, at
weight 0.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from mjx_arm.inputs import ConfigError
from mjx_arm.task import task_config
from mjx_arm.task.registry import get_task
from mjx_arm.train.config import TrainConfig
from mjx_arm.train.presets import PRESETS, preset_config

REPO = Path(__file__).resolve().parents[1].as_posix()
SNAPSHOT = json.loads((Path(__file__).parent / "data" / "preset_configs.json").read_text())
CASES = sorted(SNAPSHOT["train"])


def _json(value):
    """``value`` as JSON reads it back (tuples become lists)."""
    return json.loads(json.dumps(value))


def _portable(value):
    """:func:`_json` with paths inside the repository relative to it (the snapshot's are)."""
    return json.loads(json.dumps(value).replace(f"{REPO}/", ""))


# Task config fields added after the snapshot, with the value every preset leaves them at.
ADDED_FIELDS = {"object_scale": 0.0, "grasp_closure": 0.0, "pay_after_overforce": True}
# Training config fields added after the snapshot, with the value every preset leaves them at.
ADDED_TRAIN_FIELDS = {
    "policy_distribution": "tanh_normal",
    "kl_stop": 0.0,
    "eval_from_step": 0,
    "eval_gate": 0.0,
    "clip_per_network": False,
    "devices_lr_power": 0.0,
    "devices_clip": 0.0,
}
# ... and inside its ``normalizer`` section.
ADDED_NORMALIZER_FIELDS = {"after_update": False, "force_scale": 0.0}
# Presets changed on purpose since the snapshot, case -> normaliser fields: Touch's ``fast`` and
# ``cpu`` divide the wrist wrench by 50 N (measured on fresh seeds, docs/training.md).
CHANGED_NORMALIZER_FIELDS = {
    "fast/touch": {"force_scale": 50.0},
    "cpu/touch": {"force_scale": 50.0},
}
# Training defaults changed on purpose since the snapshot, in every case: ``--devices N`` splits
# the preset's batch over the GPUs instead of growing it (measured on two H200s,
# docs/training.md, "Several devices").
CHANGED_TRAIN_DEFAULTS = {"scale_with_devices": False}
# ... case -> training fields: ``fast`` stops at the task's ``solved_at`` instead of 0.97, so that a
# run ends on the evaluation that solved it (docs/training.md).
CHANGED_TRAIN_FIELDS = {
    "fast/reach": {"stop_at_success": 0.95},
    "fast/touch": {"stop_at_success": 0.95, "eval_from_step": 5_000_000},
    "fast/lift": {"stop_at_success": 0.9, "eval_from_step": 3_000_000, "eval_gate": 0.01},
}
# ... case -> task config fields: Touch's ``fast`` and ``cpu`` stop paying a press once a reading
# over the band rules success out (docs/training.md).
CHANGED_TASK_FIELDS = {
    "fast/touch": {"pay_after_overforce": False},
    "cpu/touch": {"pay_after_overforce": False},
}


def _drop_zero_terms(before: dict, after: dict) -> dict:
    """``before`` (a task config's dict) without the reward weights ``after`` lacks, each of
    them 0, with the reward terms added since at weight 0 (``strike``), and with
    :data:`ADDED_FIELDS` at their defaults where ``after`` has them."""
    dropped = {k: v for k, v in before["reward"].items() if k not in after["reward"]}
    assert all(v == 0 for v in dropped.values()), dropped
    added = {k: v for k, v in ADDED_FIELDS.items() if k in after and k not in before}
    reward = {k: v for k, v in before["reward"].items() if k not in dropped}
    new_terms = {k: 0.0 for k in after["reward"] if k not in before["reward"]}
    return {**before, **added, "reward": {**reward, **new_terms}}


def test_the_snapshot_covers_every_preset_and_shipped_task() -> None:
    assert {case.split("/")[0] for case in CASES} == set(PRESETS)
    assert {case.split("/")[1] for case in CASES} == {"reach", "touch", "lift"}


@pytest.mark.parametrize("case", CASES)
def test_preset_resolves_to_the_shipped_numbers(case: str) -> None:
    preset, task = case.split("/")
    before_train, before_task = SNAPSHOT["train"][case], SNAPSHOT["task"][case]
    if before_task == "ConfigError":  # the seed preset's variant is not one of Lift's
        with pytest.raises(ConfigError, match="unknown lift variant 'seed'"):
            preset_config(preset, task)
        return
    after = _portable(preset_config(preset, task).to_dict())
    settings = after.pop("task_settings")
    before = {k: v for k, v in before_train.items() if k != "task_overrides"}
    changed = CHANGED_NORMALIZER_FIELDS.get(case, {})
    normalizer = {**before["normalizer"], **ADDED_NORMALIZER_FIELDS, **changed}
    expected = {**before, **ADDED_TRAIN_FIELDS, **CHANGED_TRAIN_DEFAULTS}
    expected.update(CHANGED_TRAIN_FIELDS.get(case, {}))
    assert after == {**expected, "normalizer": normalizer}
    assert settings == {
        **_drop_zero_terms(before_task, settings),
        **CHANGED_TASK_FIELDS.get(case, {}),
    }


@pytest.mark.parametrize("case", CASES)
def test_a_config_saved_with_task_overrides_reads_as_it_did(case: str) -> None:
    """A run directory written before ``task_settings`` stored ``task_overrides``: it loads
    with the same task config."""
    before_train, before_task = SNAPSHOT["train"][case], SNAPSHOT["task"][case]
    if before_task == "ConfigError":
        with pytest.raises(ConfigError, match="unknown lift variant 'seed'"):
            TrainConfig.from_dict(before_train)
        return
    loaded = _portable(TrainConfig.from_dict(before_train).task_config().to_dict())
    assert loaded == _drop_zero_terms(before_task, loaded)


@pytest.mark.parametrize("case", sorted(SNAPSHOT["variants"]))
def test_each_task_variant_keeps_its_numbers(case: str) -> None:
    task, variant = case.split("/")
    after = _portable(task_config(task, variant=variant).to_dict())
    assert after == _drop_zero_terms(SNAPSHOT["variants"][case], after)


def test_settings_round_trip_through_a_saved_config() -> None:
    """A run saves the whole typed task config and reads back an equal one."""
    config = preset_config("fast", "lift")
    assert TrainConfig.from_dict(_json(config.to_dict())) == config
    assert TrainConfig.from_dict(_json(config.to_dict())).task_config().reward.lift == 20.0


# The ``--set`` examples of README.md, docs/commands.md and the task pages.
DOCUMENTED = [
    ("cpu", ["task=touch", "num_envs=256", "task.action_scale=0.2",
             "task.reward.approach_speed=-50", "physics.impl=jax", "randomization.enabled=true"]),
    ("fast", ["task=touch", "task.variant=seed"]),
    ("fast", ["task=touch", "task.variant=gentle"]),
    ("fast", ["task=lift", "task.variant=soft"]),
    ("seed", ["task=lift", "task.variant=gentle"]),
]  # fmt: skip


@pytest.mark.parametrize(("preset", "items"), DOCUMENTED)
def test_documented_task_settings_work(preset: str, items: list[str]) -> None:
    """Each documented ``--set task.*`` lands in the typed task settings, on top of the preset
    of the variant it names, and survives a save and load."""
    from mjx_arm.train.presets import load_config

    config = load_config(preset, None, items)
    settings = config.task_config()
    task = items[0].partition("=")[2]
    variant = next((i.partition("=")[2] for i in items if i.startswith("task.variant=")), None)
    expected = task_config(task, **({"variant": variant} if variant else {}))
    budget = get_task(task).budgets.get(preset)
    expected = expected.replace(**((budget and budget.task) or {}))  # the preset's own
    if "task.action_scale=0.2" in items:
        expected = expected.replace(action_scale=0.2, reward={"approach_speed": -50.0})
    assert settings == expected
    assert TrainConfig.from_dict(_json(config.to_dict())) == config


def test_task_settings_refuse_what_the_task_lacks() -> None:
    """A reward term of another task, an unknown field and a foreign variant are errors."""
    from mjx_arm.train.presets import load_config

    with pytest.raises(ConfigError, match=r"unknown reward key 'task\.reward\.lift'"):
        load_config("fast", None, ["task=touch", "task.reward.lift=1"])
    lift = load_config("fast", None, ["task=lift", "task.reward.lift=1"])
    assert lift.task_config().reward.lift == 1
    with pytest.raises(ConfigError, match="unknown task key"):
        load_config("fast", None, ["task.no_such=1"])
    with pytest.raises(ConfigError, match="unknown touch variant"):
        load_config("fast", None, ["task=touch", "task.variant=soft"])


@pytest.mark.parametrize("case", ["fast/reach", "cpu/touch", "fast/lift"])
def test_a_task_config_saved_with_every_terms_weight_loads(case: str) -> None:
    """A run's or a policy's task config saved while every task carried Lift's four weights
    (at 0 outside Lift) loads as the task's config of today."""
    from mjx_arm.task.config import TaskConfig

    preset, task = case.split("/")
    saved = SNAPSHOT["task"][case]
    changed = CHANGED_TASK_FIELDS.get(case, {})  # the preset's, since the snapshot
    assert (
        TaskConfig.from_dict(saved).replace(**changed) == preset_config(preset, task).task_config()
    )
    if task != "lift":
        assert "lift" in saved["reward"]
        with pytest.raises(ConfigError, match="unknown reward keys"):
            TaskConfig.from_dict({**saved, "reward": {**saved["reward"], "lift": 1.0}})


def test_a_presets_task_fields_apply_to_any_variant_and_yield_to_set() -> None:
    """Touch's ``fast`` sets ``pay_after_overforce=false`` (its ``Budget.task``) on whichever
    variant the run picks; ``--set task.pay_after_overforce=true`` takes it back; presets that
    set no task field keep the variant's value."""
    from mjx_arm.train.presets import load_config

    def pays(preset: str, *items: str) -> bool:
        return load_config(preset, None, ["task=touch", *items]).task_config().pay_after_overforce

    assert not pays("fast") and not pays("fast", "task.variant=seed") and not pays("cpu")
    assert pays("fast", "task.pay_after_overforce=true")
    assert pays("robust") and pays("seed")


@pytest.mark.parametrize("task", ["reach", "touch", "lift"])
def test_fast_stops_where_its_task_counts_as_solved(task: str) -> None:
    """``fast`` ends a run at its first evaluation at the task's ``solved_at`` (Lift 0.9, the
    others 0.95), so its last evaluation is the one that solved it; ``robust`` keeps 0.97."""
    solved_at = get_task(task).solved_at
    assert solved_at == (0.9 if task == "lift" else 0.95)
    assert preset_config("fast", task).stop_at_success == solved_at
    assert preset_config("robust", task).stop_at_success == 0.97
