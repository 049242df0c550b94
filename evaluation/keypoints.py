"""PCK (percentage of correct keypoints) for 2D keypoints.

A visible keypoint is correct when its predicted position lies within ``alpha * reference_size``
pixels of the target (distance ``<=`` threshold). The reference size is per instance, e.g. the
longer side of its bounding box (PCK@alpha of the box) or a head/torso length (PCKh). Invisible
keypoints are left out of every count.

Example:
    >>> import numpy as np
    >>> from evaluation.keypoints import pck
    >>> target = np.zeros((1, 2, 2)); predicted = np.array([[[1.0, 0.0], [5.0, 0.0]]])
    >>> pck(predicted, target, reference_size=[10.0], alpha=0.2).pck
    0.5
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from paz6d.backend.checks import as_array

REFERENCE_MODES = ("max_side", "diagonal")


@dataclass(frozen=True)
class PckResult:
    """PCK of a set of instances.

    Attributes:
        alpha: threshold as a fraction of the reference size.
        pck: correct / visible over all keypoints; NaN when nothing is visible.
        per_keypoint: (K,) PCK of each keypoint index; NaN where never visible.
        correct: (N, K) bool, visible and within the threshold.
        visible: (N, K) bool visibility used.
        distances: (N, K) pixel distances between prediction and target.
    """

    alpha: float
    pck: float
    per_keypoint: np.ndarray
    correct: np.ndarray
    visible: np.ndarray
    distances: np.ndarray


def reference_sizes_from_boxes(boxes, mode: str = "max_side") -> np.ndarray:
    """(N,) reference sizes in pixels from ``(N, 4)`` boxes ``(x_min, y_min, x_max, y_max)``.

    Args:
        mode: ``"max_side"`` (``max(w, h)``) or ``"diagonal"`` (``sqrt(w^2 + h^2)``).
    """
    boxes = as_array(boxes, "boxes", (4,))
    if boxes.ndim != 2:
        raise ValueError(f"boxes: expected shape (N, 4), got {boxes.shape}")
    width, height = boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1]
    if np.any(width < 0) or np.any(height < 0):
        raise ValueError("boxes: expected x_max >= x_min and y_max >= y_min")
    if mode == "max_side":
        return np.maximum(width, height)
    if mode == "diagonal":
        return np.hypot(width, height)
    raise ValueError(f"mode: expected one of {REFERENCE_MODES}, got {mode!r}")


def pck(predicted, target, reference_size, alpha: float = 0.2, visible=None) -> PckResult:
    """PCK@alpha of predicted keypoints.

    Args:
        predicted: (N, K, 2) predicted keypoints in pixels.
        target: (N, K, 2) ground-truth keypoints in pixels.
        reference_size: (N,) positive reference length per instance in pixels (a scalar is
            broadcast), e.g. :func:`reference_sizes_from_boxes`.
        alpha: threshold fraction, > 0.
        visible: (N, K) bool visibility mask; ``None`` means all visible.

    Returns:
        Overall and per-keypoint PCK with the per-keypoint decisions.
    """
    predicted = as_array(predicted, "predicted", (2,))
    target = as_array(target, "target", (2,))
    if predicted.ndim != 3:
        raise ValueError(f"predicted: expected shape (N, K, 2), got {predicted.shape}")
    if target.shape != predicted.shape:
        raise ValueError(f"target: expected shape {predicted.shape} like predicted, got {target.shape}")
    count, keypoint_count = predicted.shape[:2]
    sizes = np.broadcast_to(np.asarray(reference_size, dtype=np.float64), (count,)) \
        if np.ndim(reference_size) == 0 else np.asarray(reference_size, dtype=np.float64)
    if sizes.shape != (count,) or not np.all(np.isfinite(sizes)) or np.any(sizes <= 0):
        raise ValueError(f"reference_size: expected {count} positive finite values, got shape {sizes.shape}")
    if not (np.isfinite(alpha) and alpha > 0):
        raise ValueError(f"alpha: expected a positive number, got {alpha}")
    if visible is None:
        mask = np.ones((count, keypoint_count), dtype=bool)
    else:
        mask = np.asarray(visible)
        if mask.shape != (count, keypoint_count) or mask.dtype.kind not in "bi":
            raise ValueError(f"visible: expected a boolean array of shape {(count, keypoint_count)}, "
                             f"got {mask.dtype} {mask.shape}")
        mask = mask.astype(bool)
    distances = np.linalg.norm(predicted - target, axis=-1)
    correct = mask & (distances <= alpha * sizes[:, None])
    visible_per_keypoint = mask.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        per_keypoint = np.where(visible_per_keypoint > 0, correct.sum(axis=0) / visible_per_keypoint, np.nan)
    total = int(mask.sum())
    overall = float(correct.sum() / total) if total else float("nan")
    return PckResult(alpha=float(alpha), pck=overall, per_keypoint=per_keypoint, correct=correct, visible=mask,
                     distances=distances)
