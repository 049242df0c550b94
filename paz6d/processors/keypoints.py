"""Keypoint processors over :mod:`paz6d.backend.keypoints` (pixel keypoints ``(N, 2)``)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from paz6d.abstract.messages import Keypoints2D
from paz6d.abstract.processor import Processor
from paz6d.backend import keypoints as keypoints_backend


class NormalizeKeypoints(Processor):
    """Pixels to ``value_range`` (``(-1, 1)`` or ``(0, 1)``) for ``image_size = (width, height)``."""

    def __init__(self, image_size: tuple[int, int], value_range: tuple[float, float] = (-1.0, 1.0),
                 name: str | None = None):
        super().__init__(name)
        self.image_size, self.value_range = tuple(image_size), tuple(value_range)

    def call(self, keypoints) -> np.ndarray:
        return keypoints_backend.normalize(keypoints, self.image_size, self.value_range)


class DenormalizeKeypoints(Processor):
    """Normalized coordinates back to pixels (inverse of :class:`NormalizeKeypoints`)."""

    def __init__(self, image_size: tuple[int, int], value_range: tuple[float, float] = (-1.0, 1.0),
                 name: str | None = None):
        super().__init__(name)
        self.image_size, self.value_range = tuple(image_size), tuple(value_range)

    def call(self, keypoints) -> np.ndarray:
        return keypoints_backend.denormalize(keypoints, self.image_size, self.value_range)


class FlipKeypointsLeftRight(Processor):
    """Mirrors keypoints for an image of width ``image_width``, then reorders with ``permutation``."""

    def __init__(self, image_width: int, permutation: Sequence[int] | None = None, name: str | None = None):
        super().__init__(name)
        self.image_width = image_width
        self.permutation = None if permutation is None else list(permutation)

    def call(self, keypoints) -> np.ndarray:
        return keypoints_backend.flip_left_right(keypoints, self.image_width, self.permutation)


class ToKeypoints2D(Processor):
    """``(N, 2)`` pixel array (+ optional ``(N,)`` scores) to a :class:`Keypoints2D` message."""

    def __init__(self, class_name: str | None = None, name: str | None = None):
        super().__init__(name)
        self.class_name = class_name

    def call(self, keypoints, scores=None) -> Keypoints2D:
        return Keypoints2D(keypoints, scores, self.class_name)
