"""Image processors over :mod:`paz6d.backend.image`: loading, geometry and the PAZ photometric
augmentations. Images are ``uint8`` RGB ``(H, W, 3)``.

Random processors take ``seed`` (int, ``SeedSequence`` or ``Generator``); inside a
:class:`~paz6d.abstract.sequence.BatchDispatcher` they are reseeded per sample.

Example:
    >>> import numpy as np
    >>> from paz6d.abstract import SequentialProcessor
    >>> from paz6d.processors.image import RandomBrightness, RandomContrast
    >>> augment = SequentialProcessor([RandomBrightness(seed=0), RandomContrast(seed=1)])
    >>> augment(np.full((8, 8, 3), 128, np.uint8)).shape
    (8, 8, 3)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from paz6d.abstract.processor import Processor, RandomProcessor
from paz6d.backend import boxes as boxes_backend
from paz6d.backend import image as image_backend


def _as_box_rows(boxes) -> np.ndarray:
    """``(N, 4 + k)`` float copy: ``xyxy`` pixels first, then any extra columns (class id, ...)."""
    rows = np.array(boxes, dtype=np.float64)
    if rows.ndim != 2 or rows.shape[1] < 4:
        raise ValueError(f"boxes: expected shape (N, 4 + k) with xyxy first, got {rows.shape}")
    return rows


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


class RandomBrightness(RandomProcessor):
    """Adds a uniform offset in ``[-max_delta, max_delta]`` intensity levels."""

    def __init__(self, max_delta: float = 32.0, seed=None, name: str | None = None):
        super().__init__(seed, name)
        self.max_delta = max_delta

    def call(self, image: np.ndarray) -> np.ndarray:
        return image_backend.random_brightness(image, self.generator, self.max_delta)


class RandomContrast(RandomProcessor):
    """Scales deviations from the channel mean by a uniform factor in ``[lower, upper]``."""

    def __init__(self, lower: float = 0.5, upper: float = 1.5, seed=None, name: str | None = None):
        super().__init__(seed, name)
        self.lower, self.upper = lower, upper

    def call(self, image: np.ndarray) -> np.ndarray:
        return image_backend.random_contrast(image, self.generator, self.lower, self.upper)


class RandomSaturation(RandomProcessor):
    """Scales HSV saturation by a uniform factor in ``[lower, upper]``."""

    def __init__(self, lower: float = 0.5, upper: float = 1.5, seed=None, name: str | None = None):
        super().__init__(seed, name)
        self.lower, self.upper = lower, upper

    def call(self, image: np.ndarray) -> np.ndarray:
        return image_backend.random_saturation(image, self.generator, self.lower, self.upper)


class RandomHue(RandomProcessor):
    """Rotates hue by a uniform angle in ``[-max_delta_degrees, max_delta_degrees]``."""

    def __init__(self, max_delta_degrees: float = 18.0, seed=None, name: str | None = None):
        super().__init__(seed, name)
        self.max_delta_degrees = max_delta_degrees

    def call(self, image: np.ndarray) -> np.ndarray:
        return image_backend.random_hue(image, self.generator, self.max_delta_degrees)


class RandomGaussianBlur(RandomProcessor):
    """Gaussian blur with a kernel size drawn from ``kernel_sizes``, applied with ``probability``."""

    def __init__(self, kernel_sizes: tuple[int, ...] = (3, 5, 7), probability: float = 0.5, seed=None,
                 name: str | None = None):
        super().__init__(seed, name)
        self.kernel_sizes, self.probability = tuple(kernel_sizes), probability

    def call(self, image: np.ndarray) -> np.ndarray:
        if self.generator.random() >= self.probability:
            return image
        return image_backend.random_gaussian_blur(image, self.generator, self.kernel_sizes)


class RandomImageNoise(RandomProcessor):
    """Adds Gaussian noise with a standard deviation uniform in ``[0, max_std]`` levels."""

    def __init__(self, max_std: float = 10.0, seed=None, name: str | None = None):
        super().__init__(seed, name)
        self.max_std = max_std

    def call(self, image: np.ndarray) -> np.ndarray:
        return image_backend.random_image_noise(image, self.generator, self.max_std)


class RandomFlipLeftRight(RandomProcessor):
    """Mirrors the image (and ``xyxy`` boxes ``(N, 4 + k)`` if given) with ``probability``."""

    def __init__(self, probability: float = 0.5, seed=None, name: str | None = None):
        super().__init__(seed, name)
        self.probability = probability

    def call(self, image: np.ndarray, boxes=None):
        flip = self.generator.random() < self.probability
        if flip:
            image = image_backend.flip_left_right(image)
        if boxes is None:
            return image
        boxes = _as_box_rows(boxes)
        if flip:
            boxes[:, :4] = boxes_backend.flip_left_right(boxes[:, :4], image.shape[1])
        return image, boxes


class RandomCrop(RandomProcessor):
    """Crops a random window (area fraction in ``scale``, aspect ratio in ``aspect_ratio``).

    Called as ``(image)`` it returns the crop; called as ``(image, boxes)`` with ``boxes``
    ``(N, 4 + k)`` (``xyxy`` pixels first, extra columns such as class ids kept) it returns
    ``(crop, boxes_in_crop)``: boxes whose centre falls inside the window, shifted and clipped
    to it (the SSD rule).
    """

    def __init__(self, scale: tuple[float, float] = (0.3, 1.0), aspect_ratio: tuple[float, float] = (0.5, 2.0),
                 seed=None, name: str | None = None):
        super().__init__(seed, name)
        self.scale, self.aspect_ratio = tuple(scale), tuple(aspect_ratio)

    def call(self, image: np.ndarray, boxes=None):
        height, width = np.asarray(image).shape[:2]
        window = image_backend.random_crop_box((width, height), self.generator, self.scale, self.aspect_ratio)
        cropped = image_backend.crop(image, window)
        if boxes is None:
            return cropped
        boxes = _as_box_rows(boxes)
        centers = 0.5 * (boxes[:, :2] + boxes[:, 2:4])
        inside = np.all((centers >= window[:2]) & (centers < window[2:]), axis=1)
        kept = boxes[inside]
        kept[:, :4] = boxes_backend.clip(kept[:, :4] - np.tile(window[:2], 2), (cropped.shape[1], cropped.shape[0]))
        return cropped, kept


class BlendBackground(RandomProcessor):
    """Composites a foreground over a random crop of one of ``backgrounds`` (resized to fit).

    Called as ``(foreground, alpha)`` with ``alpha`` ``(H, W)`` opacity (float in [0, 1],
    ``bool`` or ``uint8`` mask).
    """

    def __init__(self, backgrounds: list[np.ndarray], scale: tuple[float, float] = (0.3, 1.0), seed=None,
                 name: str | None = None):
        super().__init__(seed, name)
        if len(backgrounds) == 0:
            raise ValueError("backgrounds: expected at least one uint8 RGB background image")
        self.backgrounds = [image_backend.as_image(background, "backgrounds[i]") for background in backgrounds]
        self.scale = tuple(scale)

    def call(self, foreground: np.ndarray, alpha: np.ndarray) -> np.ndarray:
        background = self.backgrounds[int(self.generator.integers(len(self.backgrounds)))]
        height, width = np.asarray(foreground).shape[:2]
        window = image_backend.random_crop_box((background.shape[1], background.shape[0]), self.generator,
                                               self.scale, (width / height, width / height))
        patch = image_backend.resize(image_backend.crop(background, window), (width, height))
        return image_backend.alpha_blend(foreground, alpha, patch)
