"""The lines ``mjx-arm train`` prints around a run: where it goes, what a preset or a device
count will cost before it starts, and how it ended."""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from mjx_arm.train.config import TrainConfig

# Env steps per second the cpu preset trains at on a 2-core CPU on the C MuJoCo backend
# (benchmarks/results/seeds/seeds_reach_cpu_c_backend.json: 2,008 for Reach); a GPU preset's
# larger networks and epochs are not faster.
CPU_STEPS_PER_S = 2000


def end_lines(result, run_dir: Path, quiet: bool) -> None:
    """The lines a run ends with: the done line, then the compile line where ``quiet`` kept it
    from coming after the first epoch, else where the compile report is (once is enough)."""
    print(done_line(result))
    print(result.compile_summary if quiet else f"compile report: {run_dir / 'compile.json'}")


def start_lines(run_dir: Path, config: TrainConfig, preset: str | None) -> None:
    """The lines a run starts with: its folder, and, before a GPU preset trains on a CPU, how
    long it would take at the CPU rate measured (:data:`CPU_STEPS_PER_S`) and what to run
    instead, on stderr (not for the cpu preset, a resumed run: ``preset`` None, or on an
    accelerator)."""
    import jax

    print(f"run directory: {run_dir}")
    if preset in (None, "cpu") or jax.default_backend() != "cpu":
        return
    minutes = config.num_timesteps / CPU_STEPS_PER_S / 60
    print(
        f"note: preset {preset} is meant for a GPU: {config.num_envs:,} envs, "
        f"{config.num_timesteps:,} env steps. On a 2-core CPU the cpu preset trains about "
        f"{CPU_STEPS_PER_S:,} env steps/s, so this run would take {minutes:.0f} min or more, "
        "plus compiling. For a CPU: --preset cpu --backend mujoco (Reach in about 2 min)",
        file=sys.stderr,
    )


def devices_note(devices: int | None, config: TrainConfig) -> None:
    """Before a run on several devices, say on stderr what was measured: the preset's batch
    split over them trains no sooner than one GPU, a batch grown with them later still."""
    if not devices or devices < 2:
        return
    if config.scale_with_devices:
        what = (
            f"grows the batch {devices} times: more env steps/s, but Touch seeds on 2 H200s "
            "needed 2-2.6x the env steps and reached 0.95 later than on one GPU"
        )
    else:
        what = (
            f"splits the batch over {devices} devices: the run learns as on one, and Touch "
            "seeds on 2 H200s reached 0.95 in about one GPU's time, not sooner"
        )
    print(
        f"note: --devices {devices} {what} (docs/training.md, 'Several devices'). For more "
        "results at once, train a seed per GPU: mjx-arm bench seeds",
        file=sys.stderr,
    )


def done_line(result) -> str:
    """The closing line of a run. Compile time and steady speed need two trained epochs after
    the first evaluation; a shorter run says so instead of printing NaN."""
    success = result.metrics.get("eval/episode_success", float("nan"))
    if math.isfinite(result.compile_seconds) and math.isfinite(result.steps_per_second):
        speed = f"compile {result.compile_seconds:.1f} s, {result.steps_per_second:,.0f} steps/s"
    else:
        speed = "compile time and steps/s need 3 or more evaluations"
    evals = f"last eval success {success:.3f} at step {result.steps:,}"
    if not math.isfinite(success):  # stopped before eval_from_step
        evals = f"no evaluation by step {result.steps:,} (eval_from_step)"
    if result.best is not None:
        best, step = result.best
        evals += f", best {best:.3f} at step {step:,}"
    return f"done: {result.steps:,} steps in {result.train_seconds:.1f} s ({speed}); {evals}"
