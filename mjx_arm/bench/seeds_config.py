"""The seeds benchmark's settings and the record of one seed (:mod:`mjx_arm.bench.seeds`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from mjx_arm.bench.settings import setting
from mjx_arm.inputs import MAX_SEED, ConfigError
from mjx_arm.names import BACKENDS, PRESET_NAMES
from mjx_arm.settings import check_range
from mjx_arm.task.registry import get_task, task_names


def parse_seeds(text: str) -> tuple[int, ...]:
    """Seeds from ``"0-9"``, ``"0,3,7"`` or a mix (``"0-2,5"``); ranges are inclusive.

    Raises:
        ConfigError: an empty list (or over 1000 seeds), a negative seed, a reversed range or
            a repeated seed.
    """
    seeds: list[int] = []
    for part in filter(None, (p.strip() for p in text.split(","))):
        low, dash, high = part.partition("-")
        try:
            first, last = int(low), int(high) if dash else int(low)
        except ValueError:
            raise ConfigError(f"not a seed or range: {part!r} (use e.g. 0-9 or 0,3,7)") from None
        if first < 0 or last < first or last > MAX_SEED:
            raise ConfigError(f"bad seed range {part!r}: seeds are >= 0, low-high with low <= high")
        seeds.extend(range(first, last + 1))
    if not seeds or len(seeds) > 1000:
        raise ConfigError(f"give 1 to 1000 seeds, got {len(seeds)} ({text!r})")
    if len(set(seeds)) != len(seeds):
        raise ConfigError(f"a seed is listed twice: {text!r}")
    return tuple(seeds)


@dataclass(frozen=True)
class SeedsConfig:
    """Settings of ``mjx-arm bench seeds`` (each field is a flag)."""

    task: str = setting("touch", "task to train", task_names())
    preset: str = setting("fast", "training preset, as shipped", PRESET_NAMES)
    seeds: str = setting("0-9", "seeds: a range 0-9, a list 0,3,7 or both")
    backend: str = setting("auto", "physics backend", BACKENDS)
    threshold: float = setting(
        0.0,
        "evaluation success that counts as solved (0: the task's own, where its fast preset "
        "stops: 0.95, Lift 0.9)",
    )
    devices: int = setting(
        0,
        "GPUs to train on, one seed per GPU at a time, each in its own process (0: all); "
        "on a CPU: local devices of each seed's run",
    )
    gpus_per_seed: int = setting(
        1,
        "GPUs each seed trains on (train --devices N: a process per GPU, the batch split over "
        "them); --devices then counts GPUs in all, in groups of this size",
    )
    arm: str = setting("", "the arm: a URDF or an arm file (.toml/.json); '' is the shipped arm")
    deterministic: bool = setting(
        False, "train each seed deterministically (train --deterministic): a seed repeats"
    )
    server: bool = setting(
        False,
        "train each seed's command with train --server, in a warm trainer per GPU (mjx-arm "
        "serve) that keeps the envs and programs between seeds; on a CPU, kept in this process",
    )

    def __post_init__(self) -> None:
        check_range(self, "threshold", low=0, high=1)
        if not self.threshold and self.task in task_names():
            object.__setattr__(self, "threshold", get_task(self.task).solved_at)
        check_range(self, "devices", low=0)
        check_range(self, "gpus_per_seed", low=1, high=64)
        parse_seeds(self.seeds)


@dataclass
class SeedRun:
    """One seed's result (times in seconds from that seed's own start)."""

    seed: int
    final_success: float
    best_success: float
    steps_to_threshold: int | None
    time_to_threshold: float | None
    total_steps: int
    wall_s: float
    compile_s: float
    training_steps_per_s: float
    curve: list[tuple[float, int, float]]  # (seconds, step, success) at each evaluation
    # where the start-up's seconds went (mjx_arm.train.compile_report: stages, JAX counts)
    compile_report: dict[str, Any] = dataclasses.field(default_factory=dict)
    gpu: str = ""  # the GPU of the seed's process ("" where it trained in this process)
    error: str = ""  # why the seed's process failed ("" where it ran to its end)
    # whether the seed started after another seed of its benchmark had ended (so the caches
    # were filled); None in records from before this field (then all but the first are warm)
    warm: bool | None = None

    @property
    def solved(self) -> bool:
        return self.time_to_threshold is not None

    @property
    def last_success(self) -> float:
        """The success of the run's last evaluation (NaN without one)."""
        return self.curve[-1][2] if self.curve else float("nan")

    def collapsed(self, threshold: float) -> bool:
        """Whether the run reached ``threshold`` and its last evaluation fell below it."""
        return self.best_success >= threshold and not self.last_success >= threshold
