"""Frames from a video file, an image folder or a camera device, as uint8 RGB images with timestamps.

:func:`open_frames` tells the three apart (an ``int`` or a string of digits is a device index, a folder
is an image folder, anything else a video file) and checks the source before any frame is used: the
file or folder exists, the video decodes, the device opens, and the first frame has the expected size::

    with open_frames("clip.mp4", size=(640, 480)) as frames:
        for frame in frames:                   # Frame(index, timestamp_s, image (480, 640, 3) uint8 RGB)
            ...

Timestamps (seconds from the first frame): a video's own (OpenCV ``CAP_PROP_POS_MSEC``), else
``index / fps``; a folder's ``index / fps`` (``fps`` given, default :data:`DEFAULT_FOLDER_FPS`); a device's
clock (``time.monotonic``). Every frame must have the size of the first one (or the given ``size``):
a camera's intrinsics hold for one image size only.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from paz6d.backend.image import load_image

#: Image files an image folder is read from (sorted by name).
FOLDER_SUFFIXES = (".png", ".jpg", ".jpeg")
#: Frames per second of an image folder when none is given.
DEFAULT_FOLDER_FPS = 30.0


class FrameSourceError(ValueError):
    """A frame source that cannot be read: missing file, undecodable video, closed device, empty folder."""


class FrameSizeError(ValueError):
    """A frame whose size differs from the expected one (the camera's or the first frame's)."""


@dataclass(frozen=True)
class Frame:
    """One frame: its position ``index`` (from 0), ``timestamp_s`` (seconds), ``image`` uint8 RGB ``(H, W, 3)``
    and, for a folder's frames, the image file's ``name``."""

    index: int
    timestamp_s: float
    image: np.ndarray
    name: str | None = None


def _check_fps(fps: float | None, name: str = "fps") -> float | None:
    if fps is None:
        return None
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not math.isfinite(fps) or fps <= 0:
        raise ValueError(f"{name}: expected a positive number of frames per second, got {fps!r}")
    return float(fps)


def device_index(spec: str | Path | int) -> int | None:
    """The camera device index ``spec`` names (an ``int`` or a string of digits), else ``None``."""
    if isinstance(spec, bool):
        return None
    if isinstance(spec, int):
        return spec
    text = str(spec)
    return int(text) if text.isdigit() else None


class FrameSource:
    """An open frame source; iterate it for :class:`Frame` s, close it (or use ``with``) when done.

    Attributes:
        kind: ``"video"``, ``"folder"`` or ``"device"``.
        name: the file, folder or ``device N`` (for messages).
        fps: frames per second (a video's own rate, a folder's given one, a device's reported one).
        size: ``(width, height)`` of every frame, pixels.
        count: number of frames when known beforehand (a folder's; a video's as its header says), else ``None``.
    """

    def __init__(self, kind: str, name: str, fps: float, size: tuple[int, int], count: int | None,
                 capture: cv2.VideoCapture | None = None, files: tuple[Path, ...] = (),
                 first: np.ndarray | None = None, first_milliseconds: float = 0.0):
        self.kind, self.name, self.fps, self.size, self.count = kind, name, fps, size, count
        self._capture, self._files, self._first = capture, files, first
        self._first_milliseconds = first_milliseconds
        self._started = False

    def __enter__(self) -> "FrameSource":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Releases the video file or device (frames can no longer be read)."""
        if self._capture is not None:
            self._capture.release()
            self._capture = None

    def _check_size(self, image: np.ndarray, index: int, where: str) -> np.ndarray:
        height, width = image.shape[:2]
        if (width, height) != self.size:
            raise FrameSizeError(f"{where}: frame {index} is {width}x{height} pixels, expected "
                                 f"{self.size[0]}x{self.size[1]} (width x height: the camera's, else the first "
                                 "frame's); a camera's intrinsics hold for one image size")
        return image

    def __iter__(self) -> Iterator[Frame]:
        if self._started:
            raise ValueError(f"{self.name}: frames can be read once; open the source again")
        self._started = True
        if self.kind == "folder":
            yield from self._folder_frames()
        else:
            yield from self._capture_frames()

    def _folder_frames(self) -> Iterator[Frame]:
        for index, path in enumerate(self._files):
            image = self._first if index == 0 else load_image(path)
            yield Frame(index, index / self.fps, self._check_size(image, index, str(path)), path.name)

    def _capture_frames(self) -> Iterator[Frame]:
        index, start = 0, time.monotonic()
        image, milliseconds = self._first, self._first_milliseconds
        while image is not None:
            if self.kind == "device":
                timestamp = time.monotonic() - start
            elif milliseconds > 0 or index == 0:
                timestamp = milliseconds / 1000.0
            else:  # the backend gives no timestamps
                timestamp = index / self.fps
            yield Frame(index, timestamp, self._check_size(image, index, self.name))
            index += 1
            if self._capture is None:
                return
            image, milliseconds = _read(self._capture)


def _read(capture: cv2.VideoCapture) -> tuple[np.ndarray | None, float]:
    """The next frame (RGB) and its position (ms), or ``(None, 0)`` at the end."""
    ok, image = capture.read()
    if not ok or image is None:
        return None, 0.0
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB), float(capture.get(cv2.CAP_PROP_POS_MSEC))


def folder_files(folder: Path) -> tuple[Path, ...]:
    """The image files (:data:`FOLDER_SUFFIXES`) of ``folder`` sorted by name.

    Raises:
        FrameSourceError: no image file in it.
    """
    files = tuple(sorted(path for path in folder.iterdir() if path.suffix.lower() in FOLDER_SUFFIXES
                         and path.is_file()))
    if not files:
        raise FrameSourceError(f"{folder}: no image file ({', '.join(FOLDER_SUFFIXES)}) in this folder")
    return files


def _open_capture(target, name: str, device: bool) -> cv2.VideoCapture:
    previous = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)  # its own warnings repeat ours
    try:
        capture = cv2.VideoCapture(target)
    finally:
        cv2.utils.logging.setLogLevel(previous)
    if not capture.isOpened():
        capture.release()
        if device:
            raise FrameSourceError(f"{name}: the camera device does not open (no such device, or it is busy); "
                                   "list devices with `v4l2-ctl --list-devices` on Linux")
        raise FrameSourceError(f"{name}: cannot open the video (corrupt file or a codec OpenCV's FFmpeg cannot "
                               "decode)")
    return capture


def open_frames(spec: str | Path | int, fps: float | None = None, size: tuple[int, int] | None = None) -> FrameSource:
    """Opens a video file, an image folder or a camera device (see the module docstring) and reads its first frame.

    Args:
        spec: a video file, an image folder, or a device index (``int`` or a string of digits).
        fps: frames per second of an image folder (default :data:`DEFAULT_FOLDER_FPS`), and of a device
            that reports none; a video keeps its own rate.
        size: ``(width, height)`` every frame must have (a camera's), pixels; default: the first frame's.
    Raises:
        FrameSourceError: a missing file or folder, an empty folder, a video that does not decode, a device
            that does not open or gives no frame.
        FrameSizeError: a first frame of another size than ``size``.
        ValueError: a bad ``fps`` or ``size``.
    """
    fps = _check_fps(fps)
    if size is not None:
        width, height = size
        size = (int(width), int(height))
        if size[0] <= 0 or size[1] <= 0:
            raise ValueError(f"size: expected positive (width, height) pixels, got {size}")
    if isinstance(spec, str) and not spec.strip():
        raise FrameSourceError("input: empty; expected a video file, an image folder or a device index")
    index = device_index(spec)
    if index is not None:
        name = f"device {index}"
        capture = _open_capture(index, name, device=True)
        first, milliseconds = _read(capture)
        kind, count = "device", None
        rate = capture.get(cv2.CAP_PROP_FPS)
        rate = float(rate) if math.isfinite(rate) and rate > 0 else (fps or DEFAULT_FOLDER_FPS)
        files: tuple[Path, ...] = ()
    else:
        path = Path(spec)
        name = str(path)
        if path.is_dir():
            files = folder_files(path)
            first, capture, milliseconds = load_image(files[0]), None, 0.0
            kind, count, rate = "folder", len(files), fps or DEFAULT_FOLDER_FPS
        elif not path.is_file():
            raise FrameSourceError(f"{path}: no such video file or image folder")
        else:
            capture = _open_capture(str(path), name, device=False)
            first, milliseconds = _read(capture)
            kind, files = "video", ()
            frames = capture.get(cv2.CAP_PROP_FRAME_COUNT)
            count = int(frames) if math.isfinite(frames) and frames > 0 else None
            rate = capture.get(cv2.CAP_PROP_FPS)
            rate = float(rate) if math.isfinite(rate) and rate > 0 else (fps or DEFAULT_FOLDER_FPS)
    if first is None:
        if capture is not None:
            capture.release()
        what = "the camera device gives no frame" if kind == "device" else "no frame decodes (corrupt or empty video)"
        raise FrameSourceError(f"{name}: {what}")
    first_size = (first.shape[1], first.shape[0])
    source = FrameSource(kind, name, rate, size or first_size, count, capture, files, first, milliseconds)
    try:
        source._check_size(first, 0, str(files[0]) if files else name)
    except FrameSizeError:
        source.close()
        raise
    return source
