"""Videos written frame by frame (an ``.mp4``, H.264 through imageio's ffmpeg, or a ``.gif``),
whether MuJoCo can render them here, and the camera that frames them."""

from __future__ import annotations

import math
import os
import sys
import warnings
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

# The geom groups of a converted arm: its visual meshes (MuJoCo's URDF importer) and its
# collision shapes, hidden in renders (mjx_arm.urdf.spec_edits).
VISUAL_GROUP, COLLISION_GROUP = 1, 3
# Room left around the framed points, as a share of the camera's distance to them.
FRAME_MARGIN = 0.08


class VideoWriter:
    """Frames streamed to an ``.mp4`` (H.264) or ``.gif`` file, opened at the first frame.

    Args:
        path: the video file; its suffix picks the format.
        fps: frames per second (the contract renders one frame per control step: 30).
    """

    def __init__(self, path: str | Path, fps: float = 30.0) -> None:
        self.path, self.fps, self.count = Path(path), float(fps), 0
        self._writer = None

    def append(self, frame: np.ndarray) -> None:
        """Add one RGB frame ``(height, width, 3)`` uint8."""
        with warnings.catch_warnings():
            # ffmpeg runs as a child process: JAX warns about any fork, but exec follows at once
            warnings.filterwarnings("ignore", message=r"os\.fork\(\) was called")
            if self._writer is None:
                self._writer = self._open()
            self._writer.append_data(np.asarray(frame, dtype=np.uint8))
        self.count += 1

    def _open(self):
        import imageio.v2 as imageio

        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.path.suffix.lower() == ".gif":
            return imageio.get_writer(self.path, mode="I", duration=1000.0 / self.fps, loop=0)
        return imageio.get_writer(
            self.path, fps=self.fps, codec="libx264", macro_block_size=2, ffmpeg_log_level="error"
        )

    def close(self) -> int:
        """Finish the file; returns the number of frames written."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None
        return self.count

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_video(path: str | Path, frames: Iterable[np.ndarray], fps: float = 30.0) -> int:
    """Write RGB frames to an ``.mp4`` (H.264) or ``.gif``; returns the frame count."""
    with VideoWriter(path, fps) as writer:
        for frame in frames:
            writer.append(frame)
    return writer.count


def rendering_available() -> tuple[bool, str]:
    """Whether MuJoCo can render off screen here: ``(ok, reason when not)``."""
    try:
        import mujoco

        model = mujoco.MjModel.from_xml_string("<mujoco><worldbody/></mujoco>")
        with mujoco.Renderer(model, 8, 8) as renderer:
            renderer.render()
    except Exception as exc:  # no EGL/OSMesa/GLFW, no display, driver errors
        backend = os.environ.get("MUJOCO_GL", "default")
        return False, (
            f"MuJoCo cannot render off screen here (MUJOCO_GL={backend}; "
            f"{type(exc).__name__}: {exc}); install EGL (e.g. apt-get install libegl1) "
            "or OSMesa and set MUJOCO_GL=egl or osmesa"
        )
    return True, ""


def fit_framebuffer(model: Any, width: int, height: int) -> None:
    """Grow a MuJoCo model's off-screen framebuffer to hold ``width`` x ``height`` frames."""
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), int(width))
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), int(height))


def scene_option(model: Any) -> Any:
    """What a MuJoCo render of ``model`` draws (an ``MjvOption``): MuJoCo's default groups,
    and the collision shapes where the model has no visual geom (its URDF's visuals are meshes
    MuJoCo cannot load, such as the Collada meshes of example-robot-data's arms)."""
    import mujoco

    option = mujoco.MjvOption()
    if not np.any(np.asarray(model.geom_group) == VISUAL_GROUP):
        option.geomgroup[COLLISION_GROUP] = 1
    return option


@dataclass(frozen=True)
class CameraView:
    """A camera at ``eye`` looking at ``target`` (m, world frame, z up), ``fovy`` degrees tall."""

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    fovy: float

    def axes(self) -> np.ndarray:
        """The camera's right, up and backward axes (the rows of a ``(3, 3)`` array)."""
        back = np.subtract(self.eye, self.target)
        back = back / np.linalg.norm(back)
        right = np.cross([0.0, 0.0, 1.0], back)
        right = right / np.linalg.norm(right)
        return np.stack([right, np.cross(back, right), back])

    def quat(self) -> np.ndarray:
        """The orientation (w, x, y, z) of a MuJoCo camera with this view, ``(4,)``."""
        import mujoco

        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, self.axes().T.ravel())
        return quat


def frame_points(
    points: np.ndarray, aspect: float, view: CameraView, margin: float = FRAME_MARGIN
) -> CameraView:
    """The camera that looks along ``view`` (its direction and ``fovy``) at the middle of
    ``points`` ``(k, 3)`` (m) from just far enough for every point to be in a frame of
    ``aspect`` (width over height), with ``margin`` (a share of the distance) to spare."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    axes = view.axes()
    target = 0.5 * (points.min(axis=0) + points.max(axis=0))
    spread = axes[:2] @ (points - target).T  # (2, k): across and up the frame
    target += 0.5 * (spread.min(axis=1) + spread.max(axis=1)) @ axes[:2]  # centred in it
    right, up, back = axes @ (points - target).T
    tan_v = math.tan(math.radians(view.fovy) / 2.0)
    tan_h = tan_v * aspect
    # a point ``b`` towards the camera from the target is ``distance - b`` deep
    distance = float(np.max(back + np.maximum(np.abs(right) / tan_h, np.abs(up) / tan_v)))
    distance *= 1.0 + margin
    eye = target + distance * axes[2]
    return CameraView(tuple(eye.tolist()), tuple(target.tolist()), view.fovy)


class FrameWindow:
    """Frames shown in a window as they come (an env's ``render_mode="human"``), through
    matplotlib, ``fps`` frames a second.

    Raises:
        RuntimeError: no display to show them on (on Linux, neither ``DISPLAY`` nor
            ``WAYLAND_DISPLAY`` is set), where drawing would silently show nothing.
    """

    def __init__(self, fps: float, title: str = "mjx_arm") -> None:
        missing = os.name == "posix" and sys.platform != "darwin"
        if missing and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            raise RuntimeError(
                "render_mode='human' needs a display, and this machine has none (DISPLAY and "
                "WAYLAND_DISPLAY are unset); use render_mode='rgb_array' and write the frames "
                "to a video (mjx_arm.video.write_video)"
            )
        self.fps, self.title = fps, title
        self._figure: Any = None
        self._image: Any = None

    def show(self, frame: np.ndarray) -> None:
        """Draw one RGB frame ``(height, width, 3)`` and wait one frame's time."""
        import matplotlib.pyplot as plt

        if self._figure is None:
            plt.ion()
            self._figure = plt.figure(self.title)
            self._image = plt.imshow(frame)
            plt.axis("off")
        else:
            self._image.set_data(frame)
        self._figure.canvas.draw_idle()
        plt.pause(1.0 / self.fps)
