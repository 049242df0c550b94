"""COCO run-length encoding of binary masks (pycocotools' uncompressed ``counts`` format), for the
``scene_gt_coco.json`` files ``paz6d generate`` writes; ``evaluation.coco_masks.decode_rle`` decodes.

COCO RLE runs over the mask in column-major (Fortran) order, alternating background and
foreground runs and starting with a (possibly empty) background run.
"""

from __future__ import annotations

import numpy as np


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
