"""Square crops around boxes and the way back, over :mod:`paz6d.backend.square_crop`.

AAE, KeypointNet and the face pipelines crop the same way: a square window of side
``margin × longest box side`` (integer corner) centred on the box, resampled to ``size × size``
pixels, zero outside the image.
"""

from __future__ import annotations

import numpy as np

from paz6d.abstract.messages import Box2D
from paz6d.abstract.processor import Processor
from paz6d.backend.boxes import check_box_in_image
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
        coordinates = check_box_in_image(box.to_array() if isinstance(box, Box2D) else box, image.shape[1],
                                         image.shape[0])
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
