"""Ground truth to SSD training targets, and network outputs back to detections (numpy).

Boxes here are normalised ``xyxy`` (fractions of the image width/height); priors are normalised
``cxcywh`` (:func:`paz6d.ssd.model.priors_for`). Class ids count from 1; 0 is the background.
"""

from __future__ import annotations

import numpy as np

from paz6d.backend import boxes as boxes_backend

#: Name of class 0 (ToBoxes2D looks names up by class id, so the list of names starts with it).
BACKGROUND = "background"


def encode_targets(boxes, class_ids, priors, num_classes: int, iou_threshold: float = 0.5,
                   variances=boxes_backend.SSD_VARIANCES) -> np.ndarray:
    """Training target ``(P, 4 + num_classes)`` float32 of one image.

    Each prior is matched (:func:`paz6d.backend.boxes.match`) to a ground-truth box; matched priors
    hold the encoded offsets (:func:`paz6d.backend.boxes.encode`) and the one-hot class, the others
    zero offsets and the one-hot background.

    Args:
        boxes: ``(M, 4)`` normalised ``xyxy`` (``M`` may be 0); boxes without area are ignored.
        class_ids: ``(M,)`` integers in ``[1, num_classes)``.
        priors: ``(P, 4)`` normalised ``cxcywh``.
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    class_ids = np.asarray(class_ids).reshape(-1)
    if len(class_ids) != len(boxes):
        raise ValueError(f"class_ids: expected {len(boxes)} ids matching boxes, got {len(class_ids)}")
    if len(class_ids) and (not np.issubdtype(class_ids.dtype, np.integer) or class_ids.min() < 1
                           or class_ids.max() >= num_classes):
        raise ValueError(f"class_ids: expected integers in [1, {num_classes}), got {class_ids.tolist()}")
    valid = np.all(boxes[:, 2:] > boxes[:, :2], axis=1)
    boxes, class_ids = boxes[valid], class_ids[valid]
    targets = np.zeros((len(priors), 4 + num_classes), dtype=np.float32)
    matched = boxes_backend.match(boxes, priors, iou_threshold)
    positive = matched >= 0
    targets[~positive, 4] = 1.0
    if np.any(positive):
        targets[positive, :4] = boxes_backend.encode(boxes[matched[positive]], priors[positive], variances)
        targets[positive, 4 + class_ids[matched[positive]]] = 1.0
    return targets


def softmax(logits, axis: int = -1) -> np.ndarray:
    """Numerically stable softmax of float logits."""
    logits = np.asarray(logits, dtype=np.float64)
    shifted = np.exp(logits - logits.max(axis=axis, keepdims=True))
    return shifted / shifted.sum(axis=axis, keepdims=True)


def decode_outputs(outputs, priors, variances=boxes_backend.SSD_VARIANCES) -> tuple[np.ndarray, np.ndarray]:
    """One image's network output ``(P, 4 + C)`` to normalised ``xyxy`` boxes ``(P, 4)`` (clipped to
    the image) and class probabilities ``(P, C)`` (softmax; column 0 is the background)."""
    outputs = np.asarray(outputs, dtype=np.float64)
    if outputs.ndim != 2 or outputs.shape[0] != len(priors) or outputs.shape[1] < 6:
        raise ValueError(f"outputs: expected shape ({len(priors)}, 4 + C) with C >= 2, got {outputs.shape}")
    boxes = boxes_backend.clip(boxes_backend.decode(outputs[:, :4], priors, variances), (1.0, 1.0))
    return boxes, softmax(outputs[:, 4:])


def select_detections(boxes, probabilities, score_threshold: float = 0.01, iou_threshold: float = 0.45,
                      max_detections: int = 100, candidates_per_class: int = 200, vote_iou: float | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-class non-maximum suppression over every (prior, object class) pair.

    Args:
        boxes: ``(P, 4)`` ``xyxy``; probabilities: ``(P, C)`` with the background in column 0.
        score_threshold: pairs scoring below it are dropped.
        iou_threshold: NMS overlap threshold (within one class).
        max_detections: most detections returned over all classes.
        candidates_per_class: best pairs of each class that enter NMS.
        vote_iou: ``None`` keeps each NMS winner's own box; a number replaces it by the score-weighted mean of the
            candidates of its class overlapping it by at least this IoU (box voting,
            :func:`paz6d.backend.boxes.vote_boxes`).
    Returns:
        ``boxes (K, 4)``, ``scores (K,)``, ``class_ids (K,)`` (1-based) by decreasing score.
    """
    boxes = boxes_backend.as_boxes(boxes).reshape(-1, 4)
    scores = np.asarray(probabilities, dtype=np.float64)[:, 1:]
    if scores.shape[0] != len(boxes):
        raise ValueError(f"probabilities: expected {len(boxes)} rows matching boxes, got {scores.shape[0]}")
    keep_per_class = min(int(candidates_per_class), len(boxes))
    best = np.argpartition(-scores, keep_per_class - 1, axis=0)[:keep_per_class]  # (k, C - 1) prior indices
    classes = np.broadcast_to(np.arange(scores.shape[1]), best.shape)
    prior_index, class_index = best.ravel(), classes.ravel()
    candidate_scores = scores[prior_index, class_index]
    kept = candidate_scores >= score_threshold
    prior_index, class_index, candidate_scores = prior_index[kept], class_index[kept], candidate_scores[kept]
    candidates = boxes[prior_index]
    chosen = boxes_backend.nms_per_class(candidates, candidate_scores, class_index, iou_threshold,
                                         max_outputs=max_detections)
    chosen_boxes = candidates[chosen] if vote_iou is None else \
        boxes_backend.vote_boxes(chosen, candidates, candidate_scores, class_index, vote_iou)
    return chosen_boxes, candidate_scores[chosen], class_index[chosen] + 1
