"""Random similarity warps (rotation, zoom, shift) for image augmentation, any channel count.

Used for face-expression training (Arriaga et al. 2017 augment with rotations of 10 degrees,
10 % zoom and 10 % shifts). Borders are filled by replicating the edge pixels so no black
corners appear.

Example:
    >>> import numpy as np
    >>> from paz6d.processors.affine import RandomAffine
    >>> RandomAffine(seed=0)(np.zeros((48, 48), np.uint8)).shape
    (48, 48)
"""

from __future__ import annotations

import cv2
import numpy as np

from paz6d.abstract.processor import RandomProcessor


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
