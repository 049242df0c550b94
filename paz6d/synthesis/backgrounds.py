"""Backgrounds behind rendered objects: procedural clutter in four styles (one mixes in photo
collages), random crops of background files, a bank of procedural backgrounds reused through random
crops, and the out-of-distribution backgrounds of the demo's OOD check (:data:`OOD_BACKGROUND_STYLES`),
which no training pipeline uses."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from paz6d.backend.image import load_image

#: ``"noise"``: multi-octave value noise between two colours, half of the time with stripes
#: (``paz6d generate``); ``"clutter"``: a smooth colour field or soft stripes, up to 7 rectangles,
#: ellipses and lines, blurred noise texture (AAE inputs); ``"shapes"``: coarse colour noise,
#: 3-11 rectangles and ellipses, pixel noise (KeypointNet batches).
BACKGROUND_STYLES = ("noise", "clutter", "shapes")

#: Backgrounds of the out-of-distribution check (``paz6d demo``), used by no training pipeline:
#: ``"flat"``: one uniform random colour; ``"pixel-noise"``: every pixel and channel uniform in 0-255
#: (standard deviation ~74 levels); ``"smooth-field"``: independent per-channel white noise low-passed by
#: a Gaussian of sigma 4-16 px, each channel stretched to a random range at least 128 levels wide.
OOD_BACKGROUND_STYLES = ("flat", "pixel-noise", "smooth-field")
#: Largest pixel-noise standard deviation (levels) in any :data:`BACKGROUND_STYLES` entry.
MAX_TRAINING_PIXEL_NOISE = 12.0


def procedural_background(generator: np.random.Generator, width: int, height: int, style: str = "noise") -> np.ndarray:
    """``(height, width, 3)`` uint8 procedural background of one of :data:`BACKGROUND_STYLES`."""
    if style == "noise":
        return _value_noise(generator, width, height)
    if style == "clutter":
        return _clutter(generator, width, height)
    if style == "shapes":
        return _shapes(generator, width, height)
    raise ValueError(f"style: expected one of {BACKGROUND_STYLES}, got {style!r}")


def ood_background(generator: np.random.Generator, width: int, height: int, style: str) -> np.ndarray:
    """``(height, width, 3)`` uint8 background of one of :data:`OOD_BACKGROUND_STYLES`."""
    if style == "flat":
        return np.broadcast_to(generator.integers(0, 256, 3).astype(np.uint8), (height, width, 3)).copy()
    if style == "pixel-noise":
        return generator.integers(0, 256, (height, width, 3), dtype=np.uint8)
    if style == "smooth-field":
        sigma = float(np.exp(generator.uniform(np.log(4.0), np.log(16.0))))
        field = cv2.GaussianBlur(generator.standard_normal((height, width, 3)).astype(np.float32), (0, 0), sigma)
        field -= field.min(axis=(0, 1))
        field /= np.maximum(field.max(axis=(0, 1)), 1e-6)
        width_levels = generator.uniform(128, 255, 3)
        low = generator.uniform(0, 255 - width_levels)
        return np.clip(low + field * width_levels, 0, 255).astype(np.uint8)
    raise ValueError(f"style: expected one of {OOD_BACKGROUND_STYLES}, got {style!r}")


def _value_noise(generator: np.random.Generator, width: int, height: int) -> np.ndarray:
    """Multi-octave value noise mixed between two random colours, sometimes with stripes. The octaves
    are summed on a 33×33 grid, the sum is enlarged to half resolution (cubic), coloured through a
    lookup table, striped, then enlarged to ``W×H``: the pattern is smooth anyway."""
    low_width, low_height = max(1, (width + 1) // 2), max(1, (height + 1) // 2)
    octaves = (2, 4, 8, 32)
    side = octaves[-1] + 1
    field = np.zeros((side, side), dtype=np.float32)
    for octave, cells in enumerate(octaves):
        grid = generator.random((cells + 1, cells + 1), dtype=np.float32)
        field += cv2.resize(grid, (side, side), interpolation=cv2.INTER_CUBIC) / (octave + 1)
    field = cv2.resize(field, (low_width, low_height), interpolation=cv2.INTER_CUBIC)
    levels = cv2.normalize(field, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    low, high = generator.uniform(0, 255, 3), generator.uniform(0, 255, 3)
    palette = np.rint(low + np.linspace(0.0, 1.0, 256)[:, None] * (high - low)).astype(np.uint8)
    image = cv2.LUT(cv2.merge([levels] * 3), palette[:, None, :])
    if generator.random() < 0.5:  # stripes add edges, as real clutter does
        period = np.float32(generator.uniform(4, 32))
        angle = generator.uniform(0, np.pi)
        columns = np.arange(low_width, dtype=np.float32) * np.float32(np.cos(angle))
        rows = np.arange(low_height, dtype=np.float32) * np.float32(np.sin(angle))
        stripes = np.sin((columns[None, :] + rows[:, None]) * np.float32(2 * np.pi) / period) > 0
        image = np.where(stripes[..., None], image, 255 - image)
    return cv2.resize(image, (width, height), interpolation=cv2.INTER_LINEAR)


def _soft_stripes(generator: np.random.Generator, width: int, height: int) -> np.ndarray:
    """Two-colour sinusoidal stripes of random period (3-40 px) and orientation, ``(H, W, 3)`` float32."""
    angle = generator.uniform(0, np.pi)
    period = np.exp(generator.uniform(np.log(3), np.log(40)))
    columns, rows = np.arange(width, dtype=np.float32), np.arange(height, dtype=np.float32)
    phase = (np.cos(angle) * columns[None, :] + np.sin(angle) * rows[:, None]) * (2 * np.pi / period)
    weight = (0.5 + 0.5 * np.sin(phase))[..., None]
    first, second = generator.uniform(0, 255, (2, 3)).astype(np.float32)
    return weight * first + (1 - weight) * second


def _clutter(generator: np.random.Generator, width: int, height: int) -> np.ndarray:
    """A smooth colour field or stripes, random shapes, noise texture."""
    extent_scale = np.array([width, height], dtype=np.float64)
    if generator.random() < 0.35:
        background = _soft_stripes(generator, width, height)
    else:
        cells = int(generator.integers(2, 9))
        field = generator.uniform(0, 255, (cells, cells, 3)).astype(np.float32)
        background = cv2.resize(field, (width, height), interpolation=cv2.INTER_CUBIC)
    for _ in range(int(generator.integers(0, 8))):
        color = generator.uniform(0, 255, 3).tolist()
        kind = generator.integers(3)
        if kind == 0:
            corner = generator.uniform(-0.2, 1.0, 2) * extent_scale
            extent = generator.uniform(0.05, 0.5, 2) * extent_scale
            cv2.rectangle(background, tuple(int(v) for v in corner), tuple(int(v) for v in corner + extent), color, -1)
        elif kind == 1:
            centre = tuple(int(v) for v in generator.uniform(0, extent_scale, 2))
            axes = tuple(int(v) for v in generator.uniform(0.03, 0.3, 2) * extent_scale)
            cv2.ellipse(background, centre, axes, float(generator.uniform(0, 180)), 0, 360, color, -1)
        else:
            points = generator.uniform(0, extent_scale, (2, 2)).astype(int)
            cv2.line(background, tuple(points[0].tolist()), tuple(points[1].tolist()), color,
                     int(generator.integers(1, max(2, max(width, height) // 16))))
    noise = generator.normal(0, 1, (height, width)).astype(np.float32)
    texture = cv2.GaussianBlur(noise, (0, 0), float(generator.uniform(0.3, 2)))
    background += (generator.uniform(0, 40) * texture)[..., None]
    return np.clip(background, 0, 255).astype(np.uint8)


def _shapes(generator: np.random.Generator, width: int, height: int) -> np.ndarray:
    """Smooth colour noise plus random rectangles and ellipses and pixel noise."""
    cells = int(generator.integers(2, 9))
    coarse = generator.integers(0, 256, (cells, cells, 3)).astype(np.uint8)
    background = cv2.resize(coarse, (width, height), interpolation=cv2.INTER_CUBIC)
    scale = max(height, width)
    for _ in range(int(generator.integers(3, 12))):
        colour = tuple(int(value) for value in generator.integers(0, 256, 3))
        centre = (int(generator.integers(0, width)), int(generator.integers(0, height)))
        extent = (int(generator.integers(2, scale // 4 + 3)), int(generator.integers(2, scale // 4 + 3)))
        if generator.random() < 0.5:
            cv2.ellipse(background, centre, extent, float(generator.uniform(0, 180)), 0, 360, colour, -1)
        else:
            cv2.rectangle(background, (centre[0] - extent[0], centre[1] - extent[1]),
                          (centre[0] + extent[0], centre[1] + extent[1]), colour, -1)
    noise = generator.normal(0.0, generator.uniform(0, MAX_TRAINING_PIXEL_NOISE), background.shape)
    return np.clip(background + noise, 0, 255).astype(np.uint8)


def crop_background(generator: np.random.Generator, image: np.ndarray, width: int, height: int,
                    scale: tuple[float, float] = (0.5, 1.0), max_downscale: float = np.inf,
                    interpolation: int = cv2.INTER_LINEAR) -> np.ndarray:
    """``(height, width, 3)`` uint8: a random crop of ``image`` (uint8 RGB) with the output's aspect
    ratio, mirrored half of the time, resized with ``interpolation``.

    The crop is ``scale`` (a uniform draw from the range) times the largest such window, and at most
    ``max_downscale`` times the output size (so small outputs do not shrink a whole photograph).
    """
    source_height, source_width = image.shape[:2]
    factor = generator.uniform(*scale) * min(source_width / width, source_height / height, max_downscale)
    crop_width, crop_height = max(1, int(round(width * factor))), max(1, int(round(height * factor)))
    x = int(generator.integers(0, source_width - crop_width + 1))
    y = int(generator.integers(0, source_height - crop_height + 1))
    crop = image[y:y + crop_height, x:x + crop_width]
    if generator.random() < 0.5:
        crop = crop[:, ::-1]
    return cv2.resize(np.ascontiguousarray(crop), (width, height), interpolation=interpolation)


def background_image(generator: np.random.Generator, files: list[Path], width: int, height: int,
                     style: str = "noise") -> np.ndarray:
    """``(height, width, 3)`` uint8: :func:`crop_background` of a random file among ``files`` (read
    when drawn, so a large folder costs no memory), or a procedural background of ``style`` when there
    are no files."""
    if not files:
        return procedural_background(generator, width, height, style)
    return crop_background(generator, load_image(files[int(generator.integers(len(files)))]), width, height)


class BackgroundBank:
    """Square procedural backgrounds made once (``count`` of side ``2 * size``) and reused through
    random ``size × size`` crops, mirrored and transposed half of the time each: cheap per sample.

    Args:
        size: side of the patches in pixels.
        count: backgrounds in the bank (0: every patch is black).
        generator: draws the bank.
        style: :data:`BACKGROUND_STYLES` entry of the bank's backgrounds.
    """

    def __init__(self, size: int, count: int, generator: np.random.Generator, style: str = "clutter"):
        if int(size) < 1 or int(count) < 0:
            raise ValueError(f"size/count: expected a positive size and count >= 0, got {size}, {count}")
        self.size = int(size)
        self.backgrounds = [procedural_background(generator, 2 * self.size, 2 * self.size, style)
                            for _ in range(int(count))]

    def patch(self, generator: np.random.Generator) -> np.ndarray:
        """A ``(size, size, 3)`` uint8 patch (a view into the bank: copy before writing to it)."""
        size = self.size
        if not self.backgrounds:
            return np.zeros((size, size, 3), np.uint8)
        bank = self.backgrounds[int(generator.integers(len(self.backgrounds)))]
        x, y = generator.integers(0, bank.shape[0] - size + 1, 2)
        patch = bank[y:y + size, x:x + size]
        if generator.random() < 0.5:
            patch = patch[:, ::-1]
        if generator.random() < 0.5:
            patch = patch.transpose(1, 0, 2)
        return patch
