"""Domain randomization drawn from one ``numpy.random.Generator`` per image: lights, object
colours, backgrounds and image degradations."""

from __future__ import annotations

from pathlib import Path
from statistics import NormalDist

import cv2
import numpy as np

from data_gen.config import GenerationConfig
from paz6d.backend.image import gaussian_blur, load_image, nonzero_window
from renderers import Light, Lighting


def random_lighting(generator: np.random.Generator, config: GenerationConfig, distance: float) -> Lighting:
    """Ambient light plus ``light_count`` directional/point lights on the camera's side of the scene.

    Args:
        distance: typical object distance (metres), to place point lights and scale their power.
    """
    ambient = tuple(float(a) for a in generator.uniform(0.1, 0.45) * generator.uniform(0.85, 1.0, 3))
    lights = []
    for _ in range(int(generator.integers(config.light_count[0], config.light_count[1] + 1))):
        color = tuple(float(c) for c in generator.uniform(0.75, 1.0, 3))
        # A direction in the camera's front hemisphere (the light travels into the scene).
        direction = generator.normal(size=3)
        direction[2] = abs(direction[2]) + 0.3
        if generator.random() < 0.5:
            lights.append(Light("directional", color=color, intensity=float(generator.uniform(1.0, 4.0)),
                                direction=tuple(direction.tolist())))
        else:
            position = -direction / np.linalg.norm(direction) * distance * generator.uniform(0.5, 1.5)
            position[2] += distance  # around the objects, on the camera's side
            power = float(generator.uniform(1.0, 4.0)) * distance ** 2
            lights.append(Light("point", color=color, intensity=power, position=tuple(position.tolist())))
    return Lighting(ambient=ambient, lights=tuple(lights))


def random_tints(generator: np.random.Generator, count: int, jitter: float) -> np.ndarray:
    """``(count, 3)`` per-channel colour factors in ``[1 - jitter, 1 + jitter]``."""
    return generator.uniform(1.0 - jitter, 1.0 + jitter, size=(count, 3))


def random_colors(generator: np.random.Generator, count: int) -> np.ndarray:
    """``(count, 3)`` saturated random colours (linear factors) for white distractor primitives."""
    return generator.uniform(0.05, 1.0, size=(count, 3))


def procedural_background(generator: np.random.Generator, width: int, height: int) -> np.ndarray:
    """``(H, W, 3)`` uint8 multi-octave value noise mixed between two random colours, sometimes with
    stripes. The octaves are summed on a 33×33 grid, the sum is enlarged to half resolution (cubic),
    coloured through a lookup table, striped, then enlarged to ``W×H``: the pattern is smooth anyway."""
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


def composite(foreground: np.ndarray, alpha: np.ndarray, background: np.ndarray) -> np.ndarray:
    """``alpha`` (uint8, 255 = opaque) blend of uint8 RGB images, computed only inside the bounding
    box of ``alpha > 0`` (the same result as :func:`paz6d.backend.image.alpha_blend` up to rounding,
    several times faster)."""
    image = background.copy()
    window = nonzero_window(alpha)
    if window is None:
        return image
    weight = alpha[window].astype(np.uint16)[..., None]
    blended = (foreground[window].astype(np.uint16) * weight + background[window] * (255 - weight) + 127) // 255
    image[window] = blended.astype(np.uint8)
    return image


def background_image(generator: np.random.Generator, files: list[Path], width: int, height: int) -> np.ndarray:
    """A random crop of a random file (or a procedural background without files), ``(H, W, 3)`` uint8."""
    if not files:
        return procedural_background(generator, width, height)
    image = load_image(files[int(generator.integers(len(files)))])
    source_height, source_width = image.shape[:2]
    scale = generator.uniform(0.5, 1.0) * min(source_width / width, source_height / height)
    crop_width, crop_height = max(1, int(round(width * scale))), max(1, int(round(height * scale)))
    x = int(generator.integers(0, source_width - crop_width + 1))
    y = int(generator.integers(0, source_height - crop_height + 1))
    crop = image[y:y + crop_height, x:x + crop_width]
    if generator.random() < 0.5:
        crop = crop[:, ::-1]
    return cv2.resize(np.ascontiguousarray(crop), (width, height), interpolation=cv2.INTER_LINEAR)


#: The 256 quantiles ``(i + 0.5) / 256`` of the standard normal: a uniform byte indexes one, which
#: draws 8-bit-quantized Gaussian noise (cut at ±2.9 sigma) about 4x faster than ``standard_normal``.
NORMAL_QUANTILES = np.array([NormalDist().inv_cdf((i + 0.5) / 256) for i in range(256)], dtype=np.float32)


def gaussian_noise(generator: np.random.Generator, image: np.ndarray, std: float) -> np.ndarray:
    """``image`` (uint8) plus zero-mean Gaussian noise of ``std`` grey levels, rounded and clipped."""
    indices = generator.integers(0, 256, size=image.shape, dtype=np.uint8)
    noise = cv2.LUT(indices, NORMAL_QUANTILES * np.float32(std))
    return cv2.add(image.astype(np.float32), noise, dtype=cv2.CV_8U)  # saturating: rounds and clips


def degrade(generator: np.random.Generator, image: np.ndarray, config: GenerationConfig) -> np.ndarray:
    """Random Gaussian blur (with ``blur_probability``) then, for half of the images, Gaussian
    noise up to ``noise_std`` grey levels (:func:`gaussian_noise`)."""
    if generator.random() < config.blur_probability:
        image = gaussian_blur(image, 5, sigma=float(generator.uniform(0.4, 1.2)))
    if config.noise_std > 0 and generator.random() < 0.5:
        image = gaussian_noise(generator, image, float(generator.uniform(0, config.noise_std)))
    return image
