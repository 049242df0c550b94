"""Box processors over :mod:`paz6d.backend.boxes`: formats, normalization, clipping, NMS,
SSD encoding/decoding and conversion to :class:`~paz6d.abstract.Box2D` messages.

Box arrays are ``(N, 4)`` ``xyxy`` unless a processor names another format.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from paz6d.abstract.messages import Box2D
from paz6d.abstract.processor import Processor
from paz6d.backend import boxes as boxes_backend


class ConvertBoxFormat(Processor):
    """Converts ``(..., 4)`` boxes from ``source`` to ``target`` (``xyxy``, ``xywh``, ``cxcywh``)."""

    def __init__(self, source: str, target: str, name: str | None = None):
        super().__init__(name)
        self.source, self.target = source, target

    def call(self, boxes) -> np.ndarray:
        return boxes_backend.convert(boxes, self.source, self.target)


class NormalizeBoxes(Processor):
    """Pixels to fractions of ``image_size = (width, height)``."""

    def __init__(self, image_size: tuple[float, float], name: str | None = None):
        super().__init__(name)
        self.image_size = tuple(image_size)

    def call(self, boxes) -> np.ndarray:
        return boxes_backend.normalize(boxes, self.image_size)


class DenormalizeBoxes(Processor):
    """Fractions of ``image_size = (width, height)`` to pixels."""

    def __init__(self, image_size: tuple[float, float], name: str | None = None):
        super().__init__(name)
        self.image_size = tuple(image_size)

    def call(self, boxes) -> np.ndarray:
        return boxes_backend.denormalize(boxes, self.image_size)


class ClipBoxes(Processor):
    """Clips ``xyxy`` boxes to ``[0, width] × [0, height]``."""

    def __init__(self, image_size: tuple[float, float], name: str | None = None):
        super().__init__(name)
        self.image_size = tuple(image_size)

    def call(self, boxes) -> np.ndarray:
        return boxes_backend.clip(boxes, self.image_size)


class NonMaximumSuppression(Processor):
    """Per-class NMS; called as ``(boxes (N, 4), scores (N,), class_ids (N,))``.

    Returns ``(boxes[kept], scores[kept], class_ids[kept])`` by decreasing score.
    """

    def __init__(self, iou_threshold: float = 0.45, score_threshold: float = 0.01, max_outputs: int | None = 200,
                 name: str | None = None):
        super().__init__(name)
        self.iou_threshold, self.score_threshold, self.max_outputs = iou_threshold, score_threshold, max_outputs

    def call(self, boxes, scores, class_ids) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        kept = boxes_backend.nms_per_class(boxes, scores, class_ids, self.iou_threshold, self.score_threshold,
                                           self.max_outputs)
        return np.asarray(boxes, dtype=np.float64)[kept], np.asarray(scores)[kept], np.asarray(class_ids)[kept]


class EncodeBoxes(Processor):
    """SSD training targets: matches ground truth to ``priors`` and encodes it.

    Called as ``(boxes (M, 4) normalized xyxy, class_ids (M,))``; returns ``(P, 5)``: the four
    regression offsets and the class id (0 = background, so object classes are ``class_id + 1``).
    """

    def __init__(self, priors, iou_threshold: float = 0.5, variances: Sequence[float] = boxes_backend.SSD_VARIANCES,
                 name: str | None = None):
        super().__init__(name)
        self.priors = boxes_backend.as_boxes(priors, "priors")
        self.iou_threshold, self.variances = iou_threshold, tuple(variances)

    def call(self, boxes, class_ids) -> np.ndarray:
        boxes = boxes_backend.as_boxes(boxes).reshape(-1, 4)
        class_ids = np.asarray(class_ids, dtype=np.int64).reshape(-1)
        if len(class_ids) != len(boxes):
            raise ValueError(f"class_ids: expected {len(boxes)} ids matching boxes, got {len(class_ids)}")
        matched = boxes_backend.match(boxes, self.priors, self.iou_threshold)
        targets = np.zeros((len(self.priors), 5))
        positive = matched >= 0
        targets[positive, :4] = boxes_backend.encode(boxes[matched[positive]], self.priors[positive], self.variances)
        targets[positive, 4] = class_ids[matched[positive]] + 1
        return targets


class DecodeBoxes(Processor):
    """Regression offsets ``(P, 4)`` against ``priors`` to ``xyxy`` boxes ``(P, 4)``."""

    def __init__(self, priors, variances: Sequence[float] = boxes_backend.SSD_VARIANCES, name: str | None = None):
        super().__init__(name)
        self.priors = boxes_backend.as_boxes(priors, "priors")
        self.variances = tuple(variances)

    def call(self, offsets) -> np.ndarray:
        return boxes_backend.decode(offsets, self.priors, self.variances)


class ToBoxes2D(Processor):
    """``xyxy`` pixel boxes ``(N, 4)`` (+ optional scores, class ids) to a list of :class:`Box2D`.

    Args:
        class_names: names indexed by class id; without it ``class_name`` stays None.
    """

    def __init__(self, class_names: Sequence[str] | None = None, name: str | None = None):
        super().__init__(name)
        self.class_names = None if class_names is None else list(class_names)

    def call(self, boxes, scores=None, class_ids=None) -> list[Box2D]:
        boxes = boxes_backend.as_boxes(boxes).reshape(-1, 4)
        scores = np.ones(len(boxes)) if scores is None else np.asarray(scores, dtype=np.float64).reshape(-1)
        if len(scores) != len(boxes):
            raise ValueError(f"scores: expected {len(boxes)} scores matching boxes, got {len(scores)}")
        names: list[str | None] = [None] * len(boxes)
        if class_ids is not None:
            if self.class_names is None:
                raise ValueError("class_ids: given without class_names to look the names up in")
            names = [self.class_names[int(index)] for index in np.asarray(class_ids).reshape(-1)]
        return [Box2D(*box, score=score, class_name=class_name)
                for box, score, class_name in zip(boxes, scores, names)]
