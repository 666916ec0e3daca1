"""Videos written frame by frame: an ``.mp4`` (H.264, through imageio's ffmpeg) or a ``.gif``."""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from pathlib import Path

import numpy as np


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
