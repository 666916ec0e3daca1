"""Gymnasium contract tests of the CPU envs, on both engines and both task ids.

Every test runs on both engines (``engine`` = "mujoco", "pybullet"; PyBullet is marked
``pybullet`` but never skipped) and, where the task matters, on both registered ids. Envs are
built through ``gymnasium.make`` so the registered wrappers (TimeLimit, order enforcing, the
passive checker) take part. Frames are kept tiny so rendering costs little; the file runs in
about 15 s on 2 cores.
"""

from __future__ import annotations

import math
import re
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path

import gymnasium as gym
import jax.numpy as jnp
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import mjx_arm  # noqa: F401  (registers the ids)
from mjx_arm.envs.registration import make_async_vec
from mjx_arm.paths import default_arm_urdf
from mjx_arm.task.config import REWARD_TERMS
from mjx_arm.task.observation import OBS_KEYS, flatten_obs
from mjx_arm.urdf.errors import UrdfError

ENGINES = [
    pytest.param("mujoco", id="mujoco"),
    pytest.param("pybullet", id="pybullet", marks=pytest.mark.pybullet),
]
ENV_IDS = ["mjx_arm/Reach-v0", "mjx_arm/Touch-v0"]
WIDTH, HEIGHT = 64, 48  # multiples of 16: no resizing by the video encoder
EPISODE_STEPS = 150
Make = Callable[..., gym.Env]  # the ``make`` fixture


@pytest.fixture(params=ENGINES)
def engine(request: pytest.FixtureRequest) -> str:
    """The physics engine under test."""
    return request.param


@pytest.fixture(params=ENV_IDS, ids=lambda env_id: env_id.split("/")[1])
def env_id(request: pytest.FixtureRequest) -> str:
    """The registered task id under test."""
    return request.param


@pytest.fixture
def make(engine: str, env_id: str) -> Iterator[Make]:
    """A factory of ``gymnasium.make(env_id, engine=engine, ...)`` that closes every env."""
    made: list[gym.Env] = []

    def _make(**kwargs) -> gym.Env:
        env = gym.make(env_id, engine=engine, **kwargs)
        made.append(env)
        return env

    yield _make
    for env in made:
        env.close()


def random_actions(n: int, seed: int, scale: float = 1.0) -> np.ndarray:
    """``n`` float32 actions, uniform in ``[-scale, scale]``, shape ``(n, 6)``."""
    rng = np.random.default_rng(seed)
    return rng.uniform(-scale, scale, size=(n, 6)).astype(np.float32)


def rollout(env: gym.Env, seed: int, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reset with ``seed``, apply ``actions``; return flat observations ``(n+1, 22)`` and rewards.

    Stops early (shorter arrays) when the episode ends.
    """
    obs, _ = env.reset(seed=seed)
    states, rewards = [flatten_obs(np, obs)], []
    for action in actions:
        obs, reward, terminated, truncated, _ = env.step(action)
        states.append(flatten_obs(np, obs))
        rewards.append(reward)
        if terminated or truncated:
            break
    return np.stack(states), np.array(rewards)


def assert_valid_obs(env: gym.Env, obs: dict) -> None:
    """Dict keys in contract order, every array float32 and inside the space."""
    assert tuple(obs) == OBS_KEYS
    for key in OBS_KEYS:
        assert obs[key].dtype == np.float32, key
        assert env.observation_space[key].contains(obs[key]), (key, obs[key])
    assert env.observation_space.contains(obs)


def checker_warnings(record: list[warnings.WarningMessage]) -> list[str]:
    """The Gymnasium checker's complaints (its logger prefixes them with ``WARN:``)."""
    return [str(w.message) for w in record if "WARN:" in str(w.message)]


# ----------------------------------------------------------------------------- Gymnasium API


def test_check_env(make: Make) -> None:
    """Gymnasium's own checker, render modes included, reports nothing."""
    env = make(render_mode="rgb_array", width=WIDTH, height=HEIGHT)
    assert tuple(env.observation_space.spaces) == OBS_KEYS
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (6,), np.float32)
    assert env.metadata["render_fps"] == 30
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        check_env(env.unwrapped, skip_render_check=False)
    assert checker_warnings(record) == []


def test_determinism_same_seed_same_actions(make: Make) -> None:
    """Exact repeat within an engine: twice in one env (with another episode between) and in a
    fresh env."""
    actions = random_actions(40, seed=1)
    env = make().unwrapped
    states_a, rewards_a = rollout(env, 7, actions)
    rollout(env, 8, random_actions(40, seed=2))  # an intervening episode, other actions
    states_b, rewards_b = rollout(env, 7, actions)
    states_c, rewards_c = rollout(make().unwrapped, 7, actions)
    assert len(states_a) == len(actions) + 1
    np.testing.assert_array_equal(states_a, states_b)
    np.testing.assert_array_equal(rewards_a, rewards_b)
    np.testing.assert_array_equal(states_a, states_c)
    np.testing.assert_array_equal(rewards_a, rewards_c)
    # and the seed matters: another seed starts elsewhere
    other, _ = rollout(env, 9, actions[:1])
    assert not np.array_equal(other[0], states_a[0])


def test_observations_inside_space_over_random_rollout(make: Make) -> None:
    """Full-range random actions: every observation float32, in the space, in key order."""
    env = make()
    obs, info = env.reset(seed=3)
    assert_valid_obs(env, obs)
    for action in random_actions(120, seed=3):
        obs, reward, terminated, truncated, info = env.step(action)
        assert_valid_obs(env, obs)
        assert math.isfinite(reward)
        assert not info["nonfinite"]
        if terminated or truncated:
            obs, info = env.reset()
            assert_valid_obs(env, obs)
    quat = obs["ee_pose"][3:]
    assert quat[0] >= 0 and abs(float(np.linalg.norm(quat)) - 1) < 1e-5


def test_step_types_info_and_truncation(make: Make) -> None:
    """Python float reward and bool flags; named info; truncated exactly at step 150."""
    env = make()
    _, info = env.reset(seed=4)
    assert {"is_success", "distance", "contact_force_norm"} <= set(info)
    zero = np.zeros(6, np.float32)  # hold still: no success, so the time limit ends it
    for t in range(1, EPISODE_STEPS + 1):
        obs, reward, terminated, truncated, info = env.step(zero)
        assert type(reward) is float
        assert type(terminated) is bool and type(truncated) is bool
        assert type(info["is_success"]) is bool and not info["is_success"]
        assert isinstance(info["distance"], float) and info["distance"] > 0
        assert isinstance(info["contact_force_norm"], float)
        assert set(info["reward_terms"]) == set(REWARD_TERMS)
        assert all(isinstance(v, float) for v in info["reward_terms"].values())
        assert not terminated
        assert truncated is (t == EPISODE_STEPS), t
    d = info["distance"]
    np.testing.assert_allclose(
        float(np.linalg.norm(obs["ee_pose"][:3] - obs["target_rel"])), d, rtol=1e-5, atol=1e-6
    )
    assert info["reward_terms"]["distance"] == pytest.approx(1 - math.exp(-d / 0.1))


# ----------------------------------------------------------------------------- contact force

FREE_MOTION_FORCE = 0.5  # N: well below the 1 N lower edge of the Touch success band


def quat_to_matrix(quat: np.ndarray) -> np.ndarray:
    """Rotation matrix ``(3, 3)`` of a unit quaternion (w, x, y, z)."""
    w, x, y, z = (float(v) for v in quat)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def test_contact_force_about_zero_in_free_motion(make: Make) -> None:
    """The tared F/T reading removes the tool's weight and inertia while the arm moves."""
    env = make()
    env.reset(seed=12)
    for action in random_actions(40, seed=12, scale=0.3):  # stays well above the table
        obs, _, _, _, info = env.step(action)
        assert info["contact_force_norm"] < FREE_MOTION_FORCE, obs["contact_force"]
        assert np.abs(obs["contact_force"][3:]).max() < 0.1, obs["contact_force"]


def test_contact_force_about_zero_at_reset(make: Make) -> None:
    """Right after a reset the arm is at rest and touches nothing: the reading is about zero."""
    obs, info = make().reset(seed=12)
    assert info["contact_force_norm"] < FREE_MOTION_FORCE, obs["contact_force"]


def test_contact_force_when_pressing(engine: str) -> None:
    """The box put 5 mm into the tool tip pushes it up: a world +z force of several newtons."""
    from mjx_arm.urdf.scene import box_top_offset

    env = gym.make("mjx_arm/Touch-v0", engine=engine)
    try:
        obs, _ = env.reset(seed=0)
        tip = obs["ee_pose"][:3].astype(np.float64)
        box = tip - np.array([0.0, 0.0, box_top_offset() - 0.005])
        obs, info = env.reset(seed=0, options={"target": box})
        assert info["distance"] == pytest.approx(0.005, abs=1e-3)
        best = (0.0, np.zeros(3))
        for _ in range(3):
            obs, _, terminated, _, info = env.step(np.zeros(6, np.float32))
            world = quat_to_matrix(obs["ee_pose"][3:]) @ obs["contact_force"][:3]
            best = max(best, (info["contact_force_norm"], world), key=lambda b: b[0])
            if terminated:
                assert info["is_success"]
                break
    finally:
        env.close()
    norm, world = best
    assert norm > 1.0, "no contact force while the box presses the tool"
    assert world[2] > 0.5 * norm, world  # the box pushes the tool up


# ----------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_nonfinite_action_raises(make: Make, bad: float) -> None:
    """NaN and inf actions are refused with a message that says so."""
    env = make()
    env.reset(seed=5)
    action = np.zeros(6, np.float32)
    action[2] = bad
    with pytest.raises(ValueError, match=r"NaN|inf"):
        env.step(action)


def test_rejected_action_changes_nothing(make: Make) -> None:
    """A refused action leaves the physics untouched: the episode goes on as without it."""
    env = make().unwrapped
    actions = random_actions(3, seed=6)
    expected, _ = rollout(env, 6, actions)
    states = [flatten_obs(np, env.reset(seed=6)[0])]
    for action in actions:
        with pytest.raises(ValueError):
            env.step(np.full(6, np.nan, np.float32))
        states.append(flatten_obs(np, env.step(action)[0]))
    np.testing.assert_array_equal(np.stack(states), expected)


def test_out_of_range_action_is_clipped(make: Make) -> None:
    """Actions outside [-1, 1] act exactly like their clipped values."""
    env = make().unwrapped
    wild = np.array([[3.0, -2.0, 1.5, -7.0, 0.2, 1e6]], np.float32)
    clipped, rewards_clipped = rollout(env, 11, np.clip(wild, -1, 1))
    raw, rewards_raw = rollout(env, 11, wild)
    np.testing.assert_array_equal(raw, clipped)
    np.testing.assert_array_equal(rewards_raw, rewards_clipped)
    # and apply_action reports the clipped joint velocity targets
    np.testing.assert_allclose(
        env.apply_action(wild[0]),
        np.clip(wild[0], -1, 1) * env.task.action_scale * env.arm.v_max,
        rtol=1e-6,
    )


@pytest.mark.parametrize(
    "action",
    [np.zeros(5), np.zeros((6, 1)), np.zeros((2, 6)), np.float32(0.0), np.zeros(7)],
    ids=["5", "6x1", "2x6", "scalar", "7"],
)
def test_wrong_action_shape_raises(make: Make, action: np.ndarray) -> None:
    """Anything but shape (6,) is refused (no silent broadcasting)."""
    env = make()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step(action)


def test_step_before_reset_raises(make: Make) -> None:
    """Stepping a fresh env is an error, not undefined physics."""
    env = make().unwrapped
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(6, np.float32))


def _break_mass(text: str) -> str:
    """The tool link's mass made negative (a layer-3 error)."""
    return text.replace('<mass value="0.2"/>', '<mass value="-0.2"/>', 1)


def _drop_elbow_limit(text: str) -> str:
    """The elbow's ``<limit>`` removed (a layer-2 error)."""
    return re.sub(r'(<joint name="elbow_joint".*?)<limit[^>]*/>', r"\1", text, count=1, flags=re.S)


@pytest.mark.parametrize(
    ("breakage", "message"),
    [
        pytest.param(_break_mass, r"link 'tool_link': has negative mass", id="negative-mass"),
        pytest.param(
            _drop_elbow_limit,
            r"joint 'elbow_joint': is revolute but has no <limit>",
            id="missing-limit",
        ),
    ],
)
def test_invalid_urdf_stops_construction(
    engine: str, env_id: str, tmp_path: Path, breakage: Callable[[str], str], message: str
) -> None:
    """A broken copy of the arm URDF stops construction with the validator's report."""
    broken = tmp_path / "ur5e_broken.urdf"
    text = default_arm_urdf().read_text()
    broken.write_text(breakage(text))
    assert broken.read_text() != text
    with pytest.raises(UrdfError, match=message) as err:
        gym.make(env_id, engine=engine, arm=broken)
    assert str(broken) in str(err.value)
    assert "Fix:" in str(err.value)


# ----------------------------------------------------------------------------- rendering


def test_render_frame(make: Make) -> None:
    """An rgb_array frame of the requested size that shows the scene and follows the arm."""
    env = make(render_mode="rgb_array", width=WIDTH, height=HEIGHT)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (HEIGHT, WIDTH, 3) and frame.dtype == np.uint8
    assert frame.std() > 5.0, "blank frame"
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 10
    for action in random_actions(10, seed=0):
        env.step(action)
    moved = env.render()
    assert moved.shape == frame.shape
    assert not np.array_equal(moved, frame), "the frame does not follow the arm"


def test_record_video(engine: str, tmp_path: Path) -> None:
    """RecordVideo writes one .mp4 of a short episode."""
    env = gym.make(
        "mjx_arm/Touch-v0", engine=engine, render_mode="rgb_array", width=WIDTH, height=HEIGHT
    )
    folder = tmp_path / "videos"
    env = gym.wrappers.RecordVideo(
        env, str(folder), episode_trigger=lambda _: True, disable_logger=True
    )
    env.reset(seed=0)
    for action in random_actions(8, seed=0):
        env.step(action)
    env.close()
    videos = list(folder.glob("*.mp4"))
    assert len(videos) == 1, list(folder.iterdir())
    assert videos[0].stat().st_size > 1000


# ----------------------------------------------------------------------------- vector envs


# JAX warns inside an at-fork hook, where a raised warning becomes an unraisable exception
@pytest.mark.filterwarnings("error:.*os.fork.*:RuntimeWarning")
@pytest.mark.filterwarnings("error::pytest.PytestUnraisableExceptionWarning")
@pytest.mark.parametrize("mode", ["sync", "async"])
def test_make_vec(engine: str, env_id: str, mode: str) -> None:
    """Gymnasium's sync and async vector envs run both engines (each env its own world); the
    async workers are not forked from this multithreaded JAX process (JAX's warning fails it)."""
    jnp.zeros(1).block_until_ready()  # JAX's threads are running, as in a training process
    if mode == "async":
        envs = make_async_vec(env_id, num_envs=2, engine=engine)
    else:
        envs = gym.make_vec(env_id, num_envs=2, vectorization_mode=mode, engine=engine)
    try:
        obs, info = envs.reset(seed=0)
        assert tuple(obs) == OBS_KEYS
        for key in OBS_KEYS:
            assert obs[key].shape == (2, envs.single_observation_space[key].shape[0])
            assert obs[key].dtype == np.float32
        assert not np.array_equal(obs["target_rel"][0], obs["target_rel"][1])
        for _ in range(3):
            obs, reward, terminated, truncated, info = envs.step(envs.action_space.sample())
            assert envs.observation_space.contains(obs)
            assert reward.shape == (2,) and terminated.shape == (2,) and truncated.shape == (2,)
            assert "distance" in info and info["distance"].shape == (2,)
    finally:
        envs.close()
