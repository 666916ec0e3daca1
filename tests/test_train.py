"""Training on the C MuJoCo backend: learning, resume and determinism.

Measured on the 2-core CPU: the ``cpu`` preset brings Reach to 100% evaluation success within
about 160k env steps (roughly a minute). The test asks for >= 80% after 200k steps.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from mjx_arm.inputs import ConfigError
from mjx_arm.train.ppo import train
from mjx_arm.train.presets import load_config
from mjx_arm.train.rundir import RunDir

REACH_SUCCESS_THRESHOLD = 0.8


def _tiny(run_steps: int, **extra: str) -> list[str]:
    sets = {
        "task": "reach",
        "backend": "mujoco",
        "num_timesteps": str(run_steps),
        "num_envs": "32",
        "batch_size": "32",
        "num_minibatches": "4",
        "unroll_length": "5",
        "num_updates_per_batch": "2",
        "num_evals": "3",
        "num_eval_envs": "16",
        "policy_hidden": "32,32",
        "value_hidden": "32,32",
        **extra,
    }
    return [f"{k}={v}" for k, v in sets.items()]


@pytest.mark.slow
def test_reach_learns_on_the_c_backend(tmp_path: Path) -> None:
    config = load_config("cpu", None, ["task=reach", "backend=mujoco", "num_timesteps=200000"])
    result = train(config, tmp_path / "run", quiet=True)
    success = result.metrics["eval/episode_success"]
    assert success >= REACH_SUCCESS_THRESHOLD, f"eval success {success:.3f}"
    run = RunDir(result.run_dir)
    assert (result.run_dir / "config.json").is_file()
    assert (result.run_dir / "tb").is_dir()
    rows = run.read_metrics()
    assert len(rows) == config.num_evals
    for key in (
        "eval/episode_reward",
        "eval/episode_success",
        "training/kl_mean",
        "training/policy_loss",
        "training/v_loss",
        "training/entropy_loss",
        "training/sps",
        "eval/episode_reward/distance",
    ):
        assert key in rows[-1], key
    latest = run.latest_checkpoint()
    transitions = np.load(latest / "transitions.npz")
    assert transitions["obs"].shape[1] == 22 and len(transitions["obs"]) <= 100
    assert set(transitions.files) >= {"obs", "action", "reward", "done"}


@pytest.mark.slow
@pytest.mark.parametrize("distribution", ["tanh_normal", "normal"])
def test_resume_continues_from_the_saved_step(tmp_path: Path, distribution: str) -> None:
    run_dir = tmp_path / "run"
    config = load_config("cpu", None, _tiny(4000, policy_distribution=distribution))
    first = train(config, run_dir, quiet=True)
    run = RunDir(run_dir)
    checkpoints = sorted(p.name for p in run.checkpoints.iterdir())
    assert len(checkpoints) >= 2
    # interrupt: drop the newest checkpoint and the metric rows after the one before it
    shutil.rmtree(run.latest_checkpoint())
    kept_step = int(RunDir.load_meta(run.latest_checkpoint())["step"])
    saved = json.loads((run_dir / "config.json").read_text())
    resumed = train(config, run_dir, resume=True, quiet=True)
    assert resumed.steps > kept_step
    assert resumed.steps >= first.steps
    steps = [int(r["step"]) for r in run.read_metrics()]
    assert max(steps) == resumed.steps
    assert json.loads((run_dir / "config.json").read_text()) == saved  # config untouched
    assert int(RunDir.load_meta(run.latest_checkpoint())["step"]) == resumed.steps


def test_resume_without_checkpoint_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="no checkpoint"):
        train(load_config("cpu", None, _tiny(4000)), tmp_path / "empty", resume=True)


@pytest.mark.slow
def test_same_seed_same_result_on_the_c_backend(tmp_path: Path) -> None:
    config = load_config("cpu", None, _tiny(2000, num_evals="2"))
    a = train(config, tmp_path / "a", quiet=True)
    b = train(config, tmp_path / "b", quiet=True)
    pa = RunDir.load_params(RunDir(a.run_dir).latest_checkpoint())
    pb = RunDir.load_params(RunDir(b.run_dir).latest_checkpoint())
    import jax

    for x, y in zip(jax.tree.leaves(pa), jax.tree.leaves(pb), strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    assert a.metrics["eval/episode_reward"] == b.metrics["eval/episode_reward"]


def test_task_and_reward_overrides_reach_the_task_config() -> None:
    """``task.FIELD=`` and ``task.reward.TERM=`` change the task; unknown names are errors."""
    from mjx_arm.task.touch import GENTLE_REWARD

    config = load_config(
        "cpu",
        None,
        ["task=touch", "task.action_scale=0.2", "task.reward.approach_speed=-200"],
    )
    task = config.task_config()
    assert task.action_scale == 0.2 and task.reward.approach_speed == -200
    assert task.reward.proximity == GENTLE_REWARD.proximity  # the other gentle weights stay
    with pytest.raises(ValueError, match=r"task\.reward\.nope"):
        load_config("cpu", None, ["task.reward.nope=1"])
    with pytest.raises(ValueError, match=r"task\.nope"):
        load_config("cpu", None, ["task.nope=1"])


def test_a_list_override_sets_a_tuple_task_field() -> None:
    """``task.force_band=[1,30]`` (a list on the command line) becomes the field's tuple."""
    config = load_config("cpu", None, ["task=lift", "task.force_band=[1,30]"])
    assert config.task_config().force_band == (1, 30)


def test_presets_take_the_task_changes() -> None:
    """Touch gets its own budget in the fast and cpu presets; Reach keeps the preset's base;
    a later ``task=`` override decides which task's preset applies, and --set wins over both."""
    from mjx_arm.task.touch import TOUCH
    from mjx_arm.train.presets import CPU, FAST

    touch = load_config("fast", None, ["task=touch"])
    assert touch.num_timesteps == TOUCH.budgets["fast"].num_timesteps
    assert touch.num_envs == FAST.num_envs and touch.stop_at_success == FAST.stop_at_success
    reach = load_config("fast", None, ["task=touch", "task=reach"])
    assert reach.task == "reach" and reach.num_timesteps == FAST.num_timesteps
    cpu_touch = load_config("cpu", None, ["task=touch", "num_envs=128", "batch_size=128"])
    assert cpu_touch.num_envs == 128 and cpu_touch.num_evals == 33
    assert load_config("cpu", None, []).num_envs == CPU.num_envs  # Reach, the preset's task


@pytest.mark.parametrize("keep_best", [True, False])
def test_final_checkpoint_keeps_the_best_evaluation(tmp_path: Path, keep_best: bool) -> None:
    """A run that ends on its budget saves its best evaluation's params as the last checkpoint
    (keep_best), or the last params (keep_best=False). Checkpoints are captured, not written."""
    from mjx_arm.task.config import task_config
    from mjx_arm.train.progress import _Progress

    config = load_config("cpu", None, _tiny(30, checkpoint_every="10"))
    config = config.replace(keep_best=keep_best)
    progress = _Progress(RunDir(tmp_path / "run"), config, task_config("reach"), 0, quiet=True)
    saved = []
    progress._save_job = lambda step, make_policy, params, meta, resume=None: (
        lambda: saved.append((step, params, meta))
    )
    for step, success in ((10, 0.5), (20, 0.9), (30, 0.4)):
        progress.policy_params(step, None, {"w": np.full(2, float(step))})
        progress.progress(step, {"eval/episode_success": success, "training/sps": 1.0})
    assert [s for s, _, _ in saved] == [30]  # only the final one is due (every 10 evals)
    _, params, meta = saved[0]
    if keep_best:
        np.testing.assert_array_equal(params["w"], [20.0, 20.0])
        assert meta == {"params_step": 20, "params_success": 0.9}
    else:
        np.testing.assert_array_equal(params["w"], [30.0, 30.0])
        assert meta == {}


def test_a_checkpoint_restores_the_params_it_saved(tmp_path: Path) -> None:
    """Fresh params saved as a checkpoint and read back (as a resumed run does) are the same
    arrays, the normaliser's sample count included, and go back into the training state."""
    import jax

    from mjx_arm.task.observation import OBS_SIZE
    from mjx_arm.train.checkpoints import restore_brax_params
    from mjx_arm.train.learner import Learner, local_devices, make_mesh

    config = load_config("cpu", None, _tiny(4000))
    learner = Learner(config, OBS_SIZE, 6, make_mesh(local_devices(1)))
    state = learner.init(jax.random.PRNGKey(0), jax.random.PRNGKey(1))
    saved = learner.params(state)
    run = RunDir(tmp_path / "run")
    run.save_checkpoint(640, saved, {"task": "reach"})
    restored = restore_brax_params(RunDir.load_params(run.latest_checkpoint()))
    assert int(restored[0].count.lo) == int(saved[0].count.lo)
    for a, b in zip(jax.tree.leaves(saved), jax.tree.leaves(restored), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    state = learner.restore(state, restored)
    for a, b in zip(jax.tree.leaves(saved), jax.tree.leaves(learner.params(state)), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert int(RunDir.load_meta(run.latest_checkpoint())["step"]) == 640


def test_a_mistyped_setting_names_the_closest_known_one() -> None:
    with pytest.raises(
        ConfigError, match=r"unknown config key 'num_env' \(did you mean 'num_envs'\?\)"
    ):
        load_config("cpu", None, ["num_env=64"])
    with pytest.raises(ConfigError, match=r"'impll' \(did you mean 'impl'\?\)"):
        load_config("cpu", None, ["physics.impll=jax"])
    with pytest.raises(ConfigError) as caught:
        load_config("cpu", None, ["zzz=1"])
    assert "did you mean" not in str(caught.value)


def test_a_full_disk_is_named_before_the_lock_file_is_made(tmp_path: Path, monkeypatch) -> None:
    """The free-space check runs before anything is written: no empty .lock is left behind."""
    from mjx_arm.train.rundir import RunDir, RunDirError

    def full(self, free_bytes: int = 0) -> None:
        raise RunDirError(f"the disk of {self.path} has 0 MiB free")

    monkeypatch.setattr(RunDir, "check_writable", full)
    config = load_config("cpu", None, ["task=reach"])
    with pytest.raises(RunDirError, match="0 MiB free"):
        train(config, tmp_path / "run", quiet=True)
    assert not (tmp_path / "run" / ".lock").exists()


def test_the_normal_policy_bounds_its_mean_and_shares_its_std() -> None:
    """``policy_distribution=normal``: the policy's mean stays inside (-1, 1) whatever its last
    layer gives (a soft sign: a raw mean of 40, where the tanh-normal policy's action would sit
    saturated at 1, is 0.976), its std is one learned value per action entry, the same for
    every state, starting at NORMAL_INIT_STD, and the PPO loss and its metrics take it."""
    import jax
    import jax.numpy as jnp

    from mjx_arm.task.observation import OBS_SIZE
    from mjx_arm.train.learner import Learner, local_devices, make_mesh
    from mjx_arm.train.networks import NORMAL_INIT_STD

    config = load_config("cpu", None, _tiny(4000, policy_distribution="normal"))
    learner = Learner(config, OBS_SIZE, 6, make_mesh(local_devices(1)))
    state = learner.init(jax.random.PRNGKey(0), jax.random.PRNGKey(1))
    normalizer, policy, _ = learner.params(state)
    network = learner.network.policy_network
    obs = jax.random.normal(jax.random.PRNGKey(2), (64, OBS_SIZE)) * 100.0
    mean, std = network.apply(normalizer, policy, obs)
    assert mean.shape == std.shape == (64, 6)
    assert float(jnp.max(jnp.abs(mean))) < 1.0
    np.testing.assert_allclose(np.asarray(std), NORMAL_INIT_STD, rtol=1e-6)
    dist = learner.network.parametric_action_distribution
    assert float(jnp.max(jnp.abs(dist.mode((mean, std))))) < 1.0
    head = policy["params"]["Dense_0"]  # the mean's layer: give every state a raw mean of 40
    pushed = {
        "params": {
            **policy["params"],
            "Dense_0": {
                "kernel": jnp.zeros_like(head["kernel"]),
                "bias": jnp.full_like(head["bias"], 40.0),
            },
        }
    }
    mean, _ = network.apply(normalizer, pushed, obs)
    np.testing.assert_allclose(np.asarray(mean), 40.0 / 41.0, rtol=1e-6)


def test_a_normal_policy_run_names_why_it_does_not_export(tmp_path: Path) -> None:
    """Policy files hold tanh-normal policies; a run of the other distribution is refused
    before any checkpoint is read, with the reason."""
    from mjx_arm.policy import export_policy

    run = tmp_path / "run"
    (run / "checkpoints" / "000000000640").mkdir(parents=True)
    config = load_config("cpu", None, _tiny(4000, policy_distribution="normal"))
    (run / "config.json").write_text(json.dumps({"train": config.to_dict()}))
    with pytest.raises(ConfigError, match="'normal' policy"):
        export_policy(run, tmp_path / "policy.npz")


def test_the_kl_before_an_update_is_the_normalisers_alone(tmp_path: Path, monkeypatch) -> None:
    """``training/kl_before_update`` is read before the update's first gradient step: with the
    observation normaliser held still the policy is the rollout's (a KL under 1e-3, from the
    two programs' float rounding, and no transition outside the clip), while the KL of the
    whole update is not 0; with the normaliser moving, the first update's starts far from the
    rollout's policy (its statistics start empty: a KL of about 1 and most transitions
    clipped). With ``normalizer.after_update`` the normaliser moves after each update but the
    first, whose first step then starts from the rollout's policy."""
    import mjx_arm.train.learner as learner

    config = load_config("cpu", None, _tiny(600))
    row = RunDir(train(config, tmp_path / "moving", quiet=True).run_dir).read_metrics()[-1]
    assert float(row["training/kl_before_update"]) > 0.1
    assert float(row["training/clip_fraction_before_update"]) > 0.5
    monkeypatch.setattr(learner, "normalizer_update", lambda params, *_: params)
    row = RunDir(train(config, tmp_path / "still", quiet=True).run_dir).read_metrics()[-1]
    assert 0 <= float(row["training/kl_before_update"]) < 1e-3
    assert float(row["training/clip_fraction_before_update"]) == 0.0
    assert float(row["training/kl_mean"]) > 1e-3
    monkeypatch.undo()  # the normaliser moves, after the update (normalizer.after_update)
    sets = _tiny(1900, num_evals="4", **{"normalizer.after_update": "true"})
    run = RunDir(train(load_config("cpu", None, sets), tmp_path / "after", quiet=True).run_dir)
    first, *later = run.read_metrics()[1:]  # the first update takes its rollout in first
    assert float(first["training/kl_before_update"]) > 0.1 and len(later) == 2
    for row in later:
        assert 0 <= float(row["training/kl_before_update"]) < 1e-3
        assert float(row["training/clip_fraction_before_update"]) == 0.0
    assert json.loads((run.path / "config.json").read_text())["train"]["normalizer"]["after_update"]


def test_each_networks_gradient_and_the_largest_targets_are_logged(tmp_path: Path) -> None:
    """``policy_grad_norm`` and ``value_grad_norm`` are the two parts of ``grad_norm`` (per
    minibatch each is at most the whole and the whole at most their sum, so also their means
    over an epoch); ``reward_abs_max`` and ``value_target_abs_max`` are the largest of their
    minibatch (at least 0; the targets of a reward that is never 0 are not all 0)."""
    config = load_config("cpu", None, _tiny(600))
    row = RunDir(train(config, tmp_path / "run", quiet=True).run_dir).read_metrics()[-1]
    whole, policy, value = (
        float(row[f"training/{name}"])
        for name in ("grad_norm", "policy_grad_norm", "value_grad_norm")
    )
    assert 0 < policy <= whole * (1 + 1e-5) and 0 < value <= whole * (1 + 1e-5)
    assert whole <= (policy + value) * (1 + 1e-5)
    assert float(row["training/reward_abs_max"]) > 0
    assert float(row["training/value_target_abs_max"]) > 0


def test_a_fixed_force_scale_reaches_the_policy_file(tmp_path: Path) -> None:
    """``normalizer.force_scale``: the six ``contact_force`` entries of the saved policy are
    normalised by mean 0 and the fixed scale, every other entry by its running statistics."""
    from mjx_arm.policy.export import load_run
    from mjx_arm.task.observation import obs_slices

    sets = _tiny(600, task="touch", **{"normalizer.force_scale": "50"})
    result = train(load_config("cpu", None, sets), tmp_path / "fixed", quiet=True)
    arrays, _, _ = load_run(result.run_dir)
    force = obs_slices()["contact_force"]
    assert np.all(arrays["obs_std"][force] == 50.0) and np.all(arrays["obs_mean"][force] == 0.0)
    rest = np.delete(arrays["obs_std"], np.arange(force.start, force.stop))
    assert np.all(rest != 50.0) and np.all(rest != 1.0)  # running statistics, moved


def test_kl_stop_skips_the_rest_of_an_update(tmp_path: Path) -> None:
    """``kl_stop``: a bound no minibatch reaches skips no minibatch, and the first update is the
    one without the bound within float32 rounding (relative 1e-4 on its KL and policy loss, 1e-3
    on the evaluation after it; the two programs differ by the bound's select, which XLA may
    fuse and round differently on some CPUs, and a run's later epochs amplify that rounding); a
    bound of 1e-12 stops each update after its first gradient step (the normaliser held still
    through it, every later minibatch of 8 sees a KL over the bound), so at least 7 of 8
    minibatches are skipped and the logged KL is smaller than the unstopped run's."""
    base = _tiny(1900, num_evals="4", **{"normalizer.after_update": "true"})

    def rows(name: str, *sets: str) -> list[dict]:
        config = load_config("cpu", None, [*base, *sets])
        return RunDir(train(config, tmp_path / name, quiet=True).run_dir).read_metrics()[1:]

    free, loose, tight = rows("free"), rows("loose", "kl_stop=1e30"), rows("tight", "kl_stop=1e-12")
    assert all(float(b["training/skipped_fraction"]) == 0.0 for b in loose)
    assert len(loose) == len(free)
    for key, rel in (("training/kl_mean", 1e-4), ("training/policy_loss", 1e-4),
                     ("eval/episode_reward", 1e-3)):  # fmt: skip
        assert float(loose[0][key]) == pytest.approx(float(free[0][key]), rel=rel), key
    for row in tight[1:]:  # the first update takes its rollout in first (KL over 0 at once)
        assert float(row["training/skipped_fraction"]) >= 7 / 8
    assert sum(float(r["training/kl_mean"]) for r in tight[1:]) < sum(
        float(r["training/kl_mean"]) for r in free[1:]
    )


def test_episode_counts_read_the_ends_and_successes_of_the_rollout() -> None:
    """``episode_success`` is 1 exactly where an episode ended with a success (its summed
    ``success`` metric over 0), and an epoch's rate is its successes over its ended episodes."""
    import jax.numpy as jnp
    from brax.training.types import Transition

    from mjx_arm.train.epoch_metrics import episode_counts, episode_rates, update_view

    done = jnp.array([[0, 1, 0], [1, 0, 1]], dtype=jnp.float32)  # (N=2, T=3)
    success = jnp.array([[0, 2, 1], [0, 0, 1]], dtype=jnp.float32)  # summed over the episode
    extras = {"episode_done": done, "episode_metrics": {"success": success}, "truncation": done}
    zeros = jnp.zeros((2, 3))
    data = Transition(zeros, zeros, zeros, zeros, zeros, {"state_extras": extras})
    view = update_view(data)
    assert "episode_metrics" not in view.extras["state_extras"]
    np.testing.assert_array_equal(
        view.extras["state_extras"]["episode_success"], [[0, 1, 0], [0, 0, 1]]
    )
    counts = episode_counts(view)
    assert float(counts["episodes"]) == 3 and float(counts["episode_successes"]) == 2
    # two training steps of an epoch: (3 ended, 2 succeeded) and (1 ended, 0 succeeded)
    steps = [
        {"episodes": 3.0, "episode_successes": 2.0, "v_loss": 0.5},
        {"episodes": 1.0, "episode_successes": 0.0, "v_loss": 0.5},
    ]
    assert episode_rates(steps) == {"episodes": 4, "episode_success": 0.5}
    assert steps == [{"v_loss": 0.5}, {"v_loss": 0.5}]  # the counts taken out, the rest kept
    none = [{"episodes": 0.0, "episode_successes": 0.0}] * 3
    assert episode_rates([dict(m) for m in none])["episode_success"] == 0.0


def test_each_epoch_logs_its_training_episodes_and_their_success(tmp_path: Path) -> None:
    """32 envs step 60 times in the run's three epochs. An episode ends at its time limit of
    ``L`` control steps (read from an evaluation that did not succeed: 30, the shortest Reach
    takes on this arm, though ``task.episode_steps=5`` asks for less) or at a success, so every
    env ends at least ``60 // L`` episodes; the rate is a fraction of them."""
    sets = _tiny(1900, num_evals="4", **{"task.episode_steps": "5"})
    rows = RunDir(train(load_config("cpu", None, sets), tmp_path / "run", quiet=True).run_dir)
    initial, *epochs = rows.read_metrics()
    assert float(initial["eval/episode_success"]) == 0
    length = round(float(initial["eval/avg_episode_length"]))
    ended = [float(row["training/episodes"]) for row in epochs]
    assert all(n == int(n) and n >= 0 for n in ended)
    assert sum(ended) >= 32 * (60 // length) >= 32
    assert all(0 <= float(row["training/episode_success"]) <= 1 for row in epochs)


def test_clip_per_network_reaches_the_optimiser(tmp_path: Path) -> None:
    """``clip_per_network=true`` trains another run than the shared clip (this tiny run's
    gradients are over ``max_grad_norm``, so the two clips differ), and is saved with it."""
    last = {}
    for each in ("false", "true"):
        config = load_config("cpu", None, _tiny(600, clip_per_network=each))
        run = RunDir(train(config, tmp_path / each, quiet=True).run_dir)
        last[each] = run.read_metrics()[-1]
        saved = json.loads((run.path / "config.json").read_text())["train"]["clip_per_network"]
        assert saved is (each == "true")
    assert float(last["false"]["training/grad_norm"]) > 0.5
    assert last["false"]["training/total_loss"] != last["true"]["training/total_loss"]
