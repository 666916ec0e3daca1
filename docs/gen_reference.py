"""Tables of each task's settings and each training preset, generated from the code.

The task pages include these (``docs/generated/``), so the numbers they show are the ones
``mjx_arm.task`` and ``mjx_arm.train.config`` hold, not a copy. Run by ``docs/conf.py``.
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path
from typing import Any

from mjx_arm.inputs import ConfigError
from mjx_arm.task import get_task, task_names
from mjx_arm.task.observation import obs_layout
from mjx_arm.train.presets import PRESETS, preset_config

TASK_FIELDS = (
    "ctrl_dt", "sim_dt", "action_scale", "episode_steps", "success_distance", "force_band",
    "success_hold_steps", "fail_on_overforce", "pay_after_overforce", "terminate_on_overforce",
    "strike_force", "target_low", "target_high", "init_noise", "variant",
)  # fmt: skip
TRAIN_FIELDS = (
    "num_timesteps", "num_envs", "unroll_length", "batch_size", "num_minibatches",
    "num_updates_per_batch", "learning_rate", "discounting", "entropy_cost", "num_evals",
    "num_eval_envs", "stop_at_success", "normalizer.force_scale",
)  # fmt: skip


def _cell(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, tuple):
        return "(" + ", ".join(_cell(v) for v in value) + ")"
    return str(value)


def task_table(name: str, **overrides: Any) -> str:
    """The settings and nonzero reward weights of task ``name``'s preset, as markdown."""
    cfg = get_task(name).config(**overrides)
    rows = [f"| `{f}` | {_cell(getattr(cfg, f))} |" for f in TASK_FIELDS]
    terms = cfg.reward.term_names()
    weights = [f"| `reward.{t}` | {_cell(getattr(cfg.reward, t))} |" for t in terms
               if getattr(cfg.reward, t)]  # fmt: skip
    lengths = [
        f"| `reward.{f.name}` | {_cell(getattr(cfg.reward, f.name))} |"
        for f in dataclasses.fields(cfg.reward)
        if f.name not in terms
    ]
    return "\n".join(["| setting | value |", "|---|---|", *rows, *weights, *lengths, ""])


def obs_table(name: str, n_joints: int = 6) -> str:
    """The flat observation's layout of task ``name`` for an arm of ``n_joints``."""
    layout = obs_layout(n_joints, get_task(name).extra_obs)
    rows, start = [], 0
    for key, size in layout:
        rows.append(f"| `{key}` | {size} | {start}-{start + size - 1} |")
        start += size
    return "\n".join(["| key | size | flat indices |", "|---|---|---|", *rows,
                      f"| total | {start} | |", ""])  # fmt: skip


def _setting(config: Any, name: str) -> Any:
    """A config's field by its ``--set`` name (``normalizer.force_scale``: a section's field)."""
    return functools.reduce(getattr, name.split("."), config)


def preset_table(task: str) -> str:
    """Each training preset's settings for ``task``, as markdown."""
    configs = {}
    for name in PRESETS:
        try:
            configs[name] = preset_config(name, task)
        except ConfigError:  # a preset whose task variant the task lacks (seed: Lift)
            continue
    head = "| setting | " + " | ".join(f"`{n}`" for n in configs) + " |"
    rows = [
        f"| `{f}` | " + " | ".join(_cell(_setting(c, f)) for c in configs.values()) + " |"
        for f in TRAIN_FIELDS
    ]
    variants = [_cell(c.task_config().variant) for c in configs.values()]
    rows.append("| task variant | " + " | ".join(variants) + " |")
    budgets = get_task(task).budgets.values()
    for field in sorted({f for b in budgets for f in (b.task or {})}):  # task fields of a preset
        cells = [_cell(getattr(c.task_config(), field)) for c in configs.values()]
        rows.append(f"| `task.{field}` | " + " | ".join(cells) + " |")
    return "\n".join([head, "|---|" + "---|" * len(configs), *rows, ""])


def generate(out: Path) -> list[Path]:
    """Write ``TASK_settings.md``, ``TASK_obs.md`` and ``TASK_presets.md`` for every
    built-in task (and Touch's seed variant) into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    pages = {}
    for name in ("reach", "touch", "lift"):
        pages[f"{name}_settings.md"] = task_table(name)
        pages[f"{name}_obs.md"] = obs_table(name)
        pages[f"{name}_presets.md"] = preset_table(name)
    pages["touch_seed_settings.md"] = task_table("touch", variant="seed")
    assert set(task_names()) >= {"reach", "touch", "lift"}
    written = []
    for file, text in pages.items():
        path = out / file
        if not path.is_file() or path.read_text() != text:
            path.write_text(text)
        written.append(path)
    return written
