"""The training run's evaluation: one deterministic episode per env, metrics as Brax names them.

Brax's ``acting.Evaluator`` compiles a reset of the evaluation batch in its constructor (only to
have a state to donate) and its unroll on the first evaluation, one after the other. This
evaluator is one program, ``(params, key) -> final state``, that can be lowered ahead of time
and compiled beside the training epoch (:func:`mjx_arm.train.loop.prepare_ppo`). Its metrics
are Brax's: ``eval/episode_<name>`` (mean over the episodes) and ``..._std``,
``eval/avg_episode_length``, ``eval/epoch_eval_time``, ``eval/sps``, ``eval/walltime``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import jax
import numpy as np
from brax.envs.wrappers.training import EvalWrapper
from brax.training.acting import generate_unroll


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

    def run_evaluation(self, params: Any, training_metrics: dict[str, Any]) -> dict[str, Any]:
        """One evaluation of ``params``; its metrics merged after ``training_metrics``."""
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
