"""COCO detection evaluation (``bbox`` and ``segm``), numerically identical to pycocotools ``COCOeval``.

The protocol is the one of ``COCOeval.evaluate/accumulate/summarize`` with default parameters:

* every image and category of the ground truth is evaluated; detections are sorted by score
  (stable, file order breaks ties) and only the best 100 per image and category are kept;
* a ground truth is *ignored* when it is a crowd region or its ``area`` is outside the area range;
  detections are matched greedily, each to the still-free ground truth of highest IoU (ties go to
  the later one, non-ignored ground truths first, crowd regions can absorb any number of
  detections); unmatched detections outside the area range are ignored;
* precision is made monotone and sampled at 101 recall thresholds; categories without
  non-ignored ground truth get ``-1`` and are left out of the means.

Detection areas follow ``COCO.loadRes``: ``w * h`` of ``bbox`` when the first result carries a
box, else the mask area. Boxes are ``[x, y, w, h]`` in pixels. Differences from pycocotools: a
ground-truth annotation with ``id == 0`` counts as matched (pycocotools treats id 0 as "no
match"), an empty result list evaluates to zeros instead of raising, and detections whose mask
size differs from the image raise ``ValueError`` instead of getting IoU ``-1``.
"""

from __future__ import annotations

import contextlib
import gc
import itertools
import math
import operator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import orjson

from evaluation import coco_masks
from paz6d.backend import rle
from paz6d.backend.files import load_json, read_input_bytes

STAT_NAMES = ("AP", "AP50", "AP75", "AP_small", "AP_medium", "AP_large",
              "AR1", "AR10", "AR100", "AR_small", "AR_medium", "AR_large")
IOU_THRESHOLDS = np.linspace(0.5, 0.95, int(np.round((0.95 - 0.5) / 0.05)) + 1, endpoint=True)
RECALL_THRESHOLDS = np.linspace(0.0, 1.0, int(np.round(1.0 / 0.01)) + 1, endpoint=True)
AREA_RANGE_NAMES = ("all", "small", "medium", "large")
AREA_RANGES = np.array([[0.0, 1e5 ** 2], [0.0, 32.0 ** 2], [32.0 ** 2, 96.0 ** 2], [96.0 ** 2, 1e5 ** 2]])
MAX_DETECTIONS = (1, 10, 100)
IOU_TYPES = ("bbox", "segm")


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _is_integer(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_box(value) -> bool:
    return isinstance(value, list) and len(value) == 4 and all(_is_number(v) for v in value)


def _parse_json(path: Path):
    """The file's JSON, parsed by ``orjson`` (half the time of the standard parser on a large COCO
    file); a file orjson refuses (malformed, a byte-order mark, NaN, integers beyond 64 bits) is read
    again by :func:`paz6d.backend.files.load_json`, which takes what the standard parser takes and
    names any problem."""
    try:
        return orjson.loads(read_input_bytes(path))
    except orjson.JSONDecodeError:
        return load_json(path)


def _read_json(path: str | Path, expected: type, what: str):
    path = Path(path)
    try:
        data = _parse_json(path)
    except ValueError as error:  # missing, a folder, not UTF-8, malformed, nested too deeply, huge numbers
        raise ValueError(f"{error}; expected {what}") from None
    if not isinstance(data, expected):
        raise ValueError(f"{path}: expected {what}, found a JSON {type(data).__name__}")
    return data


@dataclass(frozen=True)
class CocoGroundTruth:
    """COCO ground truth (``instances_*.json``) as arrays.

    Attributes:
        source: file name or label used in error messages.
        image_ids: (I,) sorted unique image ids.
        image_heights, image_widths: (I,) image size in pixels (0 when absent from the file).
        category_ids: (K,) sorted category ids.
        category_names: K names, in ``category_ids`` order.
        annotation_ids: (N,) annotation ids (annotations of unknown images/categories are dropped).
        image_index: (N,) row of ``image_ids`` of each annotation.
        category_index: (N,) row of ``category_ids`` of each annotation.
        boxes: (N, 4) ``[x, y, w, h]`` pixels, NaN where an annotation has no ``bbox``.
        areas: (N,) the ``area`` field (pixels^2), used for the area ranges.
        is_crowd: (N,) bool ``iscrowd`` flags.
        segmentations: N raw ``segmentation`` values (``None`` where absent).
    """

    source: str
    image_ids: np.ndarray
    image_heights: np.ndarray
    image_widths: np.ndarray
    category_ids: np.ndarray
    category_names: tuple[str, ...]
    annotation_ids: np.ndarray
    image_index: np.ndarray
    category_index: np.ndarray
    boxes: np.ndarray
    areas: np.ndarray
    is_crowd: np.ndarray
    segmentations: list = field(repr=False)

    @classmethod
    def from_file(cls, path: str | Path) -> CocoGroundTruth:
        """Reads a COCO ground-truth JSON file.

        Raises:
            ValueError: naming the file and the entry for malformed content.
        """
        data = _read_json(path, dict, "a COCO ground-truth object with 'images', 'annotations', 'categories'")
        return cls.from_dict(data, str(path))

    @classmethod
    def from_dict(cls, data: dict, source: str = "ground truth") -> CocoGroundTruth:
        """Builds the ground truth from an already parsed COCO dictionary."""
        for key in ("images", "annotations", "categories"):
            if not isinstance(data.get(key), list):
                raise ValueError(f"{source}: expected a list under '{key}'")
        images = data["images"]
        image_rows = {}
        for i, image in enumerate(images):
            if not isinstance(image, dict) or not _is_integer(image.get("id")):
                raise ValueError(f"{source}: images[{i}] must be an object with an integer 'id'")
            for key in ("height", "width"):
                if key in image and not (_is_integer(image[key]) and image[key] > 0):
                    raise ValueError(f"{source}: images[{i}].{key} must be a positive integer")
            image_rows[image["id"]] = image
        _check_unique([image["id"] for image in images], "images[].id", source)
        image_ids = np.array(sorted(image_rows), dtype=np.int64)
        heights = np.array([image_rows[i].get("height", 0) for i in image_ids.tolist()], dtype=np.int64)
        widths = np.array([image_rows[i].get("width", 0) for i in image_ids.tolist()], dtype=np.int64)
        names = {}
        for i, category in enumerate(data["categories"]):
            if not isinstance(category, dict) or not _is_integer(category.get("id")):
                raise ValueError(f"{source}: categories[{i}] must be an object with an integer 'id'")
            names[category["id"]] = str(category.get("name", category["id"]))
        _check_unique([category["id"] for category in data["categories"]], "categories[].id", source)
        _check_unique([str(category.get("name", category["id"])) for category in data["categories"]],
                      "categories[].name", source)
        category_ids = np.array(sorted(names), dtype=np.int64)
        columns = _annotation_columns(data["annotations"], source)
        bad = _bad_box_rows(columns["bbox"])
        if len(bad):
            raise ValueError(f"{source}: annotations[{int(bad[0])}].bbox must be [x, y, w, h] with w, h >= 0 and a "
                             f"finite x + w, y + h, got {data['annotations'][int(bad[0])]['bbox']!r:.80}")
        image_row = np.minimum(np.searchsorted(image_ids, columns["image_id"]), max(len(image_ids) - 1, 0))
        category_row = np.minimum(np.searchsorted(category_ids, columns["category_id"]),
                                  max(len(category_ids) - 1, 0))
        known = np.zeros(len(image_row), dtype=bool)
        if len(image_ids) and len(category_ids):  # COCOeval only looks at listed images and categories
            known = ((image_ids[image_row] == columns["image_id"])
                     & (category_ids[category_row] == columns["category_id"]))
        keep = np.flatnonzero(known)
        segmentations = list(map(dict.get, data["annotations"], itertools.repeat("segmentation")))
        return cls(source=source, image_ids=image_ids, image_heights=heights, image_widths=widths,
                   category_ids=category_ids, category_names=tuple(names[c] for c in category_ids.tolist()),
                   annotation_ids=columns["id"][keep], image_index=image_row[keep], category_index=category_row[keep],
                   boxes=columns["bbox"][keep], areas=columns["area"][keep], is_crowd=columns["iscrowd"][keep],
                   segmentations=[segmentations[i] for i in keep.tolist()])


def _integers(values: list) -> np.ndarray | None:
    if bool in set(map(type, values)):  # np.array([1, True]) would quietly be [1, 1]
        return None
    array = np.array(values) if values else np.zeros(0, dtype=np.int64)
    return array.astype(np.int64) if array.dtype.kind == "i" else None


def _bad_box_rows(boxes: np.ndarray) -> np.ndarray:
    """Rows of ``(N, 4)`` ``[x, y, w, h]`` boxes with a negative size or an overflowing corner
    (``x + w`` infinite); rows of NaN (no box) are not reported."""
    with np.errstate(over="ignore", invalid="ignore"):
        present = ~np.isnan(boxes).any(axis=1)
        bad = (boxes[:, 2] < 0) | (boxes[:, 3] < 0) | ~np.isfinite(boxes[:, :2] + boxes[:, 2:]).all(axis=1)
    return np.flatnonzero(present & bad)


def _check_unique(values: list, what: str, source: str) -> None:
    """``ValueError`` naming the first value of ``values`` (``what``: ``"categories[].id"``) seen twice."""
    seen: dict = {}
    for index, value in enumerate(values):
        if value in seen:
            raise ValueError(f"{source}: {what.replace('[]', f'[{index}]')} {value!r:.60} is also that of "
                             f"{what.split('[')[0]}[{seen[value]}]; expected unique values")
        seen[value] = index


def _finite_numbers(values: list, shape: tuple[int, ...]) -> np.ndarray | None:
    try:
        array = np.array(values) if values else np.zeros(shape, dtype=np.float64)
    except ValueError:  # ragged nested lists
        return None
    if array.dtype.kind not in "iuf" or array.shape != shape or not np.all(np.isfinite(array)):
        return None
    return array.astype(np.float64)


def _field(entries: list, key: str) -> list:
    """``[entry[key] for entry in entries]`` (KeyError/TypeError as that would raise), at C speed."""
    return list(map(operator.itemgetter(key), entries))


def _annotation_error(index: int, annotation, source: str) -> str | None:
    """Message for the first problem of one ground-truth annotation, ``None`` if it is valid."""
    where = f"{source}: annotations[{index}]"
    if not isinstance(annotation, dict):
        return f"{where} must be an object"
    for key in ("id", "image_id", "category_id"):
        if not _is_integer(annotation.get(key)):
            return f"{where}.{key} must be an integer"
    if not _is_number(annotation.get("area")):
        return f"{where}.area must be a finite number (pixels^2)"
    if "bbox" in annotation and not _is_box(annotation["bbox"]):
        return f"{where}.bbox must be [x, y, w, h] (4 finite numbers)"
    if annotation.get("iscrowd", 0) not in (0, 1):
        return f"{where}.iscrowd must be 0 or 1"
    return None


def _annotation_columns(annotations: list, source: str) -> dict[str, np.ndarray]:
    """Vectorized read of the annotation fields; on any problem, finds and reports the first bad entry."""
    n = len(annotations)
    columns: dict[str, np.ndarray | None] = {}
    try:
        for key in ("id", "image_id", "category_id"):
            columns[key] = _integers(_field(annotations, key))
        columns["area"] = _finite_numbers(_field(annotations, "area"), (n,))
        crowd = list(map(dict.get, annotations, itertools.repeat("iscrowd"), itertools.repeat(0)))
        boxes = list(map(dict.get, annotations, itertools.repeat("bbox")))
        crowd_valid = set(crowd) <= {0, 1}
    except (KeyError, TypeError, AttributeError):
        columns["id"] = None
    else:
        columns["iscrowd"] = np.array(crowd, dtype=bool) if crowd_valid else None
        present = range(n) if None not in boxes else [i for i, b in enumerate(boxes) if b is not None]
        box_array = np.full((n, 4), np.nan)
        found = _finite_numbers([boxes[i] for i in present], (len(present), 4))
        if found is not None:
            box_array[present] = found
        columns["bbox"] = box_array if found is not None else None
    if any(v is None for v in columns.values()) or len(columns) < 6:
        for i, annotation in enumerate(annotations):
            message = _annotation_error(i, annotation, source)
            if message:
                raise ValueError(message)
        raise ValueError(f"{source}: malformed 'annotations' (expected objects with integer id/image_id/"
                         "category_id, numeric area, optional bbox [x, y, w, h] and iscrowd 0/1)")
    return columns  # type: ignore[return-value]


@dataclass(frozen=True)
class CocoDetections:
    """COCO results (``[{"image_id", "category_id", "score", "bbox" | "segmentation"}, ...]``) as arrays.

    Attributes:
        source: file name or label used in error messages.
        image_index: (D,) row of the ground-truth ``image_ids``.
        category_ids: (D,) category ids as given (unknown categories are skipped at evaluation).
        scores: (D,) confidences.
        boxes: (D, 4) ``[x, y, w, h]`` pixels, or ``None`` when the results carry no boxes.
        segmentations: D raw segmentations, or ``None`` when the results carry no masks.
    """

    source: str
    image_index: np.ndarray
    category_ids: np.ndarray
    scores: np.ndarray
    boxes: np.ndarray | None
    segmentations: list | None = field(repr=False)

    @classmethod
    def from_file(cls, path: str | Path, ground_truth: CocoGroundTruth) -> CocoDetections:
        """Reads a COCO results JSON file (a list of detections) for ``ground_truth``."""
        data = _read_json(path, list, "a COCO results list [{image_id, category_id, score, bbox|segmentation}]")
        return cls.from_list(data, ground_truth, str(path))

    @classmethod
    def from_list(cls, results: list, ground_truth: CocoGroundTruth, source: str = "results") -> CocoDetections:
        """Builds detections from an already parsed results list.

        Raises:
            ValueError: naming ``source`` and the entry for malformed entries or unknown image ids.
        """
        if not isinstance(results, list):
            raise ValueError(f"{source}: expected a list of detections")
        if not results:
            empty = np.zeros(0, dtype=np.int64)
            return cls(source=source, image_index=empty, category_ids=empty, scores=np.zeros(0),
                       boxes=np.zeros((0, 4)), segmentations=[])
        first = results[0] if isinstance(results[0], dict) else {}
        has_boxes, has_masks = "bbox" in first, "segmentation" in first
        n = len(results)
        try:
            image_id = _integers(_field(results, "image_id"))
            category_ids = _integers(_field(results, "category_id"))
            scores = _finite_numbers(_field(results, "score"), (n,))
            boxes = _finite_numbers(_field(results, "bbox"), (n, 4)) if has_boxes else np.zeros((n, 4))
            segmentations = _field(results, "segmentation") if has_masks else None
        except (KeyError, TypeError, AttributeError):
            image_id = None
        if image_id is None or category_ids is None or scores is None or boxes is None or not (has_boxes or has_masks):
            for i, result in enumerate(results):
                message = _result_error(i, result, source, has_boxes, has_masks)
                if message:
                    raise ValueError(message)
            raise ValueError(f"{source}: malformed results (expected objects with integer image_id/category_id, "
                             "numeric score and bbox [x, y, w, h] or segmentation)")
        bad = _bad_box_rows(boxes) if has_boxes else []
        if len(bad):
            raise ValueError(f"{source}: entry [{int(bad[0])}].bbox must be [x, y, w, h] with w, h >= 0 and a finite "
                             f"x + w, y + h, got {results[int(bad[0])]['bbox']!r:.80}")
        image_ids = ground_truth.image_ids
        row = np.minimum(np.searchsorted(image_ids, image_id), max(len(image_ids) - 1, 0))
        unknown = np.flatnonzero(image_ids[row] != image_id) if len(image_ids) else np.arange(n)
        if len(unknown):
            i = int(unknown[0])
            raise ValueError(f"{source}: entry [{i}] has image_id {int(image_id[i])}, which is not an image of the "
                             f"ground truth {ground_truth.source}")
        return cls(source=source, image_index=row.astype(np.int64), category_ids=category_ids,
                   scores=scores, boxes=boxes if has_boxes else None, segmentations=segmentations)


def _result_error(index: int, result, source: str, has_boxes: bool, has_masks: bool) -> str | None:
    """Message for the first problem of one detection, ``None`` if it is valid."""
    where = f"{source}: entry [{index}]"
    if not isinstance(result, dict):
        return f"{where} must be an object"
    if not _is_integer(result.get("image_id")) or not _is_integer(result.get("category_id")):
        return f"{where} needs integer 'image_id' and 'category_id'"
    if not _is_number(result.get("score")):
        return f"{where}.score must be a finite number"
    if not has_boxes and not has_masks:
        return f"{where} needs a 'bbox' [x, y, w, h] or a 'segmentation'"
    if has_boxes and not _is_box(result.get("bbox")):
        return f"{where}.bbox must be [x, y, w, h] (4 finite numbers), as in the first entry"
    if has_masks and "segmentation" not in result:
        return f"{where} has no 'segmentation' (the first entry has one)"
    return None


@dataclass(frozen=True)
class CocoEvaluation:
    """Accumulated COCO results (the ``COCOeval.eval`` arrays and ``stats``).

    Attributes:
        iou_type: ``"bbox"`` or ``"segm"``.
        stats: (12,) summary in pycocotools order, see ``STAT_NAMES``; -1 where undefined.
        precision: (T=10, R=101, K, A=4, M=3) interpolated precision, -1 for categories without
            non-ignored ground truth.
        recall: (T, K, A, M) final recall, -1 likewise.
        category_ids: (K,) category ids.
        category_names: K category names.
    """

    iou_type: str
    stats: np.ndarray
    precision: np.ndarray
    recall: np.ndarray
    category_ids: np.ndarray
    category_names: tuple[str, ...]

    def stats_dict(self) -> dict[str, float]:
        """``{name: value}`` for the 12 summary numbers."""
        return {name: float(value) for name, value in zip(STAT_NAMES, self.stats)}

    def per_category_ap(self) -> dict[str, float | None]:
        """AP@[.50:.95] (area all, 100 detections) per category name; ``None`` without ground truth.

        Duplicate names get their category id appended.
        """
        result = {}
        counts: dict[str, int] = {}
        for name in self.category_names:
            counts[name] = counts.get(name, 0) + 1
        for k, (category_id, name) in enumerate(zip(self.category_ids.tolist(), self.category_names)):
            values = self.precision[:, :, k, 0, -1]
            values = values[values > -1]
            key = name if counts[name] == 1 else f"{name} ({category_id})"
            result[key] = float(np.mean(values)) if values.size else None
        return result

    def precision_curve(self, iou_threshold: float | None = None, category: int | None = None) -> np.ndarray:
        """(R,) precision at ``RECALL_THRESHOLDS`` (area all, 100 detections).

        Args:
            iou_threshold: one of ``IOU_THRESHOLDS``; ``None`` averages over all of them.
            category: row of ``category_ids``; ``None`` averages over categories with ground truth.

        Returns:
            Precision per recall threshold; NaN where no category has ground truth.
        """
        values = self.precision[..., 0, -1]  # (T, R, K)
        if iou_threshold is not None:
            rows = np.flatnonzero(np.isclose(IOU_THRESHOLDS, iou_threshold))
            if len(rows) != 1:
                raise ValueError(f"iou_threshold: expected one of {IOU_THRESHOLDS.round(2).tolist()}, "
                                 f"got {iou_threshold}")
            values = values[rows]
        if category is not None:
            values = values[:, :, [category]]
        valid = values > -1
        total = np.where(valid, values, 0.0).sum(axis=(0, 2))
        count = valid.sum(axis=(0, 2))
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(count > 0, total / np.maximum(count, 1), np.nan)


def _group_ranges(sorted_keys: np.ndarray, queries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start index and length of each query key's run in ``sorted_keys``."""
    starts = np.searchsorted(sorted_keys, queries, side="left")
    return starts, np.searchsorted(sorted_keys, queries, side="right") - starts


def _match(iou: np.ndarray, pair_det: np.ndarray, pair_gt: np.ndarray, det_rank: np.ndarray,
           gt_ignored: np.ndarray, gt_crowd: np.ndarray, n_det: int) -> tuple[np.ndarray, np.ndarray]:
    """Greedy COCOeval matching for all thresholds and area ranges at once.

    Detections of the same rank (position in their image/category's score order) never compete
    for the same ground truth, so they are processed together; the loop runs over ranks only.

    Args:
        iou: (P,) IoU of candidate pairs, ``pair_det``/``pair_gt`` their detection/gt rows; pairs
            are grouped by detection and, inside a detection, ordered like the ground truth file.
        det_rank: (D,) rank of each detection within its image and category.
        gt_ignored: (A, G) ignore flag per area range.
        gt_crowd: (G,) crowd flags.
        n_det: D.

    Returns:
        matched (T, A, D) and ignored-by-match (T, A, D) boolean arrays.
    """
    thresholds = np.minimum(IOU_THRESHOLDS, 1 - 1e-10)
    n_thresholds, n_areas = len(thresholds), gt_ignored.shape[0]
    matched = np.zeros((n_thresholds, n_areas, n_det), dtype=bool)
    ignored = np.zeros((n_thresholds, n_areas, n_det), dtype=bool)
    keep = iou >= thresholds.min()
    iou, pair_det, pair_gt = iou[keep], pair_det[keep], pair_gt[keep]
    order = np.argsort(det_rank[pair_det], kind="stable")
    iou, pair_det, pair_gt = iou[order], pair_det[order], pair_gt[order]
    taken = np.zeros((n_thresholds, n_areas, gt_ignored.shape[1]), dtype=bool)
    ranks = det_rank[pair_det]
    block_edges = np.flatnonzero(np.diff(ranks)) + 1
    for block in np.split(np.arange(len(iou)), block_edges):
        if len(block) == 0:
            continue
        dets, gts, values = pair_det[block], pair_gt[block], iou[block]
        first = np.flatnonzero(np.concatenate([[True], dets[1:] != dets[:-1]]))
        lengths = np.diff(np.append(first, len(block)))
        acceptable = (~taken[:, :, gts] | gt_crowd[gts]) & (values >= thresholds[:, None, None])
        gt_ignore = gt_ignored[:, gts]
        chosen = np.full((n_thresholds, n_areas, len(first)), -1)
        for candidates in (acceptable & ~gt_ignore, acceptable & gt_ignore):
            scored = np.where(candidates, values, -1.0)
            best = np.maximum.reduceat(scored, first, axis=2)
            at_best = candidates & (scored == np.repeat(best, lengths, axis=2))
            last = np.maximum.reduceat(np.where(at_best, np.arange(len(block)), -1), first, axis=2)
            chosen = np.where(chosen >= 0, chosen, last)
        t_index, a_index, segment = np.nonzero(chosen >= 0)
        pair = chosen[t_index, a_index, segment]
        taken[t_index, a_index, gts[pair]] = True
        matched[t_index, a_index, dets[pair]] = True
        ignored[t_index, a_index, dets[pair]] = gt_ignore[a_index, pair]
    return matched, ignored


def _segment_reverse_cummax(values: np.ndarray, first: np.ndarray, last: np.ndarray) -> np.ndarray:
    """Running maximum from the right inside each column segment ``first[s]..last[s]`` of every row.

    Args:
        values: (rows, N) floats.
        first, last: (S,) inclusive column bounds of the segments.
    """
    result = values.copy()
    for start, stop in zip(first.tolist(), (last + 1).tolist()):
        result[:, start:stop] = np.maximum.accumulate(values[:, start:stop][:, ::-1], axis=1)[:, ::-1]
    return result


def _recall_thresholds_reached(recall: np.ndarray) -> np.ndarray:
    """Number of ``RECALL_THRESHOLDS`` at or below each recall (``searchsorted(..., side="right")``).

    The thresholds are ``k * 0.01``, so ``floor(100 * r)`` is right to within one; the two
    comparisons around it settle the count exactly, without a binary search per value.
    """
    last = len(RECALL_THRESHOLDS) - 1
    guess = np.clip((recall * last).astype(np.int64), 0, last)
    reached = guess + (RECALL_THRESHOLDS[guess] <= recall)
    reached += (guess < last) & (RECALL_THRESHOLDS[np.minimum(guess + 1, last)] <= recall)
    reached -= (guess > 0) & (RECALL_THRESHOLDS[np.maximum(guess - 1, 0)] > recall)
    return reached


def _accumulate(det_category: np.ndarray, det_score: np.ndarray, det_image: np.ndarray, det_rank: np.ndarray,
                matched: np.ndarray, ignored: np.ndarray, positives: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """COCOeval.accumulate for all thresholds, categories, area ranges and max-detection limits.

    The detections of every (max-detection limit, category) pair form one segment of columns,
    ordered like COCOeval (score, then image, then rank in the image); every area range is one row,
    and one IoU threshold is done at a time (small temporaries). Cumulative TP/FP counts restart
    at each segment.

    Args:
        det_category, det_score, det_image, det_rank: (D,) per detection.
        matched, ignored: (T, A, D) from matching (ignored includes area-range ignores).
        positives: (K, A) number of non-ignored ground truths.

    Returns:
        precision (T, R, K, A, M) and recall (T, K, A, M).
    """
    n_thresholds, n_areas, _ = matched.shape
    n_categories, n_limits = positives.shape[0], len(MAX_DETECTIONS)
    n_recall = len(RECALL_THRESHOLDS)
    precision = np.zeros((n_thresholds, n_recall, n_categories, n_areas, n_limits))
    recall = np.zeros((n_thresholds, n_areas, n_limits * n_categories))
    order = np.lexsort((det_rank, det_image, -det_score, det_category))
    columns = np.concatenate([order[det_rank[order] < limit] for limit in MAX_DETECTIONS])
    limit_of_column = np.repeat(np.arange(n_limits), [np.count_nonzero(det_rank < limit) for limit in MAX_DETECTIONS])
    segment_of_column = limit_of_column * n_categories + det_category[columns]
    if len(columns):
        segments, first = np.unique(segment_of_column, return_index=True)
        segment = np.searchsorted(segments, segment_of_column)  # dense segment number per column
        last = np.append(first[1:], len(columns)) - 1
        n_positive = positives[det_category[columns]].T  # (A, N)
        zero = np.zeros((n_areas, 1), dtype=np.int64)
        limit, category = np.divmod(segments[segment], n_categories)
        base = (category * (n_areas * n_limits) + limit)[None, :] + (np.arange(n_areas) * n_limits)[:, None]
        for t in range(n_thresholds):
            counted = ~ignored[t][:, columns]
            tp = np.cumsum(matched[t][:, columns] & counted, axis=1)
            fp = np.cumsum(counted, axis=1) - tp
            tp = (tp - np.concatenate([zero, tp], axis=1)[:, first][:, segment]).astype(np.float64)
            fp = (fp - np.concatenate([zero, fp], axis=1)[:, first][:, segment]).astype(np.float64)
            with np.errstate(divide="ignore", invalid="ignore"):
                rc = tp / n_positive
            pr = _segment_reverse_cummax(tp / (fp + tp + np.spacing(1)), first, last)
            recall[t][:, segments] = rc[:, last]
            # recall threshold r takes the precision at the first column whose recall reaches it:
            # column i serves thresholds reached[i - 1] .. reached[i] - 1 of its segment
            reached = _recall_thresholds_reached(np.where(np.isfinite(rc), rc, 0.0))
            before = np.concatenate([zero, reached[:, :-1]], axis=1)
            before[:, first] = 0
            served = (reached - before).ravel()
            recall_index = rle.concatenated_ranges(before.ravel(), served)
            target = np.repeat(base.ravel(), served) + recall_index * (n_categories * n_areas * n_limits)
            precision[t].reshape(-1)[target] = np.repeat(pr.ravel(), served)
    recall = recall.reshape(n_thresholds, n_areas, n_limits, n_categories).transpose(0, 3, 1, 2).copy()
    undefined = positives == 0  # (K, A)
    precision[:, :, undefined, :] = -1
    recall[:, undefined, :] = -1
    return precision, recall


def _summarize(precision: np.ndarray, recall: np.ndarray) -> np.ndarray:
    """The 12 ``COCOeval.summarize`` numbers (means over entries > -1, -1 if none)."""

    def mean(ap: bool, iou: float | None = None, area: str = "all", max_det: int = 100) -> float:
        a = AREA_RANGE_NAMES.index(area)
        m = MAX_DETECTIONS.index(max_det)
        values = precision[:, :, :, a, m] if ap else recall[:, :, a, m]
        if iou is not None:
            values = values[np.where(iou == IOU_THRESHOLDS)[0]]
        values = values[values > -1]
        return float(np.mean(values)) if values.size else -1.0

    last = MAX_DETECTIONS[2]
    return np.array([
        mean(True), mean(True, 0.5, max_det=last), mean(True, 0.75, max_det=last),
        mean(True, area="small", max_det=last), mean(True, area="medium", max_det=last),
        mean(True, area="large", max_det=last),
        mean(False, max_det=MAX_DETECTIONS[0]), mean(False, max_det=MAX_DETECTIONS[1]),
        mean(False, max_det=last), mean(False, area="small", max_det=last),
        mean(False, area="medium", max_det=last), mean(False, area="large", max_det=last)])


def _outside_area_ranges(areas: np.ndarray) -> np.ndarray:
    """(A, N) bool: area outside each ``AREA_RANGES`` row (bounds inclusive, as COCOeval)."""
    return (areas[None, :] < AREA_RANGES[:, :1]) | (areas[None, :] > AREA_RANGES[:, 1:])


def _detection_masks(detections: CocoDetections, rows: np.ndarray, ground_truth: CocoGroundTruth):
    if detections.segmentations is None:
        raise ValueError(f"{detections.source}: segm evaluation needs a 'segmentation' in every detection")
    images = detections.image_index[rows]
    return rle.segmentations_to_intervals(
        [detections.segmentations[i] for i in rows.tolist()], ground_truth.image_heights[images].tolist(),
        ground_truth.image_widths[images].tolist(), f"{detections.source}: segmentation of kept detection")


def _truth_masks(ground_truth: CocoGroundTruth, rows: np.ndarray):
    images = ground_truth.image_index[rows]
    if np.any(ground_truth.image_heights[images] == 0):
        raise ValueError(f"{ground_truth.source}: segm evaluation needs 'height' and 'width' for every image")
    missing = [int(ground_truth.annotation_ids[r]) for r in rows.tolist() if ground_truth.segmentations[r] is None]
    if missing:
        raise ValueError(f"{ground_truth.source}: annotation id {missing[0]} has no 'segmentation'")
    return rle.segmentations_to_intervals(
        [ground_truth.segmentations[r] for r in rows.tolist()], ground_truth.image_heights[images].tolist(),
        ground_truth.image_widths[images].tolist(), f"{ground_truth.source}: annotation segmentation")


def evaluate(ground_truth: CocoGroundTruth, detections: CocoDetections, iou_type: str = "bbox") -> CocoEvaluation:
    """Runs COCO evaluation (``COCOeval`` evaluate + accumulate + summarize, default parameters).

    Args:
        ground_truth: parsed ground truth.
        detections: parsed results for that ground truth.
        iou_type: ``"bbox"`` (box IoU) or ``"segm"`` (mask IoU; polygons, RLE and crowd RLE).

    Returns:
        The accumulated arrays and the 12 summary numbers.

    Raises:
        ValueError: unknown ``iou_type`` or inputs lacking what it needs.
    """
    if iou_type not in IOU_TYPES:
        raise ValueError(f"iou_type: expected one of {IOU_TYPES}, got {iou_type!r}")
    n_categories = len(ground_truth.category_ids)
    # detections of known categories, grouped by (image, category), best score first, top 100
    category_index = np.searchsorted(ground_truth.category_ids, detections.category_ids)
    category_index = np.minimum(category_index, max(n_categories - 1, 0))
    known = (ground_truth.category_ids[category_index] == detections.category_ids) if n_categories else \
        np.zeros(len(detections.scores), bool)
    rows = np.flatnonzero(known)
    det_key = detections.image_index[rows] * n_categories + category_index[rows]
    order = np.lexsort((-detections.scores[rows], det_key))
    rows, det_key = rows[order], det_key[order]
    group_first = np.searchsorted(det_key, det_key, side="left")
    rank = np.arange(len(rows)) - group_first
    kept = rank < MAX_DETECTIONS[-1]
    rows, det_key, rank = rows[kept], det_key[kept], rank[kept]
    # ground truth grouped the same way, file order inside a group
    gt_key = ground_truth.image_index * n_categories + ground_truth.category_index
    gt_order = np.argsort(gt_key, kind="stable")
    gt_key_sorted = gt_key[gt_order]
    starts, counts = _group_ranges(gt_key_sorted, det_key)
    pair_det = np.repeat(np.arange(len(rows)), counts)
    pair_gt = rle.concatenated_ranges(starts, counts)  # rows of gt_order
    gt_rows = gt_order[pair_gt]
    crowd = ground_truth.is_crowd[gt_order]
    if iou_type == "bbox":
        if detections.boxes is not None:
            det_boxes = detections.boxes[rows]
        else:
            det_boxes = _detection_masks(detections, rows, ground_truth).boxes()
        gt_boxes = ground_truth.boxes[gt_rows]
        if np.isnan(gt_boxes).any():
            bad = int(ground_truth.annotation_ids[gt_rows[np.isnan(gt_boxes).any(axis=1)][0]])
            raise ValueError(f"{ground_truth.source}: annotation id {bad} has no 'bbox'")
        iou = coco_masks.box_iou_pairs(det_boxes[pair_det], gt_boxes, crowd[pair_gt])
        det_masks = None
    else:
        det_masks = _detection_masks(detections, rows, ground_truth)
        needed, pair_mask = np.unique(pair_gt, return_inverse=True)
        gt_masks = _truth_masks(ground_truth, gt_order[needed])
        det_mask_area, gt_mask_area = det_masks.areas(), gt_masks.areas()
        # IoU <= |box_d & box_g| / area_d (also for crowd); pairs below the lowest threshold never match
        overlap = coco_masks.box_overlap_areas(det_masks.boxes()[pair_det], gt_masks.boxes()[pair_mask])
        candidate = overlap >= IOU_THRESHOLDS.min() * det_mask_area[pair_det]
        candidate &= det_mask_area[pair_det] > 0
        pair_det, pair_gt, pair_mask = pair_det[candidate], pair_gt[candidate], pair_mask[candidate]
        intersection = coco_masks.pair_intersections(det_masks, gt_masks, pair_det, pair_mask)
        iou = coco_masks.iou_from_intersections(intersection, det_mask_area[pair_det], gt_mask_area[pair_mask],
                                                crowd[pair_gt])
    if detections.boxes is not None:
        det_area = detections.boxes[rows, 2] * detections.boxes[rows, 3]
    else:
        det_area = (det_masks if det_masks is not None else _detection_masks(detections, rows, ground_truth)
                    ).areas().astype(np.float64)
    gt_area = ground_truth.areas[gt_order]
    gt_ignored = crowd[None, :] | _outside_area_ranges(gt_area)  # (A, G)
    matched, ignored = _match(iou, pair_det, pair_gt, rank, gt_ignored, crowd, len(rows))
    ignored |= ~matched & _outside_area_ranges(det_area)[None, :, :]
    gt_category = ground_truth.category_index[gt_order]
    positives = np.stack([np.bincount(gt_category[~gt_ignored[a]], minlength=n_categories)
                          for a in range(len(AREA_RANGES))], axis=1)
    precision, recall = _accumulate(category_index[rows], detections.scores[rows], detections.image_index[rows],
                                    rank, matched, ignored, positives)
    return CocoEvaluation(iou_type=iou_type, stats=_summarize(precision, recall), precision=precision,
                          recall=recall, category_ids=ground_truth.category_ids,
                          category_names=ground_truth.category_names)


@contextlib.contextmanager
def _cyclic_collector_paused():
    """Pauses Python's cyclic garbage collector: a large COCO file parses into millions of acyclic
    objects (freed by reference counting alone), and the collector's passes over them cost about
    as much as the parsing itself (25 MB of ground truth: 0.55 s with it, 0.28 s without)."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


def read_files(ground_truth_path: str | Path, results_path: str | Path) -> tuple[CocoGroundTruth, CocoDetections]:
    """A COCO ground-truth file and a results file for it, parsed with the cyclic collector paused."""
    with _cyclic_collector_paused():
        ground_truth = CocoGroundTruth.from_file(ground_truth_path)
        return ground_truth, CocoDetections.from_file(results_path, ground_truth)


def evaluate_files(ground_truth_path: str | Path, results_path: str | Path, iou_type: str = "bbox") -> CocoEvaluation:
    """Loads a COCO ground-truth file and a results file and evaluates them (see :func:`evaluate`)."""
    with _cyclic_collector_paused():
        ground_truth, detections = read_files(ground_truth_path, results_path)
        evaluation = evaluate(ground_truth, detections, iou_type)
        del ground_truth, detections  # freed before the collector resumes, so it does not walk them once more
    return evaluation
