"""Start-up: the compile report, JAX's persistent cache across processes, warm-up.

The cache test runs two small processes (about 5 s each on the 2-core CPU): the second finds
the first's program in the cache, though it compiled in well under JAX's default 1 s threshold.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import pytest

from mjx_arm.train.compile_report import CompileReport
from mjx_arm.train.rundir import RunDir

# A small jitted program in a new process with the package's cache on; prints JAX's counts.
CHILD = """
import json
from mjx_arm.jax_cache import enable_compilation_cache
enable_compilation_cache()
import jax, jax.numpy as jnp
from mjx_arm.train.compile_report import CompileReport
report = CompileReport().open()
jax.block_until_ready(jax.jit(lambda x: jnp.tanh(x) * 3.0 + x.sum())(jnp.ones((7, 5))))
report.close()
print(json.dumps(report.to_dict()["jax_counts"]))
"""


def test_stages_add_up_and_jax_compiles_are_counted() -> None:
    x = jnp.ones(13)
    report = CompileReport().open()
    with report.stage("a"):
        jax.block_until_ready(jax.jit(lambda x: jnp.cos(x) * 2.0 + 0.123)(x))
    report.add("a", 1.0)
    report.add("b", 0.5)
    report.close()
    compiled = report.to_dict()["jax_counts"]["programs"]
    jax.block_until_ready(jax.jit(lambda x: jnp.sin(x) - 0.456)(x))  # not counted
    out = report.to_dict()
    assert out["stages"]["a"] >= 1.0 and out["stages"]["b"] == 0.5
    assert compiled >= 1 and out["jax_counts"]["programs"] == compiled
    assert out["jax_seconds"]["backend_compile"] > 0.0
    assert "other start-up (s): a " in report.summary()


def test_each_program_s_tracing_and_lowering_is_timed_under_its_own_name() -> None:
    def deep(x: jax.Array) -> jax.Array:
        for _ in range(300):  # a long trace beside a short one
            x = jnp.sin(x) * 1.0001
        return x

    x = jax.ShapeDtypeStruct((3,), jnp.float32)
    report = CompileReport().open()
    jax.jit(deep).lower(x)
    jax.jit(lambda x: x + 0.25).lower(x)
    report.close()
    traced = report.to_dict()["slowest_traces"]
    assert set(traced) == {"deep", "<lambda>"}, traced  # "jit(deep)" while lowering
    assert traced["deep"] > traced["<lambda>"] > 0.0
    total = report.seconds["trace"] + report.seconds["lower"]
    assert sum(traced.values()) == pytest.approx(total, abs=0.01)


def _child(cache: Path) -> dict:
    env = {**os.environ, "MJX_ARM_JAX_CACHE": str(cache), "JAX_PLATFORMS": "cpu"}
    done = subprocess.run(
        [sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_a_new_process_finds_even_a_small_program_in_the_cache(tmp_path: Path) -> None:
    first = _child(tmp_path / "jax")
    second = _child(tmp_path / "jax")
    assert first.get("cache_hits", 0) == 0 and first.get("cache_writes", 0) >= 1
    assert second.get("cache_hits", 0) >= 1, second


def test_each_start_adds_its_compile_report(tmp_path: Path) -> None:
    run = RunDir(tmp_path / "run")
    run.save_compile_report({"compile_s": 3.0})
    run.save_compile_report({"compile_s": 1.0})
    saved = json.loads((run.path / "compile.json").read_text())
    assert [entry["compile_s"] for entry in saved] == [3.0, 1.0]


def test_warmup_names_every_cache_and_its_variable(monkeypatch, tmp_path: Path) -> None:
    from mjx_arm.train.warmup import cache_locations

    monkeypatch.setenv("MJX_ARM_JAX_CACHE", str(tmp_path / "jax"))
    monkeypatch.setenv("WARP_CACHE_PATH", str(tmp_path / "warp"))
    where = cache_locations()
    assert str(tmp_path / "jax") in where["JAX compiled programs (XLA)"]
    assert str(tmp_path / "warp") in where["MuJoCo Warp kernels"]
    assert all("(set " in text for text in where.values())


@pytest.mark.slow
def test_after_warmup_a_new_process_loads_the_update_and_init(tmp_path: Path) -> None:
    """``mjx-arm warmup`` then a training in a new process: on the C MuJoCo backend the
    programs that do not hold the physics callbacks (learner init, the PPO update, the
    checkpoint's policy) come from the cache."""
    env = {**os.environ, "MJX_ARM_JAX_CACHE": str(tmp_path / "jax"), "JAX_PLATFORMS": "cpu"}
    sets = ["num_envs=16", "batch_size=16", "num_minibatches=2", "unroll_length=4"]
    sets += ["num_eval_envs=16", "num_evals=3", "num_timesteps=1000", "policy_hidden=16,16"]
    sets += ["value_hidden=16,16"]
    common = ["--task", "reach", "--preset", "cpu", "--backend", "mujoco", "--set", *sets]
    cli = [sys.executable, "-m", "mjx_arm.cli"]
    warm = subprocess.run([*cli, "warmup", *common, "--quiet"], env=env, capture_output=True)
    assert warm.returncode == 0, warm.stderr[-3000:]
    assert b"MJX_ARM_JAX_CACHE" in warm.stdout
    run = tmp_path / "run"
    done = subprocess.run(
        [*cli, "train", *common, "--quiet", "--run-dir", str(run)], env=env, capture_output=True
    )
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads((run / "compile.json").read_text())[-1]
    counts = report["jax_counts"]
    assert counts["cache_hits"] >= 3, counts  # init, update, policy at least
    # the first checkpoint (with its recorded CPU MuJoCo episode) is a start-up stage of its
    # own, and the report says when the trainer started
    assert 0.0 < report["stages"]["first checkpoint"] < 60.0, report["stages"]
    assert report["opened_at"] > 1.7e9
    # the start-up steps before the trainer's report, in the order they happen
    marks = report["marks"]
    order = ["command read", "trainer imported", "config read", "devices started"]
    assert sorted(marks, key=marks.get)[:4] == order, marks
    assert max(marks.values()) <= report["opened_at"]
    # loaded, not compiled: well under the rollout, which holds host callbacks and always
    # compiles (measured loaded 1.2 s against the rollout's 14.8 s on a loaded 2-core CPU)
    programs = report["slowest_programs"]
    update = sum(s for name, s in programs.items() if "update" in name)
    rollout = sum(s for name, s in programs.items() if "rollout" in name)
    assert update < 0.5 * rollout, programs
