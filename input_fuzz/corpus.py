"""Good inputs of every kind the commands read, built in seconds without training.

:func:`build` writes into a folder: the shipped arm's URDF and an arm file for it, a training
config file, a run directory with one checkpoint (params of small networks in Brax's layout,
saved by the project's own checkpoint writer, and its transitions), the policy exported from it
(``.npz``, and ``.onnx`` where onnx is installed), a trajectory file, and the arm's URDF with an
OBJ mesh (its material library and texture beside it). Each is what the real
pipeline writes, so a mutation of it is a realistic bad input, and the unmutated file must pass.
"""

from __future__ import annotations

import itertools
import json
import shutil
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

# Small networks: a checkpoint of a few kB, an export in milliseconds.
HIDDEN = (16, 16)
CHECKPOINT_STEP = 10_240
TRAJECTORY_STEPS = 30
TRAIN_SETTINGS = {
    "task": "reach",
    "backend": "mujoco",
    "num_timesteps": 20_480,
    "num_evals": 2,
    "policy_hidden": list(HIDDEN),
    "value_hidden": list(HIDDEN),
}


@dataclass(frozen=True)
class Corpus:
    """Paths of the good inputs (see the module docstring); ``onnx`` is None without onnx."""

    folder: Path
    urdf: Path
    arm_file: Path
    arm_json: Path
    config: Path
    run_dir: Path
    policy: Path
    onnx: Path | None
    trajectory: Path
    mesh: Path

    def files(self) -> dict[str, Path]:
        """Kind -> path of each good input file (the run directory not included)."""
        kinds = {
            "urdf": self.urdf,
            "arm_file": self.arm_file,
            "arm_json": self.arm_json,
            "config": self.config,
            "policy": self.policy,
            "trajectory": self.trajectory,
            "mesh": self.mesh,
        }
        return {**kinds, **({"onnx": self.onnx} if self.onnx else {})}


def build(folder: Path) -> Corpus:
    """Write every good input into ``folder`` (created) and return their paths."""
    from input_fuzz.hostile_mesh import write_urdf
    from mjx_arm.arm.report import arm_file_text
    from mjx_arm.paths import default_arm_urdf
    from mjx_arm.policy.export import export_run

    folder.mkdir(parents=True, exist_ok=True)
    urdf = folder / "arm.urdf"
    shutil.copy(default_arm_urdf(), urdf)
    arm = _arm()
    arm_file = folder / "arm.toml"
    arm_file.write_text(arm_file_text(arm).replace(str(arm.urdf), str(urdf.resolve())))
    arm_json = folder / "arm.json"
    arm_json.write_text(json.dumps(tomllib.loads(arm_file.read_text()), indent=2))
    config = folder / "train.json"
    config.write_text(json.dumps(TRAIN_SETTINGS, indent=2))
    run_dir = write_run(folder / "run", arm)
    policy = export_run(run_dir, folder / "policy.npz")
    onnx = export_run(run_dir, folder / "policy.onnx") if _have_onnx() else None
    trajectory = write_trajectory(folder / "trajectory.npz", arm)
    mesh = folder / "mesh_arm.urdf"
    write_urdf(urdf, mesh, "obj")
    return Corpus(folder, urdf, arm_file, arm_json, config, run_dir, policy, onnx, trajectory, mesh)


def _arm():
    from mjx_arm.arm.info import arm_info

    return arm_info()


def _have_onnx() -> bool:
    import importlib.util

    return all(importlib.util.find_spec(m) is not None for m in ("onnx", "onnxruntime"))


def _task(arm):
    from mjx_arm.task.config import task_config

    return task_config("reach").for_arm(tuple(arm.home_qpos), arm.reach_scale)


def write_run(run_dir: Path, arm) -> Path:
    """A run directory as ``mjx-arm train`` leaves it after its first checkpoint."""
    from mjx_arm.arm.info import arm_record
    from mjx_arm.train.presets import load_config
    from mjx_arm.train.rundir import RunDir

    settings = [f"{k}={v}" for k, v in TRAIN_SETTINGS.items() if not isinstance(v, list)]
    hidden = ",".join(map(str, HIDDEN))
    config = load_config("cpu", None, [*settings, f"policy_hidden={hidden}"])
    config = config.replace(value_hidden=HIDDEN)
    task = _task(arm)
    run = RunDir(run_dir)
    run.save_config({"train": config.to_dict(), "task": task.to_dict(), "arm": arm_record(arm)})
    obs, actions = 16 + arm.n_joints, arm.n_joints
    params = brax_params(obs, actions, np.random.default_rng(0))
    run.save_checkpoint(CHECKPOINT_STEP, params, {"task": "reach"}, trajectory_rows(arm))
    run.log_metrics(CHECKPOINT_STEP, {"eval/episode_success": 0.5})
    run.close()  # TensorBoard's writer flushes from a thread of its own until it is closed
    return run_dir


def brax_params(obs: int, actions: int, rng: np.random.Generator) -> tuple:
    """(normaliser, policy, value) params in Brax PPO's layout, small random weights."""

    def mlp(outputs: int) -> dict[str, Any]:
        sizes = (obs, *HIDDEN, outputs)
        layers = {
            f"hidden_{i}": {
                "kernel": rng.normal(0.0, 0.3, (a, b)).astype(np.float32),
                "bias": np.zeros(b, np.float32),
            }
            for i, (a, b) in enumerate(itertools.pairwise(sizes))
        }
        return {"params": layers}

    normaliser = {
        "mean": np.zeros(obs, np.float32),
        "std": np.ones(obs, np.float32),
        "summed_variance": np.full(obs, 100.0, np.float32),
        "count": np.array(100.0, np.float32),
        "std_eps": np.array(0.0, np.float32),
    }
    return normaliser, mlp(2 * actions), mlp(1)


def trajectory_rows(arm, steps: int = TRAJECTORY_STEPS) -> dict[str, np.ndarray]:
    """A plausible trajectory: the arm at home, a target, a reward rising then dropping."""
    from mjx_arm.task.observation import obs_slices

    n = arm.n_joints
    obs = np.zeros((steps, 16 + n), np.float32)
    s = obs_slices(n)
    obs[:, s["joint_angles"]] = np.asarray(arm.home_qpos, np.float32)
    obs[:, s["target_rel"]] = (0.5, 0.1, 0.3)
    reward = -np.abs(np.sin(np.linspace(0.0, 3.0, steps))).astype(np.float32)
    return {
        "obs": obs,
        "action": np.zeros((steps, n), np.float32),
        "reward": reward,
        "done": np.zeros(steps, np.float32),
        "ee_pos": np.tile(np.float32([0.45, 0.1, 0.35]), (steps, 1)),
        "contact_force": np.zeros(steps, np.float32),
    }


def write_trajectory(path: Path, arm) -> Path:
    """A trajectory file as ``mjx-arm eval --trajectory`` writes it."""
    from mjx_arm.replay import save_trajectory

    return save_trajectory(path, trajectory_rows(arm), _task(arm))
