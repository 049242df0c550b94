"""Mask geometry: pasting a crop's mask back into the image, box jitter, COCO RLE, background blanking.

Crops are the square windows ``(x_min, y_min, side)`` of :mod:`paz6d.backend.square_crop` (pixel ``i`` covers
``[i, i + 1)``); a crop pixel ``(u, v)`` of a ``size x size`` crop sits at image pixel
``(u + 0.5) * side / size + x_min - 0.5``.
"""

from __future__ import annotations

import cv2
import numpy as np

from paz6d.backend.boxes import check_box_in_image
from paz6d.backend.square_crop import crop_transform


def box_pixels(box, width: int, height: int) -> tuple[int, int, int, int]:
    """Integer pixel range ``(left, top, right, bottom)`` (exclusive ends) of the pixels an ``xyxy`` box touches,
    clipped to a ``width x height`` image."""
    x_min, y_min, x_max, y_max = (float(value) for value in np.asarray(box, np.float64).reshape(4))
    left, top = max(int(np.floor(x_min)), 0), max(int(np.floor(y_min)), 0)
    right, bottom = min(int(np.ceil(x_max)), width), min(int(np.ceil(y_max)), height)
    return left, top, max(right, left), max(bottom, top)


def paste_mask(crop_values, window: tuple[int, int, int], box, image_size: tuple[int, int]) -> np.ndarray:
    """Maps a crop's values back into the image, inside ``box`` only (Mask R-CNN pastes into the box).

    Args:
        crop_values: ``(S, S)`` float values (probabilities) of the crop of ``window``.
        window: ``(x_min, y_min, side)`` the crop was cut from.
        box: ``xyxy`` pixel box; image pixels outside it get 0.
        image_size: ``(width, height)``.
    Returns:
        ``(H, W) float32``: bilinear resampling of ``crop_values`` at each pixel centre of the box, 0 elsewhere.
    """
    crop_values = np.asarray(crop_values, np.float32)
    if crop_values.ndim != 2 or crop_values.shape[0] != crop_values.shape[1]:
        raise ValueError(f"crop_values: expected a square (S, S) map, got shape {crop_values.shape}")
    width, height = int(image_size[0]), int(image_size[1])
    box = check_box_in_image(np.asarray(box, np.float64).reshape(4), width, height, "box")
    out = np.zeros((height, width), np.float32)
    left, top, right, bottom = box_pixels(box, width, height)
    if right <= left or bottom <= top:
        return out
    # image pixel (left + i, top + j) -> crop coordinates: crop_transform @ translation
    A = crop_transform(window, crop_values.shape[0]) @ np.array([[1.0, 0, left], [0, 1.0, top], [0, 0, 1.0]])
    out[top:bottom, left:right] = cv2.warpAffine(crop_values, A[:2], (right - left, bottom - top),
                                                 flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                                 borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
    return out


def jitter_box(box, rng: np.random.Generator, jitter: float) -> np.ndarray:
    """A detector-like perturbation of an ``xyxy`` box: centre shifted by up to ``jitter`` x its width/height,
    each side scaled by a factor in ``[1 - jitter, 1 + jitter]`` (uniform)."""
    x_min, y_min, x_max, y_max = np.asarray(box, np.float64).reshape(4)
    width, height = x_max - x_min, y_max - y_min
    centre = np.array([x_min + width / 2, y_min + height / 2]) + rng.uniform(-jitter, jitter, 2) * [width, height]
    size = np.array([width, height]) * rng.uniform(1 - jitter, 1 + jitter, 2)
    return np.concatenate([centre - size / 2, centre + size / 2])


def rle_from_mask(mask) -> dict:
    """``(H, W)`` bool mask -> COCO uncompressed RLE ``{"counts": [...], "size": [H, W]}`` (column-major runs,
    starting with a run of zeros)."""
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise ValueError(f"mask: expected shape (H, W), got {mask.shape}")
    flat = mask.astype(bool).ravel(order="F")
    boundaries = np.concatenate([[0], np.flatnonzero(flat[1:] != flat[:-1]) + 1, [flat.size]])
    counts = np.diff(boundaries).tolist()
    if flat.size and flat[0]:
        counts = [0] + counts
    return {"counts": [int(count) for count in counts], "size": [int(mask.shape[0]), int(mask.shape[1])]}


def blank_background(image, mask, value: int = 0) -> np.ndarray:
    """A copy of ``image (H, W[, C])`` with every pixel outside ``mask (H, W) bool`` set to ``value``.

    Use it before a pose pipeline's crop so that clutter and neighbouring objects inside the box do not
    reach the pose network: ``ImplicitPose6D(...)(blank_background(image, mask), box)``.
    """
    image, mask = np.asarray(image), np.asarray(mask)
    if mask.shape != image.shape[:2] or mask.dtype != bool:
        raise ValueError(f"mask: expected a bool array of the image's shape {image.shape[:2]}, got {mask.dtype} "
                         f"{mask.shape}")
    blanked = image.copy()
    blanked[~mask] = value
    return blanked
