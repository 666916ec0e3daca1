"""Export a trained run's policy to a numpy ``.npz`` or an ONNX file.

``export_run(run_dir, "policy.npz")`` reads the newest checkpoint (or ``step``), takes the
observation normaliser and the policy MLP out of Brax's ``(normalizer, policy, value)`` params,
and writes them with the metadata a runtime needs: the contract version, the observation layout,
the activation, the action distribution, the action scaling and the run's whole config.

Reading a checkpoint needs orbax (and so jax); running the exported file does not.
"""

from __future__ import annotations

import inspect
import os
import time
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from mjx_arm.inputs import (
    ConfigError,
    MissingInputError,
    check_output,
    read_json_object,
    write_atomic,
)
from mjx_arm.policy.numpy_policy import (
    CONTRACT_VERSION,
    FORMAT,
    PolicyFileError,
    check_arrays,
    check_metadata,
    npz_bytes,
)

SUFFIXES = (".npz", ".onnx")


def find_checkpoint(run_dir: str | Path, step: int | None = None) -> Path:
    """The checkpoint folder of ``run_dir``: the newest usable one, or the one at ``step``.

    Raises:
        FileNotFoundError: no run directory, no checkpoint, or none at ``step`` (each an
            :class:`~mjx_arm.inputs.InputError`).
    """
    from mjx_arm.train.checkpoints import checkpoint_step, unusable_reason, usable_checkpoints
    from mjx_arm.train.rundir import RunDir

    run_dir = Path(run_dir)
    if not run_dir.is_dir() or not os.path.lexists(run_dir / "config.json"):  # else: read, named
        raise MissingInputError(
            f"{run_dir} is not a run directory (no config.json); give the RUN_DIR that "
            "mjx-arm train wrote"
        )
    run = RunDir(run_dir)
    if step is None:
        latest = run.latest_checkpoint()
        if latest is None:
            why = unusable_reason(run.checkpoints)
            raise MissingInputError(f"no usable checkpoint in {run.checkpoints}{why}")
        return latest
    found = {checkpoint_step(p): p for p in usable_checkpoints(run.checkpoints)}
    if int(step) not in found:
        raise MissingInputError(
            f"no usable checkpoint at step {step} in {run.checkpoints}; "
            f"steps available: {available_steps(run_dir)}"
        )
    return found[int(step)]


def available_steps(run_dir: str | Path) -> list[int]:
    """Steps of every usable checkpoint in ``run_dir``, ascending (a folder whose name is not
    ``step_`` and a number, ``step_abc``, is none)."""
    from mjx_arm.train.checkpoints import checkpoint_step, usable_checkpoints

    return [checkpoint_step(p) for p in usable_checkpoints(Path(run_dir) / "checkpoints")]


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
    """Everything but the weights a runtime needs, as a JSON-ready dict.

    Raises:
        InputError: the run's config.json or the checkpoint's meta.json is not usable.
    """
    from mjx_arm import __version__
    from mjx_arm.arm.info import arm_info, arm_record
    from mjx_arm.task.config import TaskConfig
    from mjx_arm.task.observation import obs_layout
    from mjx_arm.train.rundir import RunDir

    task = TaskConfig.from_dict(_table(config, "task", run_dir))
    record = config.get("arm") or arm_record(arm_info())  # runs before the arm record: shipped
    names = record.get("joint_names") if isinstance(record, dict) else None
    if not isinstance(names, list) or not isinstance(record.get("v_max"), list):
        raise ConfigError(f"{run_dir / 'config.json'}: 'arm' must record joint_names and v_max")
    n = len(names)
    n_actions = n + int(task.spec.gripper)  # a gripper task adds the gripper's command
    meta = RunDir.load_meta(checkpoint)
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
        "obs_clip": _obs_clip(config),
        "action_scale": task.action_scale,
        "v_max": list(record["v_max"]),
        "joint_speeds": task.joint_speeds(record["v_max"]).tolist(),
        "joint_names": list(names),
        "arm": record,
        "ctrl_dt": task.ctrl_dt,
        "config": dict(config),
    }


def _obs_clip(config: Mapping[str, Any]) -> float:
    """The bound training clipped normalised observations to (0: none; runs before the
    setting had none)."""
    train = config.get("train")
    normalizer = train.get("normalizer") if isinstance(train, dict) else None
    clip = normalizer.get("clip", 0.0) if isinstance(normalizer, dict) else 0.0
    return float(clip) if isinstance(clip, int | float) and not isinstance(clip, bool) else 0.0


def _table(config: Mapping[str, Any], key: str, run_dir: Path) -> dict[str, Any]:
    """``config[key]``, checked to be a table (a section of a run's config.json)."""
    value = config.get(key)
    if not isinstance(value, dict):
        raise ConfigError(f"{run_dir / 'config.json'} has no {key!r} table: a damaged run")
    return value


def _check_distribution(config: Mapping[str, Any], run_dir: Path) -> None:
    """Refuse a run (its ``config.json`` read as ``config``) whose policy is not tanh-normal,
    the one distribution policy files hold.

    Raises:
        ConfigError: the run's config names another ``policy_distribution``.
    """
    distribution = _table(config, "train", run_dir).get("policy_distribution", "tanh_normal")
    if distribution != "tanh_normal":
        raise ConfigError(
            f"{run_dir}: the run trained a {distribution!r} policy; policy files hold "
            "'tanh_normal' policies only (the training default), so this run does not export. "
            "Its metrics and checkpoints are its own (mjx-arm bench seeds reads them)"
        )


def load_run(run_dir: str | Path, step: int | None = None):
    """(arrays, metadata, raw params) of a run's checkpoint (newest, or at ``step``), checked
    as a policy file's are (:func:`~mjx_arm.policy.numpy_policy.check_arrays`).

    Raises:
        InputError: no usable run directory or checkpoint, or params that do not fit it.
    """
    from mjx_arm.train.rundir import CheckpointError, RunDir

    run_dir = Path(run_dir)
    config = None
    if (run_dir / "config.json").is_file():  # refused before any checkpoint is looked for
        config = read_json_object(run_dir / "config.json", "run config", within=run_dir)
        _check_distribution(config, run_dir)
    checkpoint = find_checkpoint(run_dir, step)
    if config is None:  # its error, after the checkpoint's
        config = read_json_object(run_dir / "config.json", "run config", within=run_dir)
    with warnings.catch_warnings():  # orbax: "Sharding info not provided when restoring"
        warnings.filterwarnings("ignore", message="Sharding info not provided")
        params = RunDir.load_params(checkpoint)
    normalize = bool(_table(config, "train", run_dir).get("normalize_observations", True))
    try:
        arrays = policy_arrays(params, normalize)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as err:
        raise CheckpointError(f"{checkpoint} holds no Brax PPO policy ({err!r})") from err
    metadata = policy_metadata(config, checkpoint, run_dir)
    try:  # what loading the exported file will check, checked before it is written
        check_metadata(metadata, str(checkpoint))
        check_arrays(arrays, metadata, str(checkpoint))
    except PolicyFileError as err:
        raise CheckpointError(str(err)) from err
    return arrays, metadata, params


def export_run(run_dir: str | Path, output: str | Path, step: int | None = None) -> Path:
    """Export a run's policy to ``output`` (``.npz`` or ``.onnx``), atomically: a failure or a
    kill leaves an older file at ``output`` whole.

    Args:
        run_dir: the training run directory.
        output: the file to write; its suffix picks the format.
        step: checkpoint step (default: the newest).

    Returns:
        The written path.

    Raises:
        InputError: an unknown suffix or unwritable output, no such run or checkpoint, or a
            checkpoint that does not hold a usable policy.
    """
    output = check_output(output, "output", SUFFIXES)
    arrays, metadata, _ = load_run(run_dir, step)
    if output.suffix == ".onnx":
        from mjx_arm.policy.onnx_export import write_onnx

        return write_onnx(output, arrays, metadata)
    write_atomic(npz_bytes(arrays, metadata), output)
    return output


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
