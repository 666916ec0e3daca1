"""The render camera frames the arm and the task area, in every engine (:mod:`mjx_arm.envs.camera`).

A tall arm (the Panda, whose home pose stands higher than the shipped UR5e's) must not be cut at
the top of the frame; an arm whose URDF visuals MuJoCo cannot load (Collada) is drawn by its
collision shapes instead of not at all.
"""

from __future__ import annotations

import math
import sysconfig
from pathlib import Path

import numpy as np
import pytest

from mjx_arm.replay import rendering_available
from mjx_arm.task import reach_config, touch_config
from mjx_arm.video import COLLISION_GROUP, VISUAL_GROUP, CameraView, frame_points

ROBOTS = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
PANDA = ROBOTS / "panda_description/urdf/panda.urdf"
UR10 = ROBOTS / "ur_description/urdf/ur10_robot.urdf"
needs_render = pytest.mark.skipif(not rendering_available()[0], reason=rendering_available()[1])
needs_robots = pytest.mark.skipif(not ROBOTS.is_dir(), reason="example-robot-data is not installed")
BORDER = 2  # pixels at each edge of the frame that no part of the arm may touch


def _in_frame(view: CameraView, points: np.ndarray, aspect: float) -> np.ndarray:
    """Each point's largest share of the half field of view it spans (<= 1: in the frame)."""
    right, up, back = view.axes() @ (points - np.asarray(view.eye)).T
    depth = -back
    tan_v = math.tan(math.radians(view.fovy) / 2)
    return np.maximum(np.abs(right) / (depth * tan_v * aspect), np.abs(up) / (depth * tan_v))


@pytest.mark.parametrize("aspect", [4 / 3, 1.0, 0.5, 16 / 9])
def test_framed_points_are_all_in_the_frame_and_fill_it(aspect: float) -> None:
    rng = np.random.default_rng(0)
    points = rng.uniform((-0.3, -0.6, -0.1), (0.9, 0.6, 1.4), (200, 3))
    scene = CameraView((1.45, -1.05, 0.85), (0.35, 0.0, 0.1), 45.0)
    view = frame_points(points, aspect, scene, margin=0.05)
    share = _in_frame(view, points, aspect)
    assert share.max() <= 1.0 and share.max() > 0.9  # in, and not lost in the middle
    direction = np.subtract(view.target, view.eye)
    np.testing.assert_allclose(  # the scene's direction and field of view kept
        direction / np.linalg.norm(direction), scene.axes()[2] * -1, atol=1e-12
    )
    assert view.fovy == 45.0


def _arm_pixels(env) -> np.ndarray:
    """A mask ``(height, width)`` of the pixels where the MuJoCo env's frame shows the arm."""
    import mujoco

    env.render()  # aims the camera
    model = env.model
    with mujoco.Renderer(model, env.height, env.width) as renderer:
        renderer.enable_segmentation_rendering()
        renderer.update_scene(env.data, camera="main", scene_option=env._scene_option)
        seg = renderer.render()
    arm = np.isin(model.geom_group, (VISUAL_GROUP, COLLISION_GROUP))
    ids, kinds = seg[..., 0], seg[..., 1]
    return (kinds == int(mujoco.mjtObj.mjOBJ_GEOM)) & arm[np.clip(ids, 0, model.ngeom - 1)]


@needs_render
@pytest.mark.parametrize(
    ("arm", "task"),
    [
        pytest.param(PANDA, reach_config(), id="panda", marks=needs_robots),
        pytest.param(UR10, touch_config(), id="ur10", marks=needs_robots),
        pytest.param(None, touch_config(), id="ur5e"),
    ],
)
def test_mujoco_frames_the_whole_arm(arm, task) -> None:
    from mjx_arm.envs.mujoco_env import MujocoArmEnv

    env = MujocoArmEnv(task, arm, render_mode="rgb_array", width=320, height=240)
    try:
        env.reset(seed=0)
        mask = _arm_pixels(env)
    finally:
        env.close()
    assert mask.mean() > 0.03  # the arm is drawn, and not as a speck
    edges = np.concatenate(
        [mask[:BORDER].ravel(), mask[-BORDER:].ravel(), mask[:, :BORDER].ravel(),
         mask[:, -BORDER:].ravel()]
    )  # fmt: skip
    assert not edges.any()  # no part of it cut by the frame's edge


@pytest.mark.pybullet
@pytest.mark.parametrize(
    ("arm", "task"),
    [
        pytest.param(PANDA, reach_config(), id="panda", marks=needs_robots),
        pytest.param(UR10, touch_config(), id="ur10", marks=needs_robots),
        pytest.param(None, touch_config(), id="ur5e"),
    ],
)
def test_pybullet_frames_the_whole_arm_as_mujoco_does(arm, task) -> None:
    import pybullet

    from mjx_arm.envs.camera import task_camera
    from pybullet_ref.env import PybulletArmEnv

    env = PybulletArmEnv(task, arm, render_mode="rgb_array", width=320, height=240)
    try:
        env.reset(seed=0)
        env.render()  # makes the camera
        view, projection = env._camera
        *_, seg = env.client.getCameraImage(
            320, 240, viewMatrix=view, projectionMatrix=projection,
            renderer=pybullet.ER_TINY_RENDERER,
        )  # fmt: skip
        camera = task_camera(env.arm_task, 320 / 240)
        expected = env.client.computeViewMatrix(camera.eye, camera.target, [0.0, 0.0, 1.0])
    finally:
        env.close()
    np.testing.assert_allclose(view, expected)  # the camera MuJoCo's env renders from
    mask = np.asarray(seg).reshape(240, 320) == env.body
    assert mask.mean() > 0.03
    assert not (mask[:BORDER].any() or mask[-BORDER:].any())
    assert not (mask[:, :BORDER].any() or mask[:, -BORDER:].any())


@pytest.mark.parametrize("engine", ["mujoco", pytest.param("pybullet", marks=pytest.mark.pybullet)])
def test_human_mode_without_a_display_warns_and_dt_is_the_control_step(
    engine: str, monkeypatch
) -> None:
    import gymnasium as gym

    import mjx_arm  # noqa: F401  (registers the ids)

    env = gym.make("mjx_arm/Reach-v0", engine=engine)
    try:
        assert env.unwrapped.dt == env.get_wrapper_attr("dt") == reach_config().ctrl_dt
    finally:
        env.close()
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.warns(UserWarning, match="render_mode='human' needs a display"):
        human = gym.make("mjx_arm/Reach-v0", engine=engine, render_mode="human")
    try:  # the env still runs (Gymnasium's checker makes every listed mode); nothing is shown
        human.reset(seed=0)
        assert human.render() is None
    finally:
        human.close()
