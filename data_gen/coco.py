"""COCO run-length encoding of binary masks (pycocotools' uncompressed ``counts`` format).

COCO RLE runs over the mask in column-major (Fortran) order, alternating background and
foreground runs and starting with a (possibly empty) background run.
"""

from __future__ import annotations

import numpy as np

from paz6d.backend.image import nonzero_window


def encode_rle(mask: np.ndarray) -> dict:
    """``(H, W)`` bool mask to ``{"counts": [int, ...], "size": [H, W]}``.

    Example:
        >>> encode_rle(np.array([[0, 1], [1, 1]], dtype=bool))
        {'counts': [1, 3], 'size': [2, 2]}
    """
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise ValueError(f"mask: expected shape (H, W), got {mask.shape}")
    flat = mask.astype(bool).ravel(order="F")
    changes = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    boundaries = np.concatenate([[0], changes, [flat.size]])
    counts = np.diff(boundaries).tolist()
    if flat.size and flat[0]:
        counts = [0] + counts
    return {"counts": counts, "size": [int(mask.shape[0]), int(mask.shape[1])]}


def decode_rle(rle: dict) -> np.ndarray:
    """Inverse of :func:`encode_rle` (uncompressed counts only)."""
    height, width = rle["size"]
    counts = np.asarray(rle["counts"], dtype=np.int64)
    if counts.sum() != height * width:
        raise ValueError(f"rle: counts sum to {counts.sum()}, expected {height * width} pixels")
    values = np.arange(len(counts)) % 2 == 1
    return np.repeat(values, counts).reshape((height, width), order="F")


def bbox_xywh(mask: np.ndarray) -> list[int]:
    """Tight ``[x, y, width, height]`` of a mask's pixels; ``[-1, -1, -1, -1]`` when empty (BOP)."""
    window = nonzero_window(mask)
    if window is None:
        return [-1, -1, -1, -1]
    rows, columns = window
    return [columns.start, rows.start, columns.stop - columns.start, rows.stop - rows.start]
