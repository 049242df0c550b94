"""Square crops around a box, resized to ``size × size``, and the intrinsics of the crop.

A crop is described by its integer square window ``(x_min, y_min, side)`` in box coordinates (pixel
``i`` covers ``[i, i + 1)``) and by the ``3×3`` affine ``A`` that maps camera pixel coordinates of
the full image (pixel centres at integers, as in :mod:`paz6d.backend.camera`) to those of the crop:
``u_crop = s * (u + 0.5 - x_min) - 0.5`` with ``s = size / side``. The crop's intrinsics are
``A @ K``, so projecting with them is the same as projecting with ``K`` and mapping through ``A``.

Example:
    >>> import numpy as np
    >>> window = square_window((10, 20, 30, 60), margin=1.0)
    >>> window
    (0, 20, 40)
    >>> crop_transform(window, 40)[0].tolist()
    [1.0, 0.0, 0.0]
"""

from __future__ import annotations

import cv2
import numpy as np

from paz6d.backend.checks import as_array, as_camera_matrix


def projected_box(points, T_model2cam, K) -> np.ndarray:
    """``xyxy`` box (pixel ``i`` covers ``[i, i + 1)``) of the projection of ``(N, 3)`` model points.

    For an object's vertices (or their convex hull) this is the box of its silhouette.
    """
    points = as_array(points, "points", (3,))
    T_model2cam = as_array(T_model2cam, "T_model2cam", (4, 4))
    K = as_camera_matrix(K)
    camera_points = points @ T_model2cam[:3, :3].T + T_model2cam[:3, 3]
    if np.any(camera_points[:, 2] <= 0):
        raise ValueError("T_model2cam: part of the object is behind the camera (z <= 0)")
    pixels = camera_points[:, :2] / camera_points[:, 2:] @ K[:2, :2].T + K[:2, 2]
    return np.concatenate([pixels.min(axis=0) + 0.5, pixels.max(axis=0) + 0.5])


def square_window(box, margin: float = 1.25) -> tuple[int, int, int]:
    """Integer square ``(x_min, y_min, side)`` centred on ``xyxy`` ``box``, ``side = margin * max(w, h)``.

    The window may extend beyond the image; :func:`crop_square` pads it.
    """
    x_min, y_min, x_max, y_max = as_array(box, "box", (4,)).reshape(4)
    if x_max <= x_min or y_max <= y_min:
        raise ValueError(f"box: expected a non-empty (x_min, y_min, x_max, y_max) box, got "
                         f"{[x_min, y_min, x_max, y_max]}")
    if not np.isfinite(margin) or margin <= 0:
        raise ValueError(f"margin: expected a positive factor, got {margin}")
    side = max(1, int(round(margin * max(x_max - x_min, y_max - y_min))))
    centre_x, centre_y = 0.5 * (x_min + x_max), 0.5 * (y_min + y_max)
    return int(round(centre_x - side / 2)), int(round(centre_y - side / 2)), side


def crop_transform(window: tuple[int, int, int], size: int) -> np.ndarray:
    """``3×3`` affine from full-image pixel coordinates to the ``size × size`` crop of ``window``."""
    x_min, y_min, side = window
    if side <= 0 or size <= 0:
        raise ValueError(f"window/size: expected a positive side and size, got {side}, {size}")
    scale = size / side
    return np.array([[scale, 0.0, scale * (0.5 - x_min) - 0.5],
                     [0.0, scale, scale * (0.5 - y_min) - 0.5],
                     [0.0, 0.0, 1.0]])


def crop_intrinsics(K, window: tuple[int, int, int], size: int) -> np.ndarray:
    """Intrinsics ``(3, 3)`` of the ``size × size`` crop of ``window`` taken from an image with ``K``."""
    return crop_transform(window, size) @ as_camera_matrix(K)


def to_full_image(points, window: tuple[int, int, int], size: int) -> np.ndarray:
    """Maps ``(..., 2)`` crop pixel coordinates back to the full image."""
    points = as_array(points, "points", (2,))
    x_min, y_min, side = window
    scale = size / side
    return (points + 0.5) / scale + np.array([x_min, y_min]) - 0.5


def crop_square(image: np.ndarray, window: tuple[int, int, int], size: int, pad_value: int = 0) -> np.ndarray:
    """Resamples ``window`` of ``image`` ``(H, W[, C])`` to ``size × size`` (``pad_value`` outside the image).

    One bilinear resampling through :func:`crop_transform` (so crop pixels sit exactly where
    ``crop_intrinsics`` says); when shrinking by more than 1.3× the window is first smoothed with a
    Gaussian of sigma ``0.4 × shrink`` pixels against aliasing, at most 1/32 of the image's longer
    side: the cap is reached only when the whole image spans fewer than 13 crop pixels (a box of
    ±1e9 px), where a wider blur would cost time growing with the window and show nothing more.
    """
    image = np.asarray(image)
    if image.ndim not in (2, 3) or 0 in image.shape:
        raise ValueError(f"image: expected a non-empty (H, W) or (H, W, C) array, got shape {image.shape}")
    x_min, y_min, side = window
    height, width = image.shape[:2]
    if x_min + side <= 0 or y_min + side <= 0 or x_min >= width or y_min >= height:
        raise ValueError(f"window: {window} (x_min, y_min, side) does not overlap the {width}x{height} image")
    A = crop_transform(window, size)
    shrink = side / size
    if shrink > 1.3:
        sigma = min(0.4 * shrink, max(height, width) / 32.0)
        reach = int(np.ceil(3 * sigma)) + 1
        left, top = max(x_min - reach, 0), max(y_min - reach, 0)
        right, bottom = min(x_min + side + reach, width), min(y_min + side + reach, height)
        image = cv2.GaussianBlur(image[top:bottom, left:right], (0, 0), sigma)
        A = A @ np.array([[1.0, 0.0, left], [0.0, 1.0, top], [0.0, 0.0, 1.0]])
    channels = image.shape[2] if image.ndim == 3 else 1
    border = (pad_value,) * min(channels, 4)
    return cv2.warpAffine(image, A[:2], (size, size), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                          borderValue=border)
