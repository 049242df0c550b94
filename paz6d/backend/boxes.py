"""Axis-aligned 2D boxes, vectorized over ``(N, 4)`` arrays (leading batch dims where noted).

Default format is ``xyxy`` = ``(x_min, y_min, x_max, y_max)`` in continuous pixel coordinates
(pixel ``i`` covers ``[i, i + 1)``, see ``docs/conventions.md``); ``xywh`` is
``(x_min, y_min, width, height)`` and ``cxcywh`` is ``(center_x, center_y, width, height)``.
"Normalized" boxes divide x by the image width and y by the image height.

SSD-style box regression: :func:`prior_boxes` builds anchors (``cxcywh``, normalized),
:func:`match` assigns ground truth to them, :func:`encode` / :func:`decode` convert between boxes
and regression offsets scaled by ``variances``.

Example:
    >>> import numpy as np
    >>> from paz6d.backend import boxes
    >>> boxes.iou_matrix([[0, 0, 2, 2]], [[1, 0, 3, 2]]).round(4)
    array([[0.3333]])
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from paz6d.backend.checks import as_array

FORMATS = ("xyxy", "xywh", "cxcywh")
SSD_VARIANCES = (0.1, 0.1, 0.2, 0.2)


def as_boxes(value, name: str = "boxes") -> np.ndarray:
    """Returns ``(..., 4)`` float64 boxes (finite), raising ``ValueError`` naming ``name`` otherwise."""
    return as_array(value, name, (4,))


#: Largest box side that crop steps accept, in multiples of the image's longer side: a crop
#: resizes the box's window to the model input, so a box far larger than the image (±1e9 px) would
#: only cost time (blur and resampling scale with it) and cannot hold the object's image.
MAX_BOX_TO_IMAGE = 4.0


def move_box(box, moves) -> np.ndarray:
    """Copies of an xyxy ``box`` ``(4,)`` (pixels) moved by ``moves`` ``(V, 3)`` rows of ``(dx, dy, scale)``: the
    centre shifted by ``dx`` × its width and ``dy`` × its height, the sides scaled by ``scale`` about it ->
    ``(V, 4)``."""
    x_min, y_min, x_max, y_max = np.asarray(box, dtype=np.float64)
    width, height = x_max - x_min, y_max - y_min
    dx, dy, scale = np.asarray(moves, dtype=np.float64).T
    centre_x = 0.5 * (x_min + x_max) + dx * width
    centre_y = 0.5 * (y_min + y_max) + dy * height
    half_width, half_height = 0.5 * width * scale, 0.5 * height * scale
    return np.stack([centre_x - half_width, centre_y - half_height, centre_x + half_width, centre_y + half_height],
                    axis=1)


def overlaps_image(box, width: int, height: int) -> bool:
    """Whether an xyxy ``box`` (pixels) reaches into the ``width x height`` image (pixel ``i`` covers ``[i, i+1)``)."""
    x_min, y_min, x_max, y_max = box
    return bool(x_max > 0 and y_max > 0 and x_min < width and y_min < height)


def check_box_in_image(box, width: int, height: int, name: str = "box") -> np.ndarray:
    """``box`` ``(4,)`` xyxy as float64 when it is finite, non-empty, overlaps the ``width x height``
    image and its sides are at most :data:`MAX_BOX_TO_IMAGE` times the image's longer side.

    Raises:
        ValueError: naming ``name``, the box and the image size.
    """
    coordinates = as_array(box, name, (4,))
    if coordinates.shape != (4,):
        raise ValueError(f"{name}: expected (x_min, y_min, x_max, y_max), got shape {coordinates.shape}")
    x_min, y_min, x_max, y_max = coordinates
    if not (x_max > x_min and y_max > y_min):
        raise ValueError(f"{name}: empty box {coordinates.tolist()}; expected x_max > x_min and y_max > y_min")
    if not overlaps_image(coordinates, width, height):
        raise ValueError(f"{name}: {coordinates.tolist()} lies outside the {width}x{height} image")
    limit = MAX_BOX_TO_IMAGE * max(width, height)
    if max(x_max - x_min, y_max - y_min) > limit:
        raise ValueError(f"{name}: {coordinates.tolist()} is larger than {MAX_BOX_TO_IMAGE:g} times the "
                         f"{width}x{height} image (sides up to {limit:g} px)")
    return coordinates


def _as_box_list(value, name: str) -> np.ndarray:
    boxes = as_boxes(value, name)
    if boxes.ndim != 2:
        raise ValueError(f"{name}: expected shape (N, 4), got {boxes.shape}")
    return boxes


def _as_image_size(image_size, name: str = "image_size") -> np.ndarray:
    size = np.asarray(image_size, dtype=np.float64)
    if size.shape != (2,) or not np.all(np.isfinite(size)) or np.any(size <= 0):
        raise ValueError(f"{name}: expected positive (width, height), got {image_size!r}")
    return size


def convert(boxes, source: str, target: str) -> np.ndarray:
    """Converts ``(..., 4)`` boxes between ``"xyxy"``, ``"xywh"`` and ``"cxcywh"``."""
    for argument, value in (("source", source), ("target", target)):
        if value not in FORMATS:
            raise ValueError(f"{argument}: expected one of {FORMATS}, got {value!r}")
    boxes = as_boxes(boxes)
    if source == "xywh":
        boxes = np.concatenate([boxes[..., :2], boxes[..., :2] + boxes[..., 2:]], axis=-1)
    elif source == "cxcywh":
        half = 0.5 * boxes[..., 2:]
        boxes = np.concatenate([boxes[..., :2] - half, boxes[..., :2] + half], axis=-1)
    if target == "xywh":
        return np.concatenate([boxes[..., :2], boxes[..., 2:] - boxes[..., :2]], axis=-1)
    if target == "cxcywh":
        return np.concatenate([0.5 * (boxes[..., :2] + boxes[..., 2:]), boxes[..., 2:] - boxes[..., :2]], axis=-1)
    return boxes.copy()


def normalize(boxes, image_size) -> np.ndarray:
    """Pixel boxes ``(..., 4)`` (``xyxy`` or ``xywh``/``cxcywh``) to fractions of ``image_size = (width, height)``."""
    width, height = _as_image_size(image_size)
    return as_boxes(boxes) / np.array([width, height, width, height])


def denormalize(boxes, image_size) -> np.ndarray:
    """Inverse of :func:`normalize`: fractions of ``(width, height)`` back to pixels."""
    width, height = _as_image_size(image_size)
    return as_boxes(boxes) * np.array([width, height, width, height])


def area(boxes) -> np.ndarray:
    """Areas ``(...)`` of ``xyxy`` boxes (zero for inverted boxes)."""
    boxes = as_boxes(boxes)
    return np.clip(boxes[..., 2] - boxes[..., 0], 0, None) * np.clip(boxes[..., 3] - boxes[..., 1], 0, None)


def clip(boxes, image_size) -> np.ndarray:
    """Clips ``xyxy`` boxes to ``[0, width] × [0, height]`` (use ``(1, 1)`` for normalized boxes)."""
    width, height = _as_image_size(image_size)
    return np.clip(as_boxes(boxes), 0.0, np.array([width, height, width, height]))


def flip_left_right(boxes, image_width: float) -> np.ndarray:
    """Mirrors ``xyxy`` boxes for an image flipped left-right (``x -> image_width - x``)."""
    boxes = as_boxes(boxes)
    flipped = boxes.copy()
    flipped[..., 0] = image_width - boxes[..., 2]
    flipped[..., 2] = image_width - boxes[..., 0]
    return flipped


def mirrored_prior_index(priors, decimals: int = 6) -> np.ndarray:
    """``(P,)`` indices ``m``: prior ``m[i]`` is the left-right mirror image of prior ``i`` (normalized ``cxcywh``
    ``(P, 4)``, ``cx -> 1 - cx``). Identical priors keep their order, so ``m`` pairs them in turn.

    Raises:
        ValueError: some prior has no mirror image among ``priors`` (compared to ``decimals`` places).
    """
    priors = as_array(priors, "priors", (4,))
    keys = np.round(priors, decimals)
    mirrored = keys.copy()
    mirrored[:, 0] = np.round(1.0 - priors[:, 0], decimals)
    order, mirrored_order = np.lexsort(keys.T[::-1]), np.lexsort(mirrored.T[::-1])
    if not np.array_equal(keys[order], mirrored[mirrored_order]):
        raise ValueError("priors: expected priors that are left-right symmetric (each with a mirror image), "
                         "as a test-time mirror image needs")
    index = np.empty(len(priors), dtype=np.int64)
    index[mirrored_order] = order
    return index


def _iou(boxes_a: np.ndarray, boxes_b: np.ndarray) -> np.ndarray:
    """IoU of already validated, broadcast-compatible ``xyxy`` arrays."""
    low = np.maximum(boxes_a[..., :2], boxes_b[..., :2])
    high = np.minimum(boxes_a[..., 2:], boxes_b[..., 2:])
    sides = np.clip(high - low, 0.0, None)
    intersection = sides[..., 0] * sides[..., 1]
    area_a = np.prod(np.clip(boxes_a[..., 2:] - boxes_a[..., :2], 0.0, None), axis=-1)
    area_b = np.prod(np.clip(boxes_b[..., 2:] - boxes_b[..., :2], 0.0, None), axis=-1)
    union = area_a + area_b - intersection
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(union > 0, intersection / np.where(union > 0, union, 1.0), 0.0)


def iou_matrix(boxes_a, boxes_b) -> np.ndarray:
    """Intersection over union ``(N, M)`` between ``xyxy`` boxes ``(N, 4)`` and ``(M, 4)``.

    Boxes of zero area have IoU 0 with everything.
    """
    boxes_a = _as_box_list(boxes_a, "boxes_a")
    boxes_b = _as_box_list(boxes_b, "boxes_b")
    return _iou(boxes_a[:, None, :], boxes_b[None, :, :])


def nms(boxes, scores, iou_threshold: float = 0.45, score_threshold: float = -np.inf,
        max_outputs: int | None = None) -> np.ndarray:
    """Greedy non-maximum suppression over ``xyxy`` boxes ``(N, 4)`` with ``scores`` ``(N,)``.

    A box is dropped when its IoU with an already kept, higher-scoring box exceeds
    ``iou_threshold``. Boxes scoring below ``score_threshold`` are discarded first; equal
    scores keep their input order.

    Returns:
        ``(K,)`` int64 indices into ``boxes`` of the kept boxes, by decreasing score.
    """
    boxes = _as_box_list(boxes, "boxes")
    scores = np.asarray(scores, dtype=np.float64)
    if scores.shape != (len(boxes),):
        raise ValueError(f"scores: expected shape ({len(boxes)},) matching boxes, got {scores.shape}")
    if not 0.0 <= iou_threshold <= 1.0:
        raise ValueError(f"iou_threshold: expected a value in [0, 1], got {iou_threshold}")
    candidates = np.flatnonzero(scores >= score_threshold)
    order = candidates[np.argsort(-scores[candidates], kind="stable")]
    limit = len(order) if max_outputs is None else int(max_outputs)
    kept: list[int] = []
    while len(order) and len(kept) < limit:
        best, order = order[0], order[1:]
        kept.append(int(best))
        order = order[_iou(boxes[best], boxes[order]) <= iou_threshold]
    return np.asarray(kept, dtype=np.int64)


def nms_per_class(boxes, scores, class_ids, iou_threshold: float = 0.45, score_threshold: float = -np.inf,
                  max_outputs: int | None = None) -> np.ndarray:
    """Non-maximum suppression run independently for each class (boxes of different classes
    never suppress each other).

    Implemented as one :func:`nms` call on boxes shifted apart by class so that boxes of
    different classes cannot overlap.

    Args:
        boxes: ``(N, 4)`` ``xyxy``.
        scores: ``(N,)``.
        class_ids: ``(N,)`` integer class of each box.
        max_outputs: maximum number of boxes kept over all classes.
    Returns:
        ``(K,)`` int64 indices of kept boxes by decreasing score.
    """
    boxes = _as_box_list(boxes, "boxes")
    class_ids = np.asarray(class_ids)
    if class_ids.shape != (len(boxes),) or not np.issubdtype(class_ids.dtype, np.integer):
        raise ValueError(f"class_ids: expected ({len(boxes)},) integers matching boxes, "
                         f"got shape {class_ids.shape} dtype {class_ids.dtype}")
    if len(boxes) == 0:
        return np.zeros(0, dtype=np.int64)
    _, dense_ids = np.unique(class_ids, return_inverse=True)
    span = float(np.max(boxes) - np.min(boxes)) + 1.0
    shifted = boxes + (dense_ids.astype(np.float64) * 2.0 * span)[:, None]
    return nms(shifted, scores, iou_threshold, score_threshold, max_outputs)


def vote_boxes(kept, boxes, scores, class_ids, iou_threshold: float = 0.5) -> np.ndarray:
    """Box voting (Gidaris & Komodakis 2015): each kept box ``(K, 4)`` replaced by the score-weighted mean of
    the candidate ``boxes`` ``(N, 4)`` of its class (``class_ids`` ``(N,)``, one per kept box given as
    ``kept`` ``(K,)`` indices into ``boxes``) whose IoU with it is at least ``iou_threshold``; the kept box
    itself always votes. Scores ``(N,)`` weigh the votes (a score of 0 counts as the smallest positive float).

    Returns:
        ``(K, 4)`` float64 ``xyxy`` boxes, in the order of ``kept``.
    """
    boxes = _as_box_list(boxes, "boxes")
    scores = np.asarray(scores, dtype=np.float64)
    class_ids, kept = np.asarray(class_ids), np.asarray(kept, dtype=np.int64).reshape(-1)
    if scores.shape != (len(boxes),) or class_ids.shape != (len(boxes),):
        raise ValueError(f"scores/class_ids: expected shape ({len(boxes)},) matching boxes, "
                         f"got {scores.shape} and {class_ids.shape}")
    if not 0.0 <= iou_threshold <= 1.0:
        raise ValueError(f"iou_threshold: expected a value in [0, 1], got {iou_threshold}")
    if len(kept) == 0:
        return np.zeros((0, 4))
    overlaps = _iou(boxes[kept][:, None, :], boxes[None, :, :])  # (K, N)
    voters = (overlaps >= iou_threshold) & (class_ids[kept][:, None] == class_ids[None, :])
    voters[np.arange(len(kept)), kept] = True
    weights = np.where(voters, np.maximum(scores, np.finfo(np.float64).tiny)[None, :], 0.0)
    return weights @ boxes / weights.sum(axis=1, keepdims=True)


def prior_boxes(image_size, feature_map_sizes: Sequence, steps: Sequence,
                min_sizes: Sequence[float], max_sizes: Sequence[float],
                aspect_ratios: Sequence[Sequence[float]], clip_to_image: bool = True) -> np.ndarray:
    """SSD prior (anchor) boxes, normalized ``cxcywh`` ``(P, 4)``.

    For each feature map ``k`` of ``rows × cols`` cells and each cell ``(i, j)`` (row-major), the cell
    centre is ``((j + 0.5) * step_x / width, (i + 0.5) * step_y / height)`` and the priors are, in
    order: a square of side ``min_size``, a square of side ``sqrt(min_size * max_size)``, then for each
    ratio ``r`` a ``min_size*sqrt(r) × min_size/sqrt(r)`` box and its transpose.

    Args:
        image_size: the network input in pixels: its side (square, e.g. 300) or ``(width, height)``.
        feature_map_sizes: per map, its side or ``(rows, cols)``.
        steps: per map, pixels between neighbouring cell centres, or ``(step_x, step_y)``.
        min_sizes, max_sizes, aspect_ratios: one entry per feature map; sizes in pixels.
        clip_to_image: clip the coordinates to ``[0, 1]``.
    """
    lengths = {len(feature_map_sizes), len(steps), len(min_sizes), len(max_sizes), len(aspect_ratios)}
    if len(lengths) != 1:
        raise ValueError("feature_map_sizes/steps/min_sizes/max_sizes/aspect_ratios: expected one entry per "
                         f"feature map, got lengths "
                         f"{[len(feature_map_sizes), len(steps), len(min_sizes), len(max_sizes), len(aspect_ratios)]}")
    width, height = _pair(image_size)
    if width <= 0 or height <= 0:
        raise ValueError(f"image_size: expected a positive size in pixels, got {image_size}")
    scale = np.array([width, height], dtype=np.float64)
    priors = []
    for size, step, min_size, max_size, ratios in zip(feature_map_sizes, steps, min_sizes, max_sizes, aspect_ratios):
        rows, cols = (int(v) for v in _pair(size))
        grid_rows, grid_cols = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
        centers = np.stack([grid_cols.ravel() + 0.5, grid_rows.ravel() + 0.5],
                           axis=-1) * np.asarray(_pair(step)) / scale
        shapes = [(min_size, min_size), (np.sqrt(min_size * max_size),) * 2]
        for ratio in ratios:
            root = np.sqrt(ratio)
            shapes += [(min_size * root, min_size / root), (min_size / root, min_size * root)]
        shapes = np.asarray(shapes, dtype=np.float64) / scale
        per_cell = np.concatenate([np.repeat(centers, len(shapes), axis=0),
                                   np.tile(shapes, (len(centers), 1))], axis=-1)
        priors.append(per_cell)
    priors = np.concatenate(priors, axis=0)
    return np.clip(priors, 0.0, 1.0) if clip_to_image else priors


def _pair(value) -> tuple[float, float]:
    """``value`` twice when it is a number, else its two entries."""
    values = np.ravel(np.asarray(value, dtype=np.float64))
    if values.size == 1:
        return float(values[0]), float(values[0])
    if values.size != 2:
        raise ValueError(f"expected a number or a pair of numbers, got {value!r}")
    return float(values[0]), float(values[1])


def match(boxes, priors, iou_threshold: float = 0.5) -> np.ndarray:
    """Assigns ground-truth boxes to priors (SSD matching).

    Each prior takes the ground truth it overlaps most if that IoU is at least
    ``iou_threshold``; in addition every ground-truth box claims its best prior, so each object
    is matched at least once.

    Args:
        boxes: ``(M, 4)`` ground truth ``xyxy`` (same units as the priors).
        priors: ``(P, 4)`` ``cxcywh``.
    Returns:
        ``(P,)`` int64 index of the matched ground truth, ``-1`` for background.
    """
    boxes = _as_box_list(boxes, "boxes")
    priors = _as_box_list(priors, "priors")
    matched = np.full(len(priors), -1, dtype=np.int64)
    if len(boxes) == 0:
        return matched
    overlaps = iou_matrix(boxes, convert(priors, "cxcywh", "xyxy"))
    best_box = np.argmax(overlaps, axis=0)
    positive = overlaps[best_box, np.arange(len(priors))] >= iou_threshold
    matched[positive] = best_box[positive]
    matched[np.argmax(overlaps, axis=1)] = np.arange(len(boxes))
    return matched


def encode(boxes, priors, variances: Sequence[float] = SSD_VARIANCES) -> np.ndarray:
    """SSD regression targets ``(..., 4)`` of ``xyxy`` ``boxes`` relative to ``cxcywh`` ``priors``.

    ``(dcx, dcy) = (c - c_prior) / (size_prior * variances[:2])`` and
    ``(dw, dh) = log(size / size_prior) / variances[2:]``.
    """
    boxes = convert(boxes, "xyxy", "cxcywh")
    priors = as_boxes(priors, "priors")
    variances = _as_variances(variances)
    if np.any(boxes[..., 2:] <= 0):
        raise ValueError("boxes: expected positive width and height to encode")
    if np.any(priors[..., 2:] <= 0):
        raise ValueError("priors: expected positive width and height")
    centers = (boxes[..., :2] - priors[..., :2]) / (priors[..., 2:] * variances[:2])
    sizes = np.log(boxes[..., 2:] / priors[..., 2:]) / variances[2:]
    return np.concatenate([centers, sizes], axis=-1)


def decode(offsets, priors, variances: Sequence[float] = SSD_VARIANCES) -> np.ndarray:
    """Inverse of :func:`encode`: regression ``offsets`` ``(..., 4)`` to ``xyxy`` boxes."""
    offsets = as_boxes(offsets, "offsets")
    priors = as_boxes(priors, "priors")
    variances = _as_variances(variances)
    centers = priors[..., :2] + offsets[..., :2] * variances[:2] * priors[..., 2:]
    sizes = priors[..., 2:] * np.exp(offsets[..., 2:] * variances[2:])
    return convert(np.concatenate([centers, sizes], axis=-1), "cxcywh", "xyxy")


def _as_variances(variances) -> np.ndarray:
    values = np.asarray(variances, dtype=np.float64)
    if values.shape != (4,) or np.any(~np.isfinite(values)) or np.any(values <= 0):
        raise ValueError(f"variances: expected 4 positive numbers, got {variances!r}")
    return values
