"""Export a trained run's policy to a numpy ``.npz`` or an ONNX file.

``export_run(run_dir, "policy.npz")`` reads the newest checkpoint (or ``step``), takes the
observation normaliser and the policy MLP out of Brax's ``(normalizer, policy, value)`` params,
and writes them with the metadata a runtime needs: the contract version, the observation layout,
the activation, the action distribution, the action scaling and the run's whole config.

Reading a checkpoint needs orbax (and so jax); running the exported file does not.
"""

from __future__ import annotations

import inspect
import json
import time
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from mjx_arm.policy.numpy_policy import CONTRACT_VERSION, FORMAT, write_npz

SUFFIXES = (".npz", ".onnx")


def find_checkpoint(run_dir: str | Path, step: int | None = None) -> Path:
    """The checkpoint folder of ``run_dir``: the newest, or the one at ``step``.

    Raises:
        FileNotFoundError: no run directory, no checkpoint, or none at ``step``.
    """
    from mjx_arm.train.rundir import RunDir

    run_dir = Path(run_dir)
    if not (run_dir / "config.json").exists():
        raise FileNotFoundError(f"{run_dir} is not a run directory (no config.json)")
    run = RunDir(run_dir)
    if step is None:
        latest = run.latest_checkpoint()
        if latest is None:
            raise FileNotFoundError(f"no checkpoint in {run.checkpoints}")
        return latest
    folder = run.checkpoint_dir(int(step))
    if not (folder / "meta.json").exists():
        raise FileNotFoundError(
            f"no checkpoint at step {step} in {run.checkpoints}; "
            f"steps available: {available_steps(run_dir)}"
        )
    return folder


def available_steps(run_dir: str | Path) -> list[int]:
    """Steps of every checkpoint in ``run_dir``, ascending."""
    from mjx_arm.train.checkpoints import CHECKPOINT_PREFIX

    folder = Path(run_dir) / "checkpoints"
    if not folder.exists():
        return []
    return sorted(
        int(p.name[len(CHECKPOINT_PREFIX) :])
        for p in folder.iterdir()
        if p.name.startswith(CHECKPOINT_PREFIX) and (p / "meta.json").exists()
    )


def _field(obj: Any, name: str) -> Any:
    """``obj[name]`` for a restored dict, ``obj.name`` for a live Brax object."""
    return obj[name] if isinstance(obj, Mapping) else getattr(obj, name)


def policy_arrays(params: Any, normalize: bool = True) -> dict[str, np.ndarray]:
    """Normaliser and policy MLP arrays of Brax PPO params.

    Args:
        params: ``(normalizer_params, policy_params, value_params)`` as restored by orbax (dicts)
            or as Brax holds them.
        normalize: whether training normalised observations (else mean 0, std 1).

    Returns:
        ``obs_mean (22,)``, ``obs_std (22,)`` and ``kernel_I (n_in, n_out)``, ``bias_I (n_out,)``
        for each dense layer, float32.
    """
    normalizer, policy = params[0], params[1]
    mean = np.asarray(_field(normalizer, "mean"), dtype=np.float32)
    std = np.asarray(_field(normalizer, "std"), dtype=np.float32)
    if not normalize:
        mean, std = np.zeros_like(mean), np.ones_like(std)
    layers = _field(policy, "params")
    names = sorted(layers, key=lambda n: int(n.rsplit("_", 1)[-1]))
    arrays = {"obs_mean": mean, "obs_std": std}
    for i, name in enumerate(names):
        arrays[f"kernel_{i}"] = np.asarray(layers[name]["kernel"], dtype=np.float32)
        arrays[f"bias_{i}"] = np.asarray(layers[name]["bias"], dtype=np.float32)
    return arrays


def brax_activation() -> str:
    """Name of the activation Brax's ``make_ppo_networks`` uses by default (as training does)."""
    from brax.training.agents.ppo import networks as ppo_networks

    default = inspect.signature(ppo_networks.make_ppo_networks).parameters["activation"].default
    name = getattr(default, "__name__", str(default))
    return {"silu": "swish"}.get(name, name)


def policy_metadata(config: Mapping[str, Any], checkpoint: Path, run_dir: Path) -> dict:
    """Everything but the weights a runtime needs, as a JSON-ready dict."""
    from mjx_arm import __version__
    from mjx_arm.envs.arm import arm_info, arm_record
    from mjx_arm.task.config import TaskConfig
    from mjx_arm.task.observation import obs_layout

    task = TaskConfig.from_dict(config["task"])
    record = config.get("arm") or arm_record(arm_info())  # runs before the arm record: shipped
    n = len(record["joint_names"])
    n_actions = n + int(task.spec.gripper)  # a gripper task adds the gripper's command
    meta = json.loads((checkpoint / "meta.json").read_text())
    return {
        "format": FORMAT,
        "contract_version": CONTRACT_VERSION,
        "mjx_arm_version": __version__,
        "task": task.task,
        "step": int(meta["step"]),
        "run_dir": str(run_dir.resolve()),
        "exported_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "obs_layout": [[key, size] for key, size in obs_layout(n, task.spec.extra_obs)],
        "action_size": n_actions,
        "activation": brax_activation(),
        "distribution": "tanh_normal",
        "action_scale": task.action_scale,
        "v_max": list(record["v_max"]),
        "joint_speeds": task.joint_speeds(record["v_max"]).tolist(),
        "joint_names": list(record["joint_names"]),
        "arm": record,
        "ctrl_dt": task.ctrl_dt,
        "config": dict(config),
    }


def load_run(run_dir: str | Path, step: int | None = None):
    """(arrays, metadata, raw params) of a run's checkpoint (newest, or at ``step``)."""
    from mjx_arm.train.rundir import RunDir

    run_dir = Path(run_dir)
    checkpoint = find_checkpoint(run_dir, step)
    config = json.loads((run_dir / "config.json").read_text())
    with warnings.catch_warnings():  # orbax: "Sharding info not provided when restoring"
        warnings.filterwarnings("ignore", message="Sharding info not provided")
        params = RunDir.load_params(checkpoint)
    normalize = bool(config.get("train", {}).get("normalize_observations", True))
    arrays = policy_arrays(params, normalize)
    return arrays, policy_metadata(config, checkpoint, run_dir), params


def export_run(run_dir: str | Path, output: str | Path, step: int | None = None) -> Path:
    """Export a run's policy to ``output`` (``.npz`` or ``.onnx``).

    Args:
        run_dir: the training run directory.
        output: the file to write; its suffix picks the format.
        step: checkpoint step (default: the newest).

    Returns:
        The written path.

    Raises:
        ValueError: an unknown suffix. FileNotFoundError: no such run or checkpoint.
    """
    output = Path(output)
    if output.suffix not in SUFFIXES:
        raise ValueError(f"output must end in one of {SUFFIXES}, got {output.name!r}")
    arrays, metadata, _ = load_run(run_dir, step)
    if output.suffix == ".onnx":
        from mjx_arm.policy.onnx_export import write_onnx

        return write_onnx(output, arrays, metadata)
    return write_npz(output, arrays, metadata)


def brax_policy(run_dir: str | Path, step: int | None = None) -> Callable[[Any], np.ndarray]:
    """The training code's own deterministic policy (JAX), for checking an export.

    Returns:
        A function from ``state (obs,)`` or ``(N, obs)`` to the action ``(..., act)``, numpy
        float32 (22 and 6 for the shipped arm).
    """
    import jax
    from brax.training.acme import running_statistics
    from brax.training.agents.ppo import networks as ppo_networks

    from mjx_arm.train.config import TrainConfig
    from mjx_arm.train.networks import make_networks

    _, metadata, params = load_run(run_dir, step)
    train = TrainConfig.from_dict(metadata["config"]["train"])
    obs_size = sum(size for _, size in metadata["obs_layout"])
    networks = make_networks(train, obs_size, metadata["action_size"])
    normalizer = running_statistics.NestedMeanStd(
        mean=np.asarray(params[0]["mean"]), std=np.asarray(params[0]["std"])
    )
    policy = ppo_networks.make_inference_fn(networks)(
        (normalizer, params[1], params[2]), deterministic=True
    )
    policy = jax.jit(policy)
    key = jax.random.PRNGKey(0)
    return lambda state: np.asarray(policy(np.asarray(state, np.float32), key)[0], np.float32)
