"""Domain randomization drawn from one ``numpy.random.Generator`` per image: lights, object
colours, backgrounds and image degradations."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from data_gen.config import GenerationConfig
from paz6d.backend.image import add_gaussian_noise, gaussian_blur, load_image
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
    """``(H, W, 3)`` uint8 multi-octave value noise mixed between random colours."""
    field = np.zeros((height, width), dtype=np.float32)
    for octave, cells in enumerate((2, 4, 8, 32)):
        grid = generator.random((cells + 1, cells + 1)).astype(np.float32)
        field += cv2.resize(grid, (width, height), interpolation=cv2.INTER_CUBIC) / (octave + 1)
    field = (field - field.min()) / max(float(field.max() - field.min()), 1e-6)
    low, high = generator.uniform(0, 255, 3), generator.uniform(0, 255, 3)
    image = low + field[..., None] * (high - low)
    if generator.random() < 0.5:  # stripes or checks add edges, as real clutter does
        period = generator.uniform(8, 64)
        angle = generator.uniform(0, np.pi)
        rows, columns = np.mgrid[0:height, 0:width]
        stripes = np.sin((columns * np.cos(angle) + rows * np.sin(angle)) * 2 * np.pi / period) > 0
        image = np.where(stripes[..., None], image, 255 - image)
    return np.clip(image, 0, 255).astype(np.uint8)


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


def degrade(generator: np.random.Generator, image: np.ndarray, config: GenerationConfig) -> np.ndarray:
    """Random Gaussian blur (with ``blur_probability``) then Gaussian noise up to ``noise_std``."""
    if generator.random() < config.blur_probability:
        image = gaussian_blur(image, 5, sigma=float(generator.uniform(0.4, 1.2)))
    if config.noise_std > 0:
        image = add_gaussian_noise(image, float(generator.uniform(0, config.noise_std)), seed=generator)
    return image
