"""Where a detector's errors come from, per class (after Hoiem et al., "Diagnosing Error in Object
Detectors", ECCV 2012): what its best-scoring detections hit, and how many objects it finds at all.

For each category with ``n`` non-crowd ground-truth boxes, its detections are matched greedily in score
order (each to the free ground truth of that category in the same image with the highest IoU >= 0.5),
and the ``n`` best-scoring ones (as many as there are objects: a perfect detector's top ``n`` are all
correct) are sorted into :data:`ERROR_KINDS`:

* ``correct``: matched;
* ``duplicate``: IoU >= 0.5 with an object of the category that a better detection already took;
* ``localization``: IoU in [0.1, 0.5) with an object of the category;
* ``other_class``: IoU >= 0.1 with an object of another category (confusion with a known object);
* ``background``: none of these (a false positive on something that is not annotated).

Detections on crowd regions (at least half of the detection inside one) are left out. ``recall`` is
the share of objects matched by a detection of any score. Boxes are ``[x, y, w, h]`` pixels.

``confusion`` says what the detector calls each object: for every non-crowd ground-truth box, the category
of the best-scoring detection of *any* category at IoU >= 0.5 with it, or ``none`` when no detection
overlaps it so (a detector that finds an object but names it as another shows up off the diagonal).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from evaluation.coco import CocoDetections, CocoGroundTruth
from evaluation.coco_masks import box_iou

ERROR_KINDS = ("correct", "duplicate", "localization", "other_class", "background")
#: The confusion column of objects that no detection overlaps at IoU >= ``MATCH_IOU``.
NO_DETECTION = "none"
MATCH_IOU = 0.5
NEAR_IOU = 0.1


@dataclass
class DetectionErrors:
    """Per category (rows in ``category_names`` order, those with objects only).

    Attributes:
        category_names: K names.
        objects: (K,) non-crowd ground-truth boxes.
        recall: (K,) share of them found by a detection of any score at IoU >= 0.5.
        top: (K, len(ERROR_KINDS)) kinds of the ``objects[k]`` best-scoring detections (fewer when there
            are fewer detections).
        called_names: the C + 1 confusion columns: every category of the ground truth, then ``"none"``.
        confusion: (K, C + 1) objects of each row's category by the category of their best-scoring
            overlapping detection (module docstring); each row sums to ``objects``.
    """

    category_names: tuple[str, ...]
    objects: np.ndarray
    recall: np.ndarray
    top: np.ndarray
    called_names: tuple[str, ...]
    confusion: np.ndarray

    def to_dict(self) -> dict:
        """``{name: {"objects", "recall", kind: count, ..., "called": {category or "none": count}}}`` (``called``:
        the non-zero entries of the name's confusion row)."""
        return {name: {"objects": int(count), "recall": float(recall),
                       **{kind: int(value) for kind, value in zip(ERROR_KINDS, row)},
                       "called": {called: int(value) for called, value in zip(self.called_names, confused) if value}}
                for name, count, recall, row, confused in zip(self.category_names, self.objects, self.recall, self.top,
                                                              self.confusion)}

    def table(self) -> str:
        """A plain-text table, one row per category."""
        lines = [f"{'class':<24s} {'objects':>7s} {'recall':>6s}  top detections: "
                 + " ".join(f"{kind:>12s}" for kind in ERROR_KINDS)]
        for name, count, recall, row in zip(self.category_names, self.objects, self.recall, self.top):
            lines.append(f"{name:<24s} {count:7d} {recall:6.2f}  {'':16s}" + " ".join(f"{v:12d}" for v in row))
        lines.append("what each object is called (its best-scoring detection at IoU >= 0.5, any class):")
        for name, confused in zip(self.category_names, self.confusion):
            called = sorted(((int(v), n) for n, v in zip(self.called_names, confused) if v), key=lambda c: -c[0])
            lines.append(f"{name:<24s} " + ", ".join(f"{n} {v}" for v, n in called))
        return "\n".join(lines)


def detection_errors(ground_truth: CocoGroundTruth, detections: CocoDetections) -> DetectionErrors:
    """The per-category error breakdown of ``detections`` (boxes) against ``ground_truth``.

    Raises:
        ValueError: results without boxes.
    """
    if detections.boxes is None:
        raise ValueError(f"{detections.source}: the error breakdown needs boxes (bbox), the results carry masks only")
    kept, objects, recalls, tops = [], [], [], []
    for k, category_id in enumerate(ground_truth.category_ids.tolist()):
        own = (ground_truth.category_index == k)
        count = int(np.sum(own & ~ground_truth.is_crowd))
        if count == 0:
            continue
        rows = np.flatnonzero(detections.category_ids == category_id)
        rows = rows[np.argsort(-detections.scores[rows], kind="stable")]
        kinds, found = _classify(ground_truth, detections, rows, k)
        kept.append(k)
        objects.append(count)
        recalls.append(found / count)
        tops.append(np.bincount(kinds[:count], minlength=len(ERROR_KINDS)))
    return DetectionErrors(tuple(ground_truth.category_names[k] for k in kept), np.asarray(objects, dtype=np.int64),
                           np.asarray(recalls, dtype=np.float64),
                           np.asarray(tops, dtype=np.int64).reshape(-1, len(ERROR_KINDS)),
                           (*ground_truth.category_names, NO_DETECTION), _confusion(ground_truth, detections)[kept])


def _confusion(ground_truth: CocoGroundTruth, detections: CocoDetections) -> np.ndarray:
    """``(C, C + 1)`` counts: ground-truth category (every one of ``category_ids``) by the category of each
    non-crowd object's best-scoring detection at IoU >= ``MATCH_IOU`` (last column: none)."""
    count = len(ground_truth.category_ids)
    column = {int(category_id): k for k, category_id in enumerate(ground_truth.category_ids.tolist())}
    confusion = np.zeros((count, count + 1), dtype=np.int64)
    known = np.isin(detections.category_ids, ground_truth.category_ids)  # unknown categories are skipped, as in AP
    for image in np.unique(ground_truth.image_index):
        objects = np.flatnonzero((ground_truth.image_index == image) & ~ground_truth.is_crowd)
        found = np.flatnonzero((detections.image_index == image) & known)
        overlaps = box_iou(detections.boxes[found], ground_truth.boxes[objects])  # (detections, objects)
        for obj, iou in zip(objects.tolist(), overlaps.T):
            hits = found[iou >= MATCH_IOU]
            best = hits[np.argmax(detections.scores[hits])] if len(hits) else None
            called = count if best is None else column[int(detections.category_ids[best])]
            confusion[ground_truth.category_index[obj], called] += 1
    return confusion


def _classify(ground_truth: CocoGroundTruth, detections: CocoDetections, rows: np.ndarray,
              category: int) -> tuple[np.ndarray, int]:
    """Kind index of each detection of ``rows`` (score order; crowd hits dropped) and the objects found."""
    taken: set[int] = set()
    kinds = []
    for row in rows:
        in_image = np.flatnonzero(ground_truth.image_index == detections.image_index[row])
        crowd = ground_truth.is_crowd[in_image]
        # COCO's box IoU: against a crowd region, the share of the detection inside it
        iou = box_iou(detections.boxes[row], ground_truth.boxes[in_image], crowd)[0]
        own = (ground_truth.category_index[in_image] == category)
        same, same_iou = in_image[own & ~crowd], iou[own & ~crowd]
        free = np.array([index not in taken for index in same.tolist()], dtype=bool)
        if np.any(free & (same_iou >= MATCH_IOU)):
            taken.add(int(same[np.argmax(np.where(free, same_iou, -1.0))]))
            kinds.append(0)
        elif np.any(iou[own & crowd] >= MATCH_IOU):
            continue
        elif np.any(same_iou >= MATCH_IOU):
            kinds.append(1)
        elif np.any(same_iou >= NEAR_IOU):
            kinds.append(2)
        else:
            kinds.append(3 if np.any(iou[~own & ~crowd] >= NEAR_IOU) else 4)
    return np.asarray(kinds, dtype=np.int64), len(taken)
