"""Square crops around boxes and the way back, over :mod:`paz6d.backend.square_crop`.

AAE, KeypointNet and the face pipelines crop the same way: a square window of side
``margin × longest box side`` (integer corner) centred on the box, resampled to ``size × size``
pixels, zero outside the image.
"""

from __future__ import annotations

import numpy as np

from paz6d.abstract.messages import Box2D
from paz6d.abstract.processor import Processor
from paz6d.backend.boxes import check_box_in_image, move_box
from paz6d.backend.square_crop import crop_square, square_window, to_full_image


class SquareCrop(Processor):
    """``(image (H, W[, C]), box) -> (crop (size, size[, C]), window (x_min, y_min, side))``.

    Args:
        margin: window side / longest box side.
        size: output side in pixels.
    """

    def __init__(self, margin: float, size: int, name: str | None = None):
        super().__init__(name)
        if not margin > 0:
            raise ValueError(f"margin: expected a positive window side / box side ratio, got {margin}")
        if int(size) <= 0:
            raise ValueError(f"size: expected a positive crop side in pixels, got {size}")
        self.margin, self.size = float(margin), int(size)

    def call(self, image: np.ndarray, box) -> tuple[np.ndarray, tuple[int, int, int]]:
        coordinates = check_box_in_image(Box2D.coordinates_of(box), image.shape[1], image.shape[0])
        window = square_window(coordinates, self.margin)
        return crop_square(image, window, self.size), window


class CropToImage(Processor):
    """``(points (N, 2) crop pixels, window) -> (N, 2)`` image pixels, for crops made by :class:`SquareCrop`.

    Args:
        size: side of the crop in pixels.
    """

    def __init__(self, size: int, name: str | None = None):
        super().__init__(name)
        self.size = int(size)

    def call(self, points, window: tuple[int, int, int]) -> np.ndarray:
        return to_full_image(points, window, self.size)


class BoxVariants(Processor):
    """``box (4,) xyxy -> (V, 4)``: the box itself first, then every combination of a shift along x, a shift
    along y (fractions of the box's width and height) and a scale about its centre.

    A pose model that scores its own crops (the AAE: cosine similarity to its codebook) can pick the variant it
    recognises best, which re-centres a detector's loose box (``ImplicitPose6D(box_variants=...)``).

    Args:
        shifts: shifts as fractions of the box's width (x) and height (y).
        scales: side factors about the box centre.
        The defaults (75 variants) are the grid measured in ``docs/experiments/2026-12-05-lmo-box-search.md``.
    Raises:
        ValueError: an empty or non-finite list, a scale that is not positive.
    """

    def __init__(self, shifts=(-0.1, -0.05, 0.0, 0.05, 0.1), scales=(0.9, 1.0, 1.1), name: str | None = None):
        super().__init__(name)
        self.shifts = np.asarray(shifts, dtype=np.float64).reshape(-1)
        self.scales = np.asarray(scales, dtype=np.float64).reshape(-1)
        if self.shifts.size == 0 or not np.all(np.isfinite(self.shifts)):
            raise ValueError(f"shifts: expected finite fractions of the box side, got {list(shifts)}")
        if self.scales.size == 0 or not np.all(np.isfinite(self.scales) & (self.scales > 0)):
            raise ValueError(f"scales: expected positive side factors, got {list(scales)}")
        dx, dy, scale = np.meshgrid(self.shifts, self.shifts, self.scales, indexing="ij")
        variants = np.stack([dx.ravel(), dy.ravel(), scale.ravel()], axis=1)
        identity = np.all(variants == (0.0, 0.0, 1.0), axis=1)
        self.variants = np.concatenate([[(0.0, 0.0, 1.0)], variants[~identity]])  # (V, 3): dx, dy, scale

    def __len__(self) -> int:
        return len(self.variants)

    def call(self, box) -> np.ndarray:
        return move_box(Box2D.coordinates_of(box), self.variants)
