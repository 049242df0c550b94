"""2D keypoints ``(..., 2)`` in pixels: normalization and left-right flipping.

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

from collections.abc import Sequence

import numpy as np

from paz6d.backend.checks import as_array

RANGES = ((-1.0, 1.0), (0.0, 1.0))


def _scale_and_offset(image_size, value_range: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
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
    scale, offset = _scale_and_offset(image_size, value_range)
    return keypoints * scale + offset


def denormalize(keypoints, image_size, value_range: tuple[float, float] = (-1.0, 1.0)) -> np.ndarray:
    """Inverse of :func:`normalize`: normalized ``(..., 2)`` back to pixels."""
    keypoints = as_array(keypoints, "keypoints", (2,))
    scale, offset = _scale_and_offset(image_size, value_range)
    return (keypoints - offset) / scale


def flip_left_right(keypoints, image_width: int, permutation: Sequence[int] | None = None) -> np.ndarray:
    """Keypoints ``(..., N, 2)`` of an image mirrored left-right (``u -> W - 1 - u``).

    Args:
        image_width: ``W`` in pixels.
        permutation: optional reordering applied after mirroring so that semantic names stay
            right (e.g. swap left/right eyes): ``output[..., i, :] = mirrored[..., permutation[i], :]``.
    """
    keypoints = as_array(keypoints, "keypoints", (2,))
    flipped = keypoints.copy()
    flipped[..., 0] = image_width - 1.0 - keypoints[..., 0]
    if permutation is None:
        return flipped
    permutation = np.asarray(permutation)
    count = keypoints.shape[-2] if keypoints.ndim >= 2 else 0
    if (permutation.shape != (count,) or not np.issubdtype(permutation.dtype, np.integer)
            or sorted(permutation.tolist()) != list(range(count))):
        raise ValueError(f"permutation: expected a permutation of range({count}), got {permutation.tolist()}")
    return flipped[..., permutation, :]
