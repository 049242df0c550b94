"""Deterministic image processors over :mod:`paz6d.backend.image`: loading, resizing, colour
spaces, normalization, cropping and padding. Images are ``uint8`` RGB ``(H, W, 3)``. Random
augmentations live in :mod:`paz6d.synthesis.augment`.

Example:
    >>> import numpy as np
    >>> from paz6d.abstract import SequentialProcessor
    >>> from paz6d.processors.image import NormalizeImage, ResizeImage
    >>> prepare = SequentialProcessor([ResizeImage((4, 2)), NormalizeImage()])
    >>> prepare(np.full((8, 8, 3), 255, np.uint8)).shape
    (2, 4, 3)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from paz6d.abstract.processor import Processor
from paz6d.backend import image as image_backend


class LoadImage(Processor):
    """Path to ``uint8`` RGB image (``(H, W)`` with ``grayscale``)."""

    def __init__(self, grayscale: bool = False, name: str | None = None):
        super().__init__(name)
        self.grayscale = grayscale

    def call(self, path: str | Path) -> np.ndarray:
        return image_backend.load_image(path, self.grayscale)


class ResizeImage(Processor):
    """Resizes to ``size = (width, height)`` pixels."""

    def __init__(self, size: tuple[int, int], interpolation: str = "linear", name: str | None = None):
        super().__init__(name)
        self.size = tuple(size)
        self.interpolation = interpolation

    def call(self, image: np.ndarray) -> np.ndarray:
        return image_backend.resize(image, self.size, self.interpolation)


class ConvertColorSpace(Processor):
    """Converts between ``RGB``, ``BGR``, ``HSV``, ``LAB`` and ``GRAY`` (OpenCV conventions)."""

    def __init__(self, source: str = "RGB", target: str = "HSV", name: str | None = None):
        super().__init__(name)
        self.source, self.target = source, target

    def call(self, image: np.ndarray) -> np.ndarray:
        return image_backend.convert_color_space(image, self.source, self.target)


class NormalizeImage(Processor):
    """``uint8`` to ``float32`` ``(image / 255 - mean) / std``."""

    def __init__(self, mean=None, std=None, name: str | None = None):
        super().__init__(name)
        self.mean, self.std = mean, std

    def call(self, image: np.ndarray) -> np.ndarray:
        return image_backend.normalize(image, self.mean, self.std)


class DenormalizeImage(Processor):
    """Inverse of :class:`NormalizeImage`, back to ``uint8``."""

    def __init__(self, mean=None, std=None, name: str | None = None):
        super().__init__(name)
        self.mean, self.std = mean, std

    def call(self, values: np.ndarray) -> np.ndarray:
        return image_backend.denormalize(values, self.mean, self.std)


class CropImage(Processor):
    """Crops the pixels covered by an ``xyxy`` box; called as ``(image, box)``."""

    def call(self, image: np.ndarray, box) -> np.ndarray:
        return image_backend.crop(image, box)


class PadToSquare(Processor):
    """Pads the shorter side to a square with ``value`` (returns the image only)."""

    def __init__(self, value: int = 0, name: str | None = None):
        super().__init__(name)
        self.value = value

    def call(self, image: np.ndarray) -> np.ndarray:
        return image_backend.pad_to_square(image, self.value)[0]
