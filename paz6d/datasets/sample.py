"""The one sample type and lazy sequence that every data set loader returns.

Each loader module (``paz6d.datasets.voc``, ``coco``, ``openimages``, ``fer2013``, ``ferplus``,
``ycb_video``, ``fat``) exposes ``load(root, split, ...) -> SampleSequence`` and its class-name list;
files are converted to the project's conventions (pixels, metres, OpenCV camera frame,
``T_model2cam``) at that one boundary, when a sample is read.

Example:
    >>> samples = voc.load("VOCdevkit/VOC2007", "val")  # doctest: +SKIP
    >>> len(samples), samples[0].boxes.shape, samples.class_names[:2]  # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass
class Sample:
    """One annotated image.

    Attributes:
        image: path of the image file, or the image itself (``(H, W)`` grey or ``(H, W, 3)`` RGB uint8)
            for formats that store pixels inline (FER-2013).
        boxes: ``(N, 4) float64`` ``x_min, y_min, x_max, y_max`` in pixels (the :class:`Box2D` order);
            ``(0, 4)`` when the format has no boxes.
        class_ids: ``(N,) int64`` indices into the data set's ``class_names``.
        class_names: ``N`` names, one per box (or one per image for classification formats).
        masks: ``(N, H, W) bool`` instance masks, or ``None``.
        keypoints: ``(N, K, 2)`` pixel keypoints (or ``(N, K, 3)`` with visibility), or ``None``.
        poses: ``(N, 4, 4) float64`` ``T_model2cam`` in metres, or ``None``.
        camera_matrix: ``(3, 3)`` intrinsics in pixels, or ``None``.
        extras: format-specific fields per box or per image (``difficult``, ``truncated``,
            ``iscrowd``, ``image_id``, vote counts, ...).
    """

    image: str | Path | np.ndarray
    boxes: np.ndarray
    class_ids: np.ndarray
    class_names: list[str]
    masks: np.ndarray | None = None
    keypoints: np.ndarray | None = None
    poses: np.ndarray | None = None
    camera_matrix: np.ndarray | None = None
    extras: dict = field(default_factory=dict)


class SampleSequence(Sequence):
    """A lazy, indexable, length-aware sequence: ``read(i)`` builds sample ``i`` only when asked.

    Args:
        count: number of samples.
        read: ``index -> Sample``.
        class_names: the data set's classes (``Sample.class_ids`` index into them).
    """

    def __init__(self, count: int, read: Callable[[int], Sample], class_names: Sequence[str]):
        self._count = int(count)
        self._read = read
        self.class_names = list(class_names)

    def __len__(self) -> int:
        return self._count

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(self._count))]
        if not isinstance(index, (int, np.integer)):
            raise TypeError(f"sample index: expected an integer or a slice, got {type(index).__name__}")
        if not -self._count <= index < self._count:
            raise IndexError(f"sample index {index} outside 0..{self._count - 1}")
        return self._read(int(index) % self._count)

    def __iter__(self) -> Iterator[Sample]:
        return (self._read(i) for i in range(self._count))
