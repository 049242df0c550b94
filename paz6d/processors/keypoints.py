"""Keypoint processors: pixel keypoints ``(N, 2)`` to :class:`~paz6d.abstract.Keypoints2D` messages."""

from __future__ import annotations

from paz6d.abstract.messages import Keypoints2D
from paz6d.abstract.processor import Processor


class ToKeypoints2D(Processor):
    """``(N, 2)`` pixel array (+ optional ``(N,)`` scores) to a :class:`Keypoints2D` message."""

    def __init__(self, class_name: str | None = None, name: str | None = None):
        super().__init__(name)
        self.class_name = class_name

    def call(self, keypoints, scores=None) -> Keypoints2D:
        return Keypoints2D(keypoints, scores, self.class_name)
