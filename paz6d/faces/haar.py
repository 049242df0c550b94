"""Viola-Jones Haar cascade detection with the cascades that OpenCV ships in ``cv2.data``.

Example:
    >>> import skimage.data
    >>> from paz6d.faces.haar import HaarCascadeDetector
    >>> boxes = HaarCascadeDetector("frontalface_default")(skimage.data.astronaut())
    >>> len(boxes)
    1
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

from paz6d.abstract import Box2D, KeyedStep, Processor, SequentialProcessor
from paz6d.backend.image import as_image
from paz6d.processors.boxes import ConvertBoxFormat, ToBoxes2D

CASCADE_PREFIX = "haarcascade_"
#: Largest image-pyramid step: beyond it the pyramid has a single level (and OpenCV's buffers
#: overflow for infinite steps).
MAX_SCALE_FACTOR = 100.0


def cascade_folder() -> Path:
    """Folder holding OpenCV's bundled Haar cascade XML files (``cv2.data.haarcascades``)."""
    return Path(cv2.data.haarcascades)


def available_cascades() -> list[str]:
    """Sorted names of the bundled cascades, e.g. ``"frontalface_default"``, ``"eye"``, ``"smile"``."""
    return sorted(path.name[len(CASCADE_PREFIX):-len(".xml")]
                  for path in cascade_folder().glob(f"{CASCADE_PREFIX}*.xml"))


def cascade_path(cascade: str | Path) -> Path:
    """Resolves a bundled cascade name (``"eye"``, ``"haarcascade_eye"``, ``"haarcascade_eye.xml"``) or an XML path.

    Raises:
        ValueError: unknown name or missing file; the message lists the available cascades.
    """
    text = str(cascade)
    if Path(text).is_file():
        return Path(text)
    name = text.removesuffix(".xml").removeprefix(CASCADE_PREFIX)
    bundled = cascade_folder() / f"{CASCADE_PREFIX}{name}.xml"
    if bundled.is_file():
        return bundled
    available = ", ".join(available_cascades())
    if text.endswith(".xml") or "/" in text or "\\" in text:
        raise ValueError(f"cascade: XML file {text} does not exist; bundled cascades are {available}")
    raise ValueError(f"cascade: unknown cascade {text!r}; available: {available} "
                     "(or pass the path of a cascade XML file)")


def to_grey(image, name: str = "image") -> np.ndarray:
    """Returns a grey ``(H, W)`` uint8 view of a ``uint8`` RGB ``(H, W, 3)`` or grey ``(H, W)`` image.

    Raises:
        ValueError: wrong dtype, empty image or a channel count other than 3 (for example RGBA or
            ``(H, W, 1)``), with a hint how to convert.
    """
    array = np.asarray(image)
    if array.ndim == 2:
        return as_image(array, name, channels=None)
    if array.ndim == 3 and array.shape[-1] == 3:
        return cv2.cvtColor(as_image(array, name, channels=3), cv2.COLOR_RGB2GRAY)
    hint = ""
    if array.ndim == 3 and array.shape[-1] == 4:
        hint = "; drop the alpha channel (image[..., :3]) first"
    elif array.ndim == 3 and array.shape[-1] == 1:
        hint = "; squeeze the channel axis (image[..., 0]) first"
    raise ValueError(f"{name}: expected uint8 RGB (H, W, 3) or grey (H, W), got shape {array.shape}{hint}")


def _as_size(size, name: str) -> tuple[int, int]:
    values = np.asarray(size)
    if values.shape != (2,) or np.any(values < 0) or not np.all(np.mod(values, 1) == 0):
        raise ValueError(f"{name}: expected (width, height) non-negative integers, got {size}")
    return int(values[0]), int(values[1])


class RunCascade(Processor):
    """``grey (H, W) uint8 -> (rectangles (N, 4) xywh pixels, counts (N,))``: one OpenCV cascade pass.

    Args: see :class:`HaarCascadeDetector`. ``counts`` are OpenCV's ``numDetections``: the raw
    detections merged into each rectangle.
    """

    def __init__(self, path: Path, scale_factor: float = 1.1, min_neighbors: int = 5,
                 min_size: tuple[int, int] = (30, 30), max_size: tuple[int, int] | None = None,
                 name: str | None = None):
        super().__init__(name)
        if not (math.isfinite(scale_factor) and 1.0 < scale_factor <= MAX_SCALE_FACTOR):
            raise ValueError(f"scale_factor: expected a finite number in (1, {MAX_SCALE_FACTOR:g}], got {scale_factor}")
        if int(min_neighbors) < 0:
            raise ValueError(f"min_neighbors: expected a non-negative integer, got {min_neighbors}")
        self.min_size = _as_size(min_size, "min_size")
        self.max_size = None if max_size is None else _as_size(max_size, "max_size")
        try:
            self.classifier = cv2.CascadeClassifier(str(path))
        except (cv2.error, SystemError) as error:
            raise ValueError(f"cascade: {path} is not a valid OpenCV cascade XML file ({error})") from error
        if self.classifier.empty():
            raise ValueError(f"cascade: {path} is not a valid OpenCV cascade XML file")
        self.scale_factor = float(scale_factor)
        self.min_neighbors = int(min_neighbors)

    def call(self, grey: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rectangles, counts = self.classifier.detectMultiScale2(
            grey, scaleFactor=self.scale_factor, minNeighbors=self.min_neighbors,
            minSize=self.min_size, maxSize=self.max_size or (0, 0))
        return (np.reshape(np.asarray(rectangles, dtype=np.float64), (-1, 4)),
                np.ravel(np.asarray(counts, dtype=np.float64)))


def sort_by_score(boxes: list[Box2D]) -> list[Box2D]:
    """Boxes by decreasing score (stable)."""
    return sorted(boxes, key=lambda box: -box.score)


class HaarCascadeDetector(SequentialProcessor):
    """Detects objects with a Haar cascade: ``image -> list[Box2D]`` (pixels, ``xyxy``).

    Args:
        cascade: a name from :func:`available_cascades` or a path to a cascade XML file.
        scale_factor: image pyramid step (> 1); smaller finds more sizes but runs slower.
        min_neighbors: overlapping raw detections needed to keep a box (higher = fewer false positives).
        min_size: smallest object ``(width, height)`` in pixels.
        max_size: largest object ``(width, height)`` in pixels, or ``None`` for no limit.
        class_name: ``Box2D.class_name`` of the detections; defaults to the cascade name.

    The boxes' ``score`` is the number of raw detections merged into each box (OpenCV's
    ``numDetections``), so larger is more certain. Boxes are sorted by decreasing score.

    The steps pass a dict of named values along (each a :class:`~paz6d.abstract.KeyedStep`):
    ``to_grey`` (``image`` -> ``grey``, :func:`to_grey`), ``detect`` (``grey`` -> ``rectangles``,
    ``counts``, :class:`RunCascade`), ``to_xyxy`` (``rectangles`` -> ``corners``,
    :class:`~paz6d.processors.boxes.ConvertBoxFormat`), ``to_boxes2d`` (``corners``, ``counts`` ->
    ``boxes``, :class:`~paz6d.processors.boxes.ToBoxes2D`) and ``sort`` (``boxes`` -> ``boxes``,
    :func:`sort_by_score`).
    """

    def __init__(self, cascade: str | Path = "frontalface_default", scale_factor: float = 1.1,
                 min_neighbors: int = 5, min_size: tuple[int, int] = (30, 30),
                 max_size: tuple[int, int] | None = None, class_name: str | None = None):
        path = cascade_path(cascade)
        super().__init__(name=f"HaarCascadeDetector({path.stem})")
        self.path = path
        self.class_name = class_name or path.stem.removeprefix(CASCADE_PREFIX)
        self.add(KeyedStep(to_grey, "image", "grey", "to_grey"))
        self.add(KeyedStep(RunCascade(path, scale_factor, min_neighbors, min_size, max_size), "grey",
                           ("rectangles", "counts"), "detect"))
        self.add(KeyedStep(ConvertBoxFormat("xywh", "xyxy"), "rectangles", "corners", "to_xyxy"))
        self.add(KeyedStep(ToBoxes2D(class_name=self.class_name), ("corners", "counts"), "boxes", "to_boxes2d"))
        self.add(KeyedStep(sort_by_score, "boxes", "boxes", "sort"))

    def call(self, image) -> list[Box2D]:
        """Runs the cascade on a ``uint8`` RGB ``(H, W, 3)`` or grey ``(H, W)`` image."""
        return self.run_steps({"image": image})["boxes"]
