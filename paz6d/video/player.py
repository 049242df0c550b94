"""``VideoPlayer``: any pipeline over the frames of a video, a folder or a camera device.

Each frame goes through the pipeline (timed), the output is drawn on the frame with the pipeline's own
drawing, and the player writes an annotated video (:class:`~paz6d.video.video_file.VideoFileWriter`)
and a JSON-lines stream of the messages (:mod:`paz6d.video.records`), and returns a summary with the
frames per second and the per-frame latency::

    from paz6d.video.frames import open_frames
    from paz6d.pipelines import HaarCascadeDetector
    from paz6d.ssd.pipeline import draw_detections

    with open_frames("clip.mp4") as frames:
        player = VideoPlayer(HaarCascadeDetector(), frames, draw=draw_detections)
        summary = player.run(video="out/annotated.mp4", records="out/frames.jsonl")
    summary["latency_ms"]["p95"]

A camera with lens distortion given as ``undistort`` undistorts every frame before the pipeline
(which then works with the camera's ``K`` and no distortion). Stopping with Ctrl-C (a live device) ends
the run normally: the frames so far are kept.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Iterator, TextIO

import cv2
import numpy as np

from paz6d.backend.camera import Camera
from paz6d.backend.files import atomic_output
from paz6d.video.frames import Frame, FrameSource
from paz6d.video.video_file import VideoFileWriter
from paz6d.video.drawing import draw_entries
from paz6d.video.records import FrameRecord, record_line, result_entries


def has_display() -> bool:
    """Whether a window can be shown (an X11 or Wayland display is set)."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def latency_summary(latencies_s) -> dict[str, float | None]:
    """Median, 95th percentile (linear interpolation), mean and maximum of per-frame latencies, milliseconds."""
    values = np.asarray(latencies_s, dtype=np.float64) * 1000.0
    if values.size == 0:
        return {"median": None, "p95": None, "mean": None, "max": None}
    return {"median": round(float(np.median(values)), 3), "p95": round(float(np.percentile(values, 95)), 3),
            "mean": round(float(values.mean()), 3), "max": round(float(values.max()), 3)}


class VideoPlayer:
    """Applies ``pipeline`` to every frame of ``source``.

    Args:
        pipeline: ``image (H, W, 3) uint8 RGB -> output`` (messages, tuples of them, dataclasses, a dict).
        source: an open :class:`~paz6d.video.frames.FrameSource`.
        draw: ``(image, output) -> image``, the pipeline's drawing; default ``pipeline.draw`` when it has
            one, else :func:`draw_entries`.
        undistort: a camera whose distortion is removed from every frame before the pipeline.
        camera: the camera :func:`draw_entries` projects poses with (default: ``undistort``).
        transform: ``(output, frame) -> output`` applied after the pipeline (e.g. temporal smoothing),
            timed with it.
    """

    def __init__(self, pipeline: Callable, source: FrameSource, draw: Callable | None = None,
                 undistort: Camera | None = None, camera: Camera | None = None,
                 transform: Callable[[Any, Frame], Any] | None = None):
        if not callable(pipeline):
            raise ValueError(f"pipeline: expected a callable image -> messages, got {type(pipeline).__name__}")
        self.pipeline, self.source, self.transform = pipeline, source, transform
        self.undistort = undistort if undistort is not None and undistort.distortion is not None else None
        self.camera = camera or undistort
        if draw is None:
            draw = getattr(pipeline, "draw", None) or (lambda image, output: draw_entries(image, output, self.camera))
        self.draw = draw

    def play(self, max_frames: int | None = None) -> Iterator[tuple[Frame, Any, float]]:
        """``(frame, output, latency_s)`` of each frame (at most ``max_frames``); ``frame.image`` is the
        image the pipeline saw (undistorted when asked)."""
        if max_frames is not None and max_frames < 1:
            raise ValueError(f"max_frames: expected a whole number >= 1, got {max_frames}")
        for frame in self.source:
            image = frame.image
            if self.undistort is not None:
                image = cv2.undistort(image, self.undistort.K, self.undistort.distortion)
                frame = Frame(frame.index, frame.timestamp_s, image, frame.name)
            start = time.perf_counter()
            output = self.pipeline(image)
            if self.transform is not None:
                output = self.transform(output, frame)
            yield frame, output, time.perf_counter() - start
            if max_frames is not None and frame.index + 1 >= max_frames:
                return  # no frame read beyond the last one asked for

    def run(self, video: str | Path | None = None, records: str | Path | None = None,
            max_frames: int | None = None, progress: bool = False, show: bool = False,
            stream: TextIO | None = None) -> dict[str, Any]:
        """Plays the source, writing the annotated ``video`` and the JSON-lines ``records`` (each when given).

        Args:
            max_frames: stop after this many frames (default: all; a device runs until Ctrl-C).
            progress: a progress bar (tqdm).
            show: show the annotated frames in a window (``q`` stops); needs a display.
            stream: a text stream (e.g. ``sys.stdout``, a pipe to another process) that also gets each frame's
                JSON line, flushed as soon as the frame is done (``records`` appears only when the run ends).
        Returns:
            ``{"frames", "seconds", "fps", "pipeline_fps", "latency_ms": {median, p95, mean, max}, "first_frame_ms",
            "stopped"}``: ``fps`` counts the whole loop (read, pipeline, draw, write), ``pipeline_fps`` and the
            latencies the pipeline alone (the first frame's includes a model's one-time warm-up); ``stopped`` is
            ``"end"``, ``"interrupted"`` (Ctrl-C) or ``"window"`` (``q`` in the window).
        Raises:
            ValueError: ``show`` without a display, or a frame the pipeline or the source refuses.
        """
        if show and not has_display():
            raise ValueError("show: no display (DISPLAY/WAYLAND_DISPLAY unset); run without showing the frames")
        from tqdm.auto import tqdm

        latencies, stopped, started = [], "end", time.perf_counter()
        total = self.source.count if max_frames is None else min(max_frames, self.source.count or max_frames)
        with contextlib.ExitStack() as stack:
            writer = None if video is None else stack.enter_context(
                VideoFileWriter(video, self.source.fps, self.source.size))
            lines = None if records is None else stack.enter_context(atomic_output(records))
            bar = stack.enter_context(tqdm(total=total, desc=f"run ({self.source.kind})", unit="frame",
                                           disable=not progress))
            if show:
                stack.callback(cv2.destroyAllWindows)
            try:
                for frame, output, latency in self.play(max_frames):
                    latencies.append(latency)
                    if lines is not None or stream is not None:
                        line = record_line(FrameRecord(frame.index, round(frame.timestamp_s, 6),
                                                       round(latency * 1000.0, 3), result_entries(output),
                                                       frame.name)) + "\n"
                        if lines is not None:
                            lines.write(line.encode())
                        if stream is not None:
                            stream.write(line)
                            stream.flush()
                    if writer is not None or show:
                        annotated = self.draw(frame.image, output)
                        if writer is not None:
                            writer.write(annotated)
                        if show and _show(annotated):
                            stopped = "window"
                            break
                    bar.update(1)
            except KeyboardInterrupt:
                stopped = "interrupted"
        seconds = time.perf_counter() - started
        count = len(latencies)
        return {"frames": count, "seconds": round(seconds, 3), "fps": round(count / seconds, 3) if count else None,
                "pipeline_fps": round(count / sum(latencies), 3) if count and sum(latencies) > 0 else None,
                "latency_ms": latency_summary(latencies),
                "first_frame_ms": round(latencies[0] * 1000.0, 3) if count else None, "stopped": stopped}


def _show(image: np.ndarray) -> bool:
    """Shows ``image`` (RGB) in the player's window; True when ``q`` or Esc was pressed."""
    try:
        cv2.imshow("paz6d run", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        key = cv2.waitKey(1) & 0xFF
    except cv2.error as error:
        raise ValueError(f"show: OpenCV cannot open a window ({str(error).strip().splitlines()[-1]})") from error
    return key in (ord("q"), 27)
