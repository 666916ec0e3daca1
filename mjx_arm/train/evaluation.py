"""The training run's evaluation: one deterministic episode per env, metrics as Brax names them.

Brax's ``acting.Evaluator`` compiles a reset of the evaluation batch in its constructor (only to
have a state to donate) and its unroll on the first evaluation, one after the other. This
evaluator is one program, ``(params, key) -> final state``, that can be lowered ahead of time
and compiled beside the training epoch (:func:`mjx_arm.train.loop.prepare_ppo`), or, where the
first evaluation comes after some epochs, on a thread of its own while they train
(:meth:`Evaluator.compile_aside`). Its metrics
are Brax's: ``eval/episode_<name>`` (mean over the episodes) and ``..._std``,
``eval/avg_episode_length``, ``eval/epoch_eval_time``, ``eval/sps``, ``eval/walltime``.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any

import jax
import numpy as np
from brax.envs.wrappers.training import EvalWrapper
from brax.training.acting import generate_unroll

# Python's thread switch interval (s) while the evaluation traces aside (default 0.005). MuJoCo
# Warp's foreign calls run a Python callback each, which waits for the interpreter lock that
# the tracing thread holds: at the default, the first reset of the training envs took 1.39 s
# beside the trace instead of 0.06 s (median of 24 Touch runs on an H200).
ASIDE_SWITCH_INTERVAL = 1e-4


class Evaluator:
    """Evaluations of a policy on ``num_eval_envs`` envs, one episode each.

    Args:
        eval_env: the batched evaluation env (Brax training wrappers, batch axis first).
        make_policy: ``params -> policy`` (deterministic).
        num_eval_envs: envs, one episode each.
        episode_length: control steps of an episode.
        key: the evaluations' PRNG key (split once per evaluation).
    """

    def __init__(
        self,
        eval_env: Any,
        make_policy: Callable[[Any], Callable],
        num_eval_envs: int,
        episode_length: int,
        key: jax.Array,
    ) -> None:
        env = EvalWrapper(eval_env)

        def unroll(params: Any, key: jax.Array) -> Any:
            first = env.reset(jax.random.split(key, num_eval_envs))
            policy = make_policy(params)
            return generate_unroll(env, first, policy, key, unroll_length=episode_length)[0]

        self._unroll: Callable = jax.jit(unroll)
        self._pending: tuple[Future, Any] | None = None  # compile_aside's program and report
        self._key = key
        self._walltime = 0.0
        self._steps = episode_length * num_eval_envs

    def lower(self, params: Any) -> Any:
        """The evaluation program lowered for ``params`` (shapes only matter)."""
        return self._unroll.lower(params, self._key)

    @property
    def key(self) -> jax.Array:
        """The key the next evaluation's key is split from (a checkpoint keeps it)."""
        return self._key

    def use(self, compiled: Callable) -> None:
        """Run evaluations with ``compiled``, the compiled result of :meth:`lower`."""
        self._unroll = compiled

    def compiled(self) -> Callable:
        """The evaluation program (:meth:`compile_aside`'s waited for), for another evaluator
        of the same config (a warm trainer's next run: :mod:`mjx_arm.train.warm`)."""
        return self._pending[0].result() if self._pending is not None else self._unroll

    def compile_aside(self, params: Any, report: Any) -> None:
        """Trace, lower and compile the evaluation on a thread of its own, for a run whose first
        evaluation comes after some epochs: they train meanwhile, and the first evaluation
        waits for the program. ``params`` gives the shapes and shardings alone (the epochs may
        donate its buffers); ``report`` (a ``CompileReport``) gets the thread's seconds
        ("evaluation compiled aside") and the first evaluation's wait for it."""
        shapes = jax.tree.map(_shape_of, params)
        key = self._key

        def build() -> Callable:
            previous = sys.getswitchinterval()
            sys.setswitchinterval(ASIDE_SWITCH_INTERVAL)
            try:
                with report.stage("evaluation compiled aside"):
                    return self._unroll.lower(shapes, key).compile()
            finally:
                sys.setswitchinterval(previous)

        self._pending = (run_aside(build, "evaluation compile"), report)

    def run_evaluation(self, params: Any, training_metrics: dict[str, Any]) -> dict[str, Any]:
        """One evaluation of ``params``; its metrics merged after ``training_metrics``."""
        if self._pending is not None:  # compile_aside's program (its error raises here)
            future, report = self._pending
            with report.stage("waited for the evaluation's compile"):
                self._unroll = future.result()
            self._pending = None
        self._key, key = jax.random.split(self._key)
        start = time.time()
        state = self._unroll(params, key)
        metrics = jax.tree.map(np.asarray, state.info["eval_metrics"])
        seconds = time.time() - start
        self._walltime += seconds
        lengths = np.maximum(metrics.episode_steps, 1.0).astype(float)
        out: dict[str, Any] = {}
        for fn, suffix in ((np.mean, ""), (np.std, "_std")):
            for name, value in metrics.episode_metrics.items():
                scaled = value / lengths if name.endswith("per_step") else value
                out[f"eval/episode_{name}{suffix}"] = fn(scaled)
        out["eval/avg_episode_length"] = np.mean(metrics.episode_steps)
        out["eval/std_episode_length"] = np.std(metrics.episode_steps)
        out["eval/epoch_eval_time"] = seconds
        out["eval/sps"] = self._steps / seconds
        return {"eval/walltime": self._walltime, **training_metrics, **out}


def _shape_of(leaf: Any) -> jax.ShapeDtypeStruct:
    """An array's shape, dtype and sharding (a NumPy array has none), without its buffer."""
    return jax.ShapeDtypeStruct(leaf.shape, leaf.dtype, sharding=getattr(leaf, "sharding", None))


def run_aside(fn: Callable[[], Any], name: str) -> Future:
    """Start ``fn()`` on a daemon thread called ``name``; the future holds its value or error.
    A daemon, so that a run stopped meanwhile (Ctrl-C, an error) does not wait for it at exit.
    """
    future: Future = Future()

    def run() -> None:
        try:
            future.set_result(fn())
        except BaseException as error:  # handed to whoever waits on the future
            future.set_exception(error)

    threading.Thread(target=run, name=name, daemon=True).start()
    return future
