"""Box processors over :mod:`paz6d.backend.boxes`: format conversion and conversion to
:class:`~paz6d.abstract.Box2D` messages (used by :class:`paz6d.faces.haar.HaarCascadeDetector`).

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


class ToBoxes2D(Processor):
    """``xyxy`` pixel boxes ``(N, 4)`` (+ optional scores, class ids) to a list of :class:`Box2D`.

    Args:
        class_names: names indexed by class id; without it ``class_name`` stays None.
        class_name: the name of every box called without class ids (a one-class detector).
    """

    def __init__(self, class_names: Sequence[str] | None = None, class_name: str | None = None,
                 name: str | None = None):
        super().__init__(name)
        self.class_names = None if class_names is None else list(class_names)
        self.class_name = class_name

    def call(self, boxes, scores=None, class_ids=None) -> list[Box2D]:
        boxes = boxes_backend.as_boxes(boxes).reshape(-1, 4)
        scores = np.ones(len(boxes)) if scores is None else np.asarray(scores, dtype=np.float64).reshape(-1)
        if len(scores) != len(boxes):
            raise ValueError(f"scores: expected {len(boxes)} scores matching boxes, got {len(scores)}")
        names: list[str | None] = [self.class_name] * len(boxes)
        if class_ids is not None:
            if self.class_names is None:
                raise ValueError("class_ids: given without class_names to look the names up in")
            names = [self.class_names[int(index)] for index in np.asarray(class_ids).reshape(-1)]
        return [Box2D(*box, score=score, class_name=class_name)
                for box, score, class_name in zip(boxes, scores, names)]
