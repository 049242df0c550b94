"""Writing a video file frame by frame (OpenCV ``VideoWriter``), appearing complete or not at all.

The frames go to a temporary file beside the target (named with
:data:`~paz6d.backend.files.TEMPORARY_PREFIX`, same extension, so that FFmpeg picks the same container);
:meth:`VideoFileWriter.finish` closes it and renames it into place, :meth:`VideoFileWriter.discard`
removes it. As a context manager it finishes when the block ends normally and discards otherwise.
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from paz6d.backend.files import TEMPORARY_PREFIX, prepare_output_file
from paz6d.backend.image import as_image

#: FourCC codes by file extension (``mp4v`` MPEG-4 part 2 plays in common players; ``FFV1`` is lossless).
CODECS = {".mp4": "mp4v", ".avi": "MJPG", ".mkv": "FFV1"}


class VideoFileWriter:
    """Writes uint8 RGB ``(H, W, 3)`` frames of one size to ``path`` at ``fps`` frames per second.

    Args:
        path: the video file (extension ``.mp4``, ``.avi`` or ``.mkv``).
        fps: frames per second, positive.
        size: ``(width, height)`` pixels of every frame.
        codec: a FourCC code (default by extension, :data:`CODECS`).
    Raises:
        ValueError: an unknown extension, a bad ``fps``/``size``, a path that cannot receive a file, or a
            codec this OpenCV cannot write.
    """

    def __init__(self, path: str | Path, fps: float, size: tuple[int, int], codec: str | None = None):
        path = Path(path)
        if path.suffix.lower() not in CODECS:
            raise ValueError(f"{path}: expected a video file name ending in {', '.join(CODECS)}")
        if not (isinstance(fps, (int, float)) and np.isfinite(fps) and fps > 0):
            raise ValueError(f"fps: expected a positive number of frames per second, got {fps!r}")
        width, height = (int(value) for value in size)
        if width <= 0 or height <= 0:
            raise ValueError(f"size: expected positive (width, height) pixels, got {size}")
        self.path, self.fps, self.size = prepare_output_file(path), float(fps), (width, height)
        self.temporary = path.with_name(f"{TEMPORARY_PREFIX}{path.stem}-{os.getpid()}{path.suffix}")
        fourcc = codec or CODECS[path.suffix.lower()]
        self._writer = cv2.VideoWriter(str(self.temporary), cv2.VideoWriter_fourcc(*fourcc), self.fps, self.size)
        if not self._writer.isOpened():
            self._writer.release()
            self.temporary.unlink(missing_ok=True)
            raise ValueError(f"{path}: OpenCV cannot write {fourcc!r} video here")
        self.frames = 0

    def write(self, image) -> None:
        """Appends one uint8 RGB ``(H, W, 3)`` frame of the writer's size."""
        image = as_image(image, "frame", channels=3)
        if (image.shape[1], image.shape[0]) != self.size:
            raise ValueError(f"frame: {image.shape[1]}x{image.shape[0]} pixels, the video is "
                             f"{self.size[0]}x{self.size[1]}")
        self._writer.write(cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        self.frames += 1

    def finish(self) -> Path:
        """Closes the file and moves it to ``path``."""
        self._writer.release()
        os.replace(self.temporary, self.path)
        return self.path

    def discard(self) -> None:
        """Closes and removes the unfinished file."""
        self._writer.release()
        self.temporary.unlink(missing_ok=True)

    def __enter__(self) -> "VideoFileWriter":
        return self

    def __exit__(self, kind, value, traceback) -> None:
        if kind is None:
            self.finish()
        else:
            self.discard()
