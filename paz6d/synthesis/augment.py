"""Augmentation as random processors: photometric (brightness, contrast, saturation, hue, blur,
noise), mirroring, random similarity warps and compositing over background images. Images are ``uint8`` RGB
``(H, W, 3)``; augmentations of images with boxes (SSD) are in :mod:`paz6d.synthesis.box_augment`.

Every class is a :class:`~paz6d.abstract.processor.RandomProcessor` (its own ``generator``;
:func:`~paz6d.abstract.processor.reseed` reseeds it per sample), so augmentations compose
with :class:`~paz6d.abstract.processor.SequentialProcessor`. :func:`share_generator` makes a whole
sequence draw from one caller's generator, in step order (how the trainers make a sample a pure
function of its seed).

Example:
    >>> import numpy as np
    >>> from paz6d.abstract import SequentialProcessor
    >>> from paz6d.synthesis.augment import RandomBrightness, RandomContrast
    >>> augment = SequentialProcessor([RandomBrightness(seed=0), RandomContrast(seed=1)])
    >>> augment(np.full((8, 8, 3), 128, np.uint8)).shape
    (8, 8, 3)
"""

from __future__ import annotations

from statistics import NormalDist
from typing import Callable

import cv2
import numpy as np

from paz6d.abstract.processor import RandomProcessor, random_processors
from paz6d.backend import image as image_backend
from paz6d.synthesis.backgrounds import BACKGROUND_STYLES, crop_background, procedural_background


def share_generator(processor: Callable, generator: np.random.Generator) -> None:
    """Makes every random processor inside ``processor`` draw from ``generator`` (one stream, in step
    order), e.g. the generator of the sample being made."""
    for target in random_processors(processor):
        target.generator = generator


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
    """With ``probability``, a Gaussian blur with a kernel size drawn from ``kernel_sizes`` and a
    standard deviation uniform in ``sigma`` pixels (``None``: derived from the kernel size).

    Args:
        kernel_sizes: odd kernel sides; 0 (only with ``sigma``) derives the side from the drawn sigma.
            A single size draws nothing.
    """

    def __init__(self, kernel_sizes: tuple[int, ...] = (3, 5, 7), probability: float = 0.5,
                 sigma: tuple[float, float] | None = None, seed=None, name: str | None = None):
        super().__init__(seed, name)
        kernel_sizes = tuple(int(size) for size in kernel_sizes)
        smallest = 0 if sigma is not None else 1
        if not kernel_sizes or any(size < smallest or (size and size % 2 == 0) for size in kernel_sizes):
            raise ValueError(f"kernel_sizes: expected odd positive sizes (or 0 with sigma), got {kernel_sizes}")
        self.kernel_sizes, self.probability = kernel_sizes, probability
        self.sigma = None if sigma is None else tuple(sigma)

    def call(self, image: np.ndarray) -> np.ndarray:
        if self.generator.random() >= self.probability:
            return image
        size = int(self.generator.choice(self.kernel_sizes))
        sigma = 0.0 if self.sigma is None else float(self.generator.uniform(*self.sigma))
        return cv2.GaussianBlur(image, (size, size), sigma)


#: The 256 quantiles ``(i + 0.5) / 256`` of the standard normal: a uniform byte indexes one, which
#: draws 8-bit-quantized Gaussian noise (cut at ±2.9 sigma) faster than ``standard_normal``.
NORMAL_QUANTILES = np.array([NormalDist().inv_cdf((i + 0.5) / 256) for i in range(256)], dtype=np.float32)


def sensor_noise(generator: np.random.Generator, image: np.ndarray, std: float) -> np.ndarray:
    """``image`` (uint8, any shape) plus zero-mean Gaussian noise of ``std`` grey levels drawn through
    :data:`NORMAL_QUANTILES`, rounded and clipped."""
    indices = generator.integers(0, 256, size=image.shape, dtype=np.uint8)
    noise = cv2.LUT(indices, NORMAL_QUANTILES * np.float32(std))
    return cv2.add(image.astype(np.float32), noise, dtype=cv2.CV_8U)  # saturating: rounds and clips


def relight(rgb: np.ndarray, generator: np.random.Generator, strength: float, ramp_scale: float = 1.0) -> np.ndarray:
    """Image-space re-lighting: ``rgb (H, W, 3)`` as float32 times random per-channel gains
    ``1 ± strength/2`` and a linear brightness ramp across the image in a random direction, whose slope is
    up to ``strength × ramp_scale`` per image side (factors clipped to [0.2, 2]). ``strength`` 0 returns
    the float32 copy without drawing."""
    values = rgb.astype(np.float32)
    if strength <= 0:
        return values
    gains = (1.0 + generator.uniform(-strength / 2, strength / 2, 3)).astype(np.float32)
    direction = generator.normal(size=2)
    direction /= np.linalg.norm(direction) + 1e-12
    height, width = values.shape[:2]
    u = (np.arange(width, dtype=np.float32) + 0.5) / width - 0.5
    v = (np.arange(height, dtype=np.float32) + 0.5) / height - 0.5
    ramp = direction[0] * u[None, :] + direction[1] * v[:, None]
    gradient = np.clip(1.0 + generator.uniform(0, strength) * ramp_scale * ramp, 0.2, 2.0)
    values *= gradient[..., None] * gains  # in place: stays float32
    return values


class RandomImageNoise(RandomProcessor):
    """With ``probability``, zero-mean Gaussian noise of a standard deviation uniform in ``[0, max_std]``
    grey levels, rounded and clipped. Nothing is drawn when ``max_std`` is 0, and no coin is tossed
    when ``probability`` is 1.

    Args:
        quantized: draw 8-bit-quantized noise through :data:`NORMAL_QUANTILES` (:func:`sensor_noise`,
            faster; ``paz6d generate``) instead of ``Generator.normal``.
    """

    def __init__(self, max_std: float = 10.0, probability: float = 1.0, quantized: bool = False, seed=None,
                 name: str | None = None):
        super().__init__(seed, name)
        self.max_std, self.probability, self.quantized = max_std, probability, quantized

    def call(self, image: np.ndarray) -> np.ndarray:
        if self.max_std <= 0 or (self.probability < 1.0 and self.generator.random() >= self.probability):
            return image
        std = float(self.generator.uniform(0.0, self.max_std))
        if self.quantized:
            return sensor_noise(self.generator, image, std)
        return image_backend.add_gaussian_noise(image, std, self.generator)


class RandomFlipLeftRight(RandomProcessor):
    """Mirrors the image left-right with ``probability`` (images with boxes:
    :class:`~paz6d.synthesis.box_augment.RandomFlip`)."""

    def __init__(self, probability: float = 0.5, seed=None, name: str | None = None):
        super().__init__(seed, name)
        self.probability = probability

    def call(self, image: np.ndarray) -> np.ndarray:
        return image_backend.flip_left_right(image) if self.generator.random() < self.probability else image


class BlendBackground(RandomProcessor):
    """Composites a foreground over a random background: a random crop
    (:func:`~paz6d.synthesis.backgrounds.crop_background`) of one of ``backgrounds`` or, without
    images, a procedural background of ``style``
    (:data:`~paz6d.synthesis.backgrounds.BACKGROUND_STYLES`).

    Called as ``(foreground, alpha)`` with ``alpha`` ``(H, W)`` opacity (float in [0, 1],
    ``bool`` or ``uint8`` mask).
    """

    def __init__(self, backgrounds: list[np.ndarray] | None = None, style: str = "shapes", seed=None,
                 name: str | None = None):
        super().__init__(seed, name)
        if backgrounds is not None and len(backgrounds) == 0:
            raise ValueError("backgrounds: expected at least one uint8 RGB background image (or None: procedural)")
        if style not in BACKGROUND_STYLES:
            raise ValueError(f"style: expected one of {BACKGROUND_STYLES}, got {style!r}")
        self.backgrounds = None if backgrounds is None else [
            image_backend.as_image(background, "backgrounds[i]") for background in backgrounds]
        self.style = style

    def call(self, foreground: np.ndarray, alpha: np.ndarray) -> np.ndarray:
        height, width = np.asarray(foreground).shape[:2]
        if self.backgrounds is None:
            background = procedural_background(self.generator, width, height, self.style)
        else:
            image = self.backgrounds[int(self.generator.integers(len(self.backgrounds)))]
            background = crop_background(self.generator, image, width, height)
        return image_backend.alpha_blend(foreground, alpha, background)


class RandomContrastBrightnessNoise(RandomProcessor):
    """Contrast factor uniform in ``contrast`` (about each channel's mean), brightness offset uniform in
    ``±brightness`` and Gaussian noise of a standard deviation uniform in ``[0, noise]`` levels, all in
    float32 and rounded down to uint8 once (the AAE input jitter; no noise is drawn when ``noise`` is 0)."""

    def __init__(self, contrast: tuple[float, float] = (0.6, 1.4), brightness: float = 30.0, noise: float = 8.0,
                 seed=None, name: str | None = None):
        super().__init__(seed, name)
        self.contrast, self.brightness, self.noise = tuple(contrast), brightness, noise

    def call(self, image: np.ndarray) -> np.ndarray:
        generator = self.generator
        values = image.astype(np.float32)
        mean = values.mean(axis=(0, 1), keepdims=True)
        values = (values - mean) * np.float32(generator.uniform(*self.contrast)) + mean
        values += np.float32(generator.uniform(-self.brightness, self.brightness))
        if self.noise > 0:
            values += generator.standard_normal(values.shape, dtype=np.float32) * np.float32(
                generator.uniform(0, self.noise))
        return np.clip(values, 0, 255).astype(np.uint8)


def similarity_matrix(center: tuple[float, float], angle_degrees: float, scale: float,
                      shift: tuple[float, float]) -> np.ndarray:
    """``(2, 3)`` matrix rotating by ``angle_degrees`` (counter-clockwise on screen) and scaling
    about ``center`` (pixels), then shifting by ``shift = (dx, dy)`` pixels."""
    matrix = cv2.getRotationMatrix2D((float(center[0]), float(center[1])), float(angle_degrees), float(scale))
    matrix[:, 2] += np.asarray(shift, dtype=np.float64)
    return matrix


class RandomAffine(RandomProcessor):
    """Warps an ``(H, W)`` or ``(H, W, C)`` image by a random similarity transform.

    Args:
        max_rotation_degrees: rotation drawn uniformly from ``[-max, max]``.
        max_zoom: scale drawn uniformly from ``[1 - max_zoom, 1 + max_zoom]``.
        max_shift: shift drawn uniformly from ``[-max_shift, max_shift]`` times the width/height.
        seed: int, ``SeedSequence`` or ``Generator``.
    """

    def __init__(self, max_rotation_degrees: float = 10.0, max_zoom: float = 0.1, max_shift: float = 0.1,
                 seed=None, name: str | None = None):
        super().__init__(seed, name)
        for argument, value, upper in (("max_rotation_degrees", max_rotation_degrees, 180.0),
                                       ("max_zoom", max_zoom, 0.99), ("max_shift", max_shift, 1.0)):
            if not 0.0 <= value <= upper:
                raise ValueError(f"{argument}: expected a value in [0, {upper}], got {value}")
        self.max_rotation_degrees = float(max_rotation_degrees)
        self.max_zoom = float(max_zoom)
        self.max_shift = float(max_shift)

    def call(self, image: np.ndarray) -> np.ndarray:
        image = np.asarray(image)
        if image.ndim not in (2, 3) or 0 in image.shape:
            raise ValueError(f"image: expected a non-empty (H, W) or (H, W, C) array, got shape {image.shape}")
        height, width = image.shape[:2]
        angle = self.generator.uniform(-self.max_rotation_degrees, self.max_rotation_degrees)
        scale = self.generator.uniform(1.0 - self.max_zoom, 1.0 + self.max_zoom)
        shift = self.generator.uniform(-self.max_shift, self.max_shift, size=2) * (width, height)
        matrix = similarity_matrix(((width - 1) / 2.0, (height - 1) / 2.0), angle, scale, shift)
        return cv2.warpAffine(image, matrix, (width, height), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_REPLICATE)
