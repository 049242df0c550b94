"""The one sample type and lazy sequence that every data set loader returns.

Each loader module (``paz6d.datasets.voc``, ``coco``, ``openimages``, ``fer2013``, ``ferplus``,
``ycb_video``, ``fat``) exposes ``load(root, split, ...) -> SampleSequence`` and its class-name list;
files are converted to the project's conventions (pixels, metres, OpenCV camera frame,
``T_model2cam``) at that one boundary, when a sample is read.

Every sample a :class:`SampleSequence` returns has been checked against its image's real size
(:func:`check_sample`): boxes are finite, not inverted, and not off the image (a box may reach past
the border, as truncated objects' boxes do, but by less than the image's own width or height); a
size the annotation claims (``extras["image_size"]``) must be the image file's. A bad sample raises
``ValueError`` naming its annotation (``Sample.source``: file and record), the box and the field.

Example:
    >>> samples = voc.load("VOCdevkit/VOC2007", "val")  # doctest: +SKIP
    >>> len(samples), samples[0].boxes.shape, samples.class_names[:2]  # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from paz6d.backend.image import MAX_IMAGE_SIDE, image_size_from_header


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
        source: the annotation the sample was read from (file and record), for messages.
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
    source: str = ""


def _real_size(sample: Sample, where: str) -> tuple[int, int] | None:
    """``(width, height)`` of the sample's image (inline array or file header); ``None`` when the file
    does not exist (whoever reads the pixels reports that)."""
    if isinstance(sample.image, np.ndarray):
        return int(sample.image.shape[1]), int(sample.image.shape[0])
    path = Path(sample.image)
    if not path.is_file():
        return None
    width, height = image_size_from_header(path)
    if not (0 < width <= MAX_IMAGE_SIDE and 0 < height <= MAX_IMAGE_SIDE):
        raise ValueError(f"{where}: image {path} claims {width} x {height} pixels in its header; expected sides "
                         f"of 1..{MAX_IMAGE_SIDE} px")
    return width, height


def check_sample(sample: Sample) -> Sample:
    """``sample`` when its annotation can describe its image (see the module doc); else ``ValueError``
    naming ``sample.source``, the box and the field.

    Args:
        sample: boxes ``(N, 4)`` ``x_min, y_min, x_max, y_max`` pixels; ``extras["image_size"]``
            ``(width, height)`` when the annotation states one.
    """
    where = sample.source or f"annotation of {sample.image if not isinstance(sample.image, np.ndarray) else 'an image'}"
    claimed = sample.extras.get("image_size")
    if claimed is not None:
        if (len(claimed) != 2 or not all(isinstance(v, (int, np.integer)) and 0 < v <= MAX_IMAGE_SIDE
                                         for v in claimed)):
            raise ValueError(f"{where}, field image size: expected a width and height of 1..{MAX_IMAGE_SIDE} px, "
                             f"got {tuple(claimed)!r:.60}")
        claimed = (int(claimed[0]), int(claimed[1]))
    real = _real_size(sample, where)
    if claimed is not None and real is not None and claimed != real:
        raise ValueError(f"{where}, field image size: the annotation says {claimed[0]} x {claimed[1]} px, but the "
                         f"image {sample.image} is {real[0]} x {real[1]} px")
    boxes = np.asarray(sample.boxes, dtype=np.float64)
    if boxes.ndim != 2 or boxes.shape[1] != 4:
        raise ValueError(f"{where}, field boxes: expected (N, 4) boxes, got shape {boxes.shape}")
    size = real or claimed
    for number, box in enumerate(boxes):
        problem = None
        if not np.all(np.isfinite(box)):
            problem = "not finite (NaN, infinite or overflowing)"
        elif box[2] < box[0] or box[3] < box[1]:
            problem = "inverted (x_max < x_min or y_max < y_min)"
        elif size is not None:
            width, height = size
            if box[2] < 0 or box[3] < 0 or box[0] > width or box[1] > height:
                problem = f"entirely outside the {width} x {height} px image"
            elif box[0] < -width or box[1] < -height or box[2] > 2 * width or box[3] > 2 * height:
                problem = f"further outside the {width} x {height} px image than the image's own size"
        if problem is not None:
            name = sample.class_names[number] if number < len(sample.class_names) else "?"
            raise ValueError(f"{where}, box {number} ({name}): {np.round(box, 3).tolist()!r:.120} is {problem}")
    return sample


class SampleSequence(Sequence):
    """A lazy, indexable, length-aware sequence: ``read(i)`` builds sample ``i`` only when asked.

    Args:
        count: number of samples.
        read: ``index -> Sample`` (each sample is checked by :func:`check_sample` on the way out).
        class_names: the data set's classes (``Sample.class_ids`` index into them).
    """

    def __init__(self, count: int, read: Callable[[int], Sample], class_names: Sequence[str]):
        self._count = int(count)
        self._read = lambda index: check_sample(read(index))
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
