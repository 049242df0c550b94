"""2D keypoints ``(..., 2)`` in pixels to normalized coordinates (the keypoint networks' losses).

Pixel coordinates follow the camera convention (OpenCV): integer coordinates are pixel centres,
so an image of width ``W`` spans ``u`` in ``[-0.5, W - 0.5]``. Normalization maps that extent
(not the pixel centres) onto ``[-1, 1]`` or ``[0, 1]``; it matches :meth:`Camera.scaled`, so
normalized coordinates do not change when an image is resized.

Example:
    >>> from paz6d.backend import keypoints
    >>> keypoints.normalize([[-0.5, 99.5], [49.5, 49.5]], (100, 100)).tolist()
    [[-1.0, 1.0], [0.0, 0.0]]
"""

from __future__ import annotations

import numpy as np

from paz6d.backend.checks import as_array

RANGES = ((-1.0, 1.0), (0.0, 1.0))


def normalization(image_size, value_range: tuple[float, float] = (-1.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """``(scale, offset)``, each ``(2,)`` float64 per ``(u, v)``: normalized = pixels * scale + offset, for
    ``image_size = (width, height)`` (usable on arrays and tensors alike).

    Raises:
        ValueError: a non-positive size or another ``value_range`` than :data:`RANGES`.
    """
    size = np.asarray(image_size, dtype=np.float64)
    if size.shape != (2,) or not np.all(np.isfinite(size)) or np.any(size <= 0):
        raise ValueError(f"image_size: expected positive (width, height), got {image_size!r}")
    if tuple(value_range) not in RANGES:
        raise ValueError(f"value_range: expected one of {RANGES}, got {value_range!r}")
    if tuple(value_range) == (0.0, 1.0):
        return 1.0 / size, 0.5 / size
    return 2.0 / size, 1.0 / size - 1.0


def normalize(keypoints, image_size, value_range: tuple[float, float] = (-1.0, 1.0)) -> np.ndarray:
    """Pixels ``(..., 2)`` to normalized coordinates; ``image_size = (width, height)``.

    ``value_range=(-1, 1)`` gives ``(2u + 1) / W - 1``; ``(0, 1)`` gives ``(u + 0.5) / W``.
    """
    keypoints = as_array(keypoints, "keypoints", (2,))
    scale, offset = normalization(image_size, value_range)
    return keypoints * scale + offset
