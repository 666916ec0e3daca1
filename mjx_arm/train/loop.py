"""The PPO run: devices, env batch, epochs between evaluations, and the callbacks.

The order of events follows Brax's ``ppo.train``: an evaluation of the initial policy (when more
than one evaluation is asked for), then ``num_evals - 1`` epochs, each followed by
``policy_params_fn(step, make_policy, params)`` and ``progress_fn(step, metrics)``. Metric names
are Brax's (``eval/...``, ``training/...``), so run directories read the same as before.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import NamedSharding
from jax.sharding import PartitionSpec as P

from mjx_arm.envs.wrappers import wrap_for_training
from mjx_arm.train import warm
from mjx_arm.train.compile_report import CompileReport
from mjx_arm.train.config import TrainConfig
from mjx_arm.train.distributed import gather, is_leader, share
from mjx_arm.train.divergence import check_epoch
from mjx_arm.train.evaluation import Evaluator
from mjx_arm.train.learner import (
    ENV_AXIS,
    EpochSizes,
    Learner,
    Params,
    batch_sharding,
    make_mesh,
    train_devices,
)
from mjx_arm.train.resume import ResumeState, env_leaf_paths, replace_leaves, select_leaves

# The evaluation figures every process needs (to stop together), sent from process 0.
SHARED_EVAL = ("eval/episode_success", "eval/episode_physics_overflow")


@dataclass
class Callbacks:
    """What the run reports to: Brax's ``progress_fn`` and ``policy_params_fn`` signatures,
    and ``snapshot(step, take)``, given after each epoch a function that gathers the run's
    :class:`~mjx_arm.train.resume.ResumeState` (``take(with_envs)``; a collective: every process
    calls it, or none).
    """

    progress: Callable[[int, dict[str, Any]], None]
    policy_params: Callable[[int, Callable, Params], None]
    snapshot: Callable[[int, Callable[[], ResumeState]], None] = field(
        default=lambda step, take: None
    )


def resolve_partition(config: TrainConfig, impl: str) -> str:
    """``auto``: ``xla`` for MJX-JAX; ``per_device`` for Warp and C MuJoCo (foreign calls)."""
    if config.partition != "auto":
        return config.partition
    return "xla" if impl == "jax" else "per_device"


def strong(tree: Any) -> Any:
    """``tree`` without weak types (a weak type changes the jitted epoch's signature)."""
    return jax.tree.map(lambda x: jnp.asarray(x).astype(jnp.asarray(x).dtype), tree)


def _run_keys(seed: int, restore: Any = None) -> tuple[jax.Array, ...]:
    """The run's keys from its seed: (policy init, value init, env reset, evaluation, epochs);
    a :class:`ResumeState` ``restore`` gives the last two as they were when it was taken."""
    global_key, local_key = jax.random.split(jax.random.PRNGKey(seed))
    local_key, key_env, key_eval = jax.random.split(local_key, 3)
    key_policy, key_value = jax.random.split(global_key)
    if isinstance(restore, ResumeState):
        local_key, key_eval = (jnp.asarray(restore.keys[k]) for k in ("epochs", "evaluation"))
    return key_policy, key_value, key_env, key_eval, local_key


def _training_metrics(metrics: dict[str, Any], sps: float, walltime: float) -> dict[str, Any]:
    """An epoch's metrics as Brax names them: ``training/sps``, ``training/walltime``, ..."""
    named = {f"training/{name}": value for name, value in metrics.items()}
    return {"training/sps": sps, "training/walltime": walltime, **named}


@dataclass
class Prepared:
    """A run ready to train: its programs compiled, the first env state reset.

    Attributes:
        learner: networks, loss and optimiser.
        state: the training state (params, optimiser, normaliser), replicated.
        env_state: the first state of the training envs, split over the devices.
        epoch: the compiled epoch ``(state, env_state, key) -> (state, env_state, metrics)``.
        evaluate: the evaluator (its program compiled).
        sizes: the epoch's cut.
        local_key: the key the epochs' keys are split from.
        devices, partition: where the run trains and how the physics is split.
        env_paths: tree paths of the per-env leaves of ``env_state`` (what a checkpoint keeps).
    """

    learner: Learner
    state: Any
    env_state: Any
    epoch: Callable
    evaluate: Evaluator
    sizes: EpochSizes
    local_key: jax.Array
    devices: list
    partition: str
    env_paths: list = field(default_factory=list)

    def snapshot(
        self, state: Any, env_state: Any, local_key: jax.Array, with_envs: bool = True
    ) -> ResumeState:
        """The run between two epochs, gathered on the host (a collective); the envs' state
        only ``with_envs``."""
        leaves = gather(select_leaves(env_state, self.env_paths)) if with_envs else None
        keys = {"epochs": np.asarray(local_key), "evaluation": np.asarray(self.evaluate.key)}
        return ResumeState(gather(state), keys, leaves)


def prepare_ppo(
    config: TrainConfig,
    env: Any,
    eval_env: Any,
    episode_length: int,
    restore: Params | ResumeState | None = None,
    step_offset: int = 0,
    report: CompileReport | None = None,
) -> Prepared:
    """Build the learner, compile the run's XLA programs and reset the training envs.

    The reset, the training step's rollout and update (:meth:`Learner.epoch_programs`) and
    the evaluation are traced and lowered one after the other (Python), then compiled by XLA
    at the same time on a thread pool while MuJoCo Warp's kernels, started when the env was
    built, compile. A warm trainer's run takes the programs of an earlier run of its config
    (:mod:`.warm`). Each stage is timed into ``report``. ``restore`` is a checkpoint's whole
    state (:class:`ResumeState`: the run goes on exactly where it stopped) or, from an older
    checkpoint, its params alone (new keys, fresh optimiser moments, reset envs). Where
    several processes train, only process 0 compiles the evaluation.
    """
    report = report or CompileReport()
    devices = train_devices(config.devices)
    config.check_devices(len(devices))
    mesh = make_mesh(devices)
    partition = resolve_partition(config, env.physics.impl)
    run_keys = _run_keys(config.seed + step_offset, restore)
    key_policy, key_value, key_env, key_eval, local_key = run_keys
    kept = warm.programs_of(env)  # a warm trainer's, of an earlier run of this config
    with report.stage("learner init"):
        learner, state = _learner(config, env, mesh, (key_policy, key_value), restore, kept)
    evaluate = _evaluator(config, eval_env, learner, episode_length, key_eval)
    sizes = EpochSizes.of(config, config.num_timesteps)
    keys = jax.random.split(key_env, config.num_envs)
    split_mesh = mesh if partition == "per_device" else None
    train_env = wrap_for_training(env, episode_length, mesh=split_mesh, axis=ENV_AXIS)
    aside = not evaluates_initial_policy(config, step_offset) and jax.process_count() == 1
    programs = _Programs(train_env, mesh, keys, learner, evaluate, aside)
    epoch, reset = programs.kept_or_compiled(kept, state, sizes, local_key, report)
    if kept is None:
        _wait_for_kernels((env, eval_env), report)
        warm.keep_programs(env, warm.Programs(learner, epoch, reset, evaluate))
    env_state, paths = _first_envs(reset, keys, env.physics.splits, restore, report)
    return Prepared(
        learner, state, env_state, epoch, evaluate, sizes, local_key, devices, partition, paths
    )


@dataclass(frozen=True)
class _Programs:
    """What the run's programs are built from: the wrapped training envs on ``mesh``, their
    reset keys (``[num_envs, 2]``), the learner and the evaluator; ``aside``: the evaluation
    is compiled on a thread of its own once the rest is (its first use is epochs away)."""

    train_env: Any
    mesh: Any
    keys: jax.Array
    learner: Learner
    evaluate: Evaluator
    aside: bool = False

    def kept_or_compiled(
        self,
        kept: warm.Programs | None,
        state: Any,
        sizes: EpochSizes,
        local_key: jax.Array,
        report: CompileReport,
    ) -> tuple[Any, Callable]:
        """``kept``'s programs (a warm trainer's, of an earlier run of this config: the
        evaluator takes its evaluation), else :meth:`compile`'s."""
        if kept is None:
            return self.compile(state, sizes, local_key, report)
        self.evaluate.use(kept.evaluator.compiled())
        report.kept.append("programs")
        return kept.epoch, kept.reset

    def compile(
        self, state: Any, sizes: EpochSizes, local_key: jax.Array, report: CompileReport
    ) -> tuple[Any, Callable]:
        """Trace and lower the reset, the epoch and (process 0) the evaluation, then compile
        them at once; the evaluator takes its program (or, ``aside``, compiles it on a thread
        of its own afterwards). Returns (the compiled epoch, the compiled reset
        ``keys -> env_state``)."""
        with report.stage("trace + lower"):
            reset, shardings = _reset_fn(self.train_env, self.mesh, self.keys)
            env_shapes = jax.tree.map(_strong_shape, jax.eval_shape(reset, self.keys), shardings)
            epoch = self.learner.epoch_programs(self.train_env, sizes, shardings)
            lowered = {"reset": reset.lower(self.keys), **epoch.lower(state, env_shapes, local_key)}
            if is_leader() and not self.aside:
                lowered["evaluation"] = self.evaluate.lower(self.learner.params(state))
        with report.stage("XLA compile (in parallel)"):
            compiled = compile_all(lowered)
        if "evaluation" in compiled:
            self.evaluate.use(compiled["evaluation"])
        elif self.aside:
            self.evaluate.compile_aside(self.learner.params(state), report)
        return epoch.with_programs(compiled["rollout"], compiled["update"]), compiled["reset"]


def _evaluator(
    config: TrainConfig, eval_env: Any, learner: Learner, episode_length: int, key: jax.Array
) -> Evaluator:
    """The evaluator of the run's deterministic policy on the evaluation envs."""
    policy = functools.partial(learner.make_policy, deterministic=True)
    wrapped = wrap_for_training(eval_env, episode_length)
    return Evaluator(wrapped, policy, config.num_eval_envs, episode_length, key)


def _first_envs(
    reset: Callable, keys: jax.Array, splits: Any, restore: Any, report: CompileReport
) -> tuple[Any, list]:
    """The training envs' first state, reset from ``keys`` (``[num_envs, 2]``), or a
    :class:`ResumeState`'s envs where it has them; and the tree paths of its per-env leaves."""
    with report.stage("first reset run"):
        env_state = jax.block_until_ready(strong(reset(keys)))
    paths = env_leaf_paths(env_state, keys.shape[0], splits)
    if isinstance(restore, ResumeState) and restore.env_leaves is not None:
        env_state = _restored_envs(env_state, paths, restore.env_leaves)
    return env_state, paths


def _restored_envs(env_state: Any, paths: list, leaves: list[np.ndarray]) -> Any:
    """``env_state`` with a checkpoint's per-env leaves, each laid out as the fresh one is."""
    fresh = select_leaves(env_state, paths)
    placed = [jax.device_put(np.asarray(x), f.sharding) for x, f in zip(leaves, fresh, strict=True)]
    return replace_leaves(env_state, paths, placed)


def _learner(
    config: TrainConfig,
    env: Any,
    mesh: Any,
    keys: tuple[jax.Array, jax.Array],
    restore: Any,
    kept: warm.Programs | None = None,
) -> tuple[Learner, Any]:
    """The learner (``kept``'s, a warm trainer's of an earlier run of this config) and its
    first state: fresh from ``keys`` (policy, value), or restored."""
    if kept is not None:
        learner = kept.learner
    else:
        sizes = (env.observation_size, env.action_size)
        learner = Learner(config, *sizes, mesh, env.contact_force_dims)
    state = learner.init(*keys)
    if restore is None:
        return learner, state
    if isinstance(restore, ResumeState):
        return learner, learner.place(restore.train_state)
    return learner, learner.restore(state, restore)


def _wait_for_kernels(envs: tuple[Any, ...], report: CompileReport) -> None:
    """Wait for each env's MuJoCo Warp kernel compiles; their seconds into ``report``."""
    physics = {id(env.physics): env.physics for env in envs}.values()
    labels = {"warp_kernels": "Warp kernels", "warp_kernels_wait": "waited for Warp"}
    for times in (p.wait_precompiled() for p in physics):
        for name, label in labels.items():
            if times.get(name):
                report.add(label, times[name])


def compile_all(lowered: dict[str, Any]) -> dict[str, Any]:
    """Compile every lowered program at once (XLA compiles outside Python's lock); one after
    another where several processes train (XLA's GPU compiler crashed, SIGSEGV, compiling two
    programs at once in a process joined by jax.distributed on H100s, jax 0.11)."""
    workers = len(lowered) if jax.process_count() == 1 else 1
    with ThreadPoolExecutor(max_workers=workers) as pool:
        futures = {name: pool.submit(low.compile) for name, low in lowered.items()}
        return {name: future.result() for name, future in futures.items()}


def run_ppo(
    config: TrainConfig,
    env: Any,
    eval_env: Any,
    episode_length: int,
    callbacks: Callbacks,
    restore: Params | ResumeState | None = None,
    step_offset: int = 0,
    report: CompileReport | None = None,
) -> dict[str, Any]:
    """Train PPO up to ``config.num_timesteps`` env steps; return the devices and partition.

    The run is cut into ``num_evals - 1`` epochs of equal size (rounded up, as Brax does); a
    resumed run (``step_offset`` > 0) runs the epochs that remain, so it ends at the same step
    and logs the same steps as a run that was never stopped.

    Args:
        config: PPO settings, devices and partition.
        env, eval_env: the unwrapped training and evaluation envs (``MjxArmEnv``).
        episode_length: control steps before an episode is truncated.
        callbacks: where evaluations and params go (steps are the run's global steps).
        restore: the checkpoint's whole state, or its (normaliser, policy, value) alone.
        step_offset: env steps already trained (a resumed run's checkpoint step).
        report: where the start-up stages are timed (the first evaluation and epoch included).
    """
    report = report or CompileReport()
    run = prepare_ppo(config, env, eval_env, episode_length, restore, step_offset, report)
    state, env_state, local_key = run.state, run.env_state, run.local_key
    if evaluates_initial_policy(config, step_offset):
        _first_evaluation(run, callbacks, report)
    walltime, step = 0.0, step_offset
    while step < config.num_timesteps:
        epoch_key, local_key = jax.random.split(local_key)
        start = time.monotonic()
        state, env_state, metrics = run.epoch(state, strong(env_state), epoch_key)
        seconds = time.monotonic() - start
        if walltime == 0.0:
            report.add("first epoch run", seconds)
        walltime += seconds
        step += run.sizes.env_steps_per_epoch
        training = _training_metrics(metrics, run.sizes.env_steps_per_epoch / seconds, walltime)
        taken = (state, env_state, local_key)
        _epoch_done(config, run, callbacks, step, taken, metrics, training)
    return {"devices": [str(d) for d in run.devices], "partition": run.partition}


def _first_evaluation(run: Prepared, callbacks: Callbacks, report: CompileReport) -> None:
    """Evaluate the initial policy (timed into ``report``) and report it at step 0."""
    with report.stage("first evaluation run"):
        metrics = _evaluate(run.evaluate, run.learner.params(run.state), {})
    callbacks.progress(0, metrics)


def _epoch_done(
    config: TrainConfig,
    run: Prepared,
    callbacks: Callbacks,
    step: int,
    taken: tuple[Any, Any, jax.Array],
    metrics: dict[str, Any],
    training: dict[str, Any],
) -> None:
    """After the epoch that reached ``step``: check it, hand out its params and a snapshot of
    ``taken`` (state, env state, epochs' key), evaluate (:func:`evaluates_at`) and report with
    ``training``."""
    state = taken[0]
    check_epoch(config, step, state, metrics)  # before anything of the epoch is saved
    params = run.learner.params(state)
    callbacks.policy_params(step, run.learner.make_policy, params)
    callbacks.snapshot(step, functools.partial(run.snapshot, *taken))
    if not evaluates_at(config, step, training):
        callbacks.progress(step, dict(training))
        return
    callbacks.progress(step, _evaluate(run.evaluate, params, training))


def evaluates_initial_policy(config: TrainConfig, step_offset: int) -> bool:
    """Whether a run from ``step_offset`` evaluates its policy before the first epoch: a new
    run (not a resumed one) with evaluations during training, no ``eval_from_step`` and no
    ``eval_gate``."""
    skipped = config.eval_from_step or config.eval_gate
    return config.num_evals > 1 and step_offset == 0 and not skipped


def evaluates_at(config: TrainConfig, step: int, training: dict[str, Any]) -> bool:
    """Whether the epoch that ends at env step ``step``, with ``training`` metrics, is
    evaluated: from ``config.eval_from_step`` on where its training episodes' success rate is
    at least ``config.eval_gate``, and the run's last epoch always. The same on every process
    (the step, and a rate over every process's envs), so that all stop at the same evaluation."""
    if step >= config.num_timesteps:
        return True
    rate = float(training.get("training/episode_success", 1.0))
    return step >= config.eval_from_step and rate >= config.eval_gate


def _evaluate(evaluate: Evaluator, params: Params, training: dict[str, Any]) -> dict[str, Any]:
    """Process 0 evaluates ``params``; every process gets its success and overflow figures
    (so that all stop at the same evaluation). Alone: the evaluation's metrics."""
    if jax.process_count() == 1:
        return evaluate.run_evaluation(params, training)
    metrics = evaluate.run_evaluation(params, training) if is_leader() else dict(training)
    shared = share({k: float(np.mean(metrics.get(k, 0.0))) for k in SHARED_EVAL})
    return metrics if is_leader() else {**metrics, **shared}


def _strong_shape(leaf: Any, sharding: Any) -> jax.ShapeDtypeStruct:
    """The shape of a state leaf as the epoch receives it: strong type, its sharding."""
    return jax.ShapeDtypeStruct(leaf.shape, leaf.dtype, sharding=sharding)


def _reset_fn(env: Any, mesh: Any, keys: jax.Array) -> tuple[Any, Any]:
    """The jitted reset of the training envs, its batch split over the mesh, and the state's
    shardings."""
    num_envs = keys.shape[0]
    shardings = batch_sharding(mesh, jax.eval_shape(env.reset, keys), num_envs)
    reset = jax.jit(
        env.reset, in_shardings=NamedSharding(mesh, P(ENV_AXIS)), out_shardings=shardings
    )
    return reset, shardings
