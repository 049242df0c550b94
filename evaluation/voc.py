"""PASCAL VOC detection AP: 11-point (VOC2007) and all-point (VOC2010+) interpolation.

Protocol (VOC devkit ``VOCevaldet``): per class, detections are sorted by score, highest first,
with a *stable* sort (ties keep reading order: files in sorted name order, lines in file order).
Each detection takes the ground truth of the same image and class with the highest IoU (the first
one on ties). If that IoU is ``>= iou_threshold`` the detection is a true positive unless the
ground truth was already taken (false positive) or is ``difficult`` (ignored: neither TP nor FP);
otherwise it is a false positive. Recall is over non-difficult ground truth.

Area convention: by default boxes follow the VOC "+1 pixel" convention, where integer corners
are inclusive pixel indices, so ``area = (x2 - x1 + 1) * (y2 - y1 + 1)`` and the intersection
width is ``min(x2) - max(x1) + 1``. ``plus_one=False`` uses continuous coordinates
(``area = (x2 - x1) * (y2 - y1)``), the paz6d convention elsewhere. ``xywh`` input is converted
with ``x2 = x + w`` before either convention applies.

11-point AP samples recall at ``np.linspace(0, 1, 11)`` (so 0.6000000000000001, not 0.6) and
averages the highest precision at recall >= each sample. All-point AP integrates the monotone
precision envelope over recall.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from paz6d.backend.files import read_input_text
from paz6d.datasets.voc import read_annotation as read_xml_annotation

METHODS = ("11point", "allpoint")
BOX_FORMATS = ("xyxy", "xywh")
_DEVKIT_NAME = re.compile(r"^comp\d+_det_[^_]+_(?P<class_name>.+)\.txt$")


@dataclass(frozen=True)
class VocGroundTruth:
    """Ground-truth boxes of a set of images.

    Attributes:
        image_ids: sorted image ids (file stems).
        image_index: (N,) row of ``image_ids`` per object.
        class_names: N class names.
        boxes: (N, 4) ``(x_min, y_min, x_max, y_max)`` pixels.
        difficult: (N,) bool ``difficult`` flags.
    """

    image_ids: tuple[str, ...]
    image_index: np.ndarray
    class_names: tuple[str, ...]
    boxes: np.ndarray
    difficult: np.ndarray


@dataclass(frozen=True)
class VocDetections:
    """Detections in reading order (files sorted by name, lines in file order).

    Attributes:
        image_index: (D,) row of the ground truth ``image_ids`` per detection.
        class_names: D class names.
        boxes: (D, 4) ``(x_min, y_min, x_max, y_max)`` pixels.
        scores: (D,) confidences.
    """

    image_index: np.ndarray
    class_names: tuple[str, ...]
    boxes: np.ndarray
    scores: np.ndarray


@dataclass(frozen=True)
class VocClassResult:
    """AP of one class and the curve it comes from.

    Attributes:
        class_name: the class.
        average_precision: AP in [0, 1]; NaN when the class has only difficult ground truth.
        ground_truth_count: number of non-difficult ground-truth boxes.
        detection_count: number of detections of the class.
        true_positives, false_positives: totals over the detections.
        recall, precision: (D,) cumulative values in score order (ignored detections included).
    """

    class_name: str
    average_precision: float
    ground_truth_count: int
    detection_count: int
    true_positives: int
    false_positives: int
    recall: np.ndarray
    precision: np.ndarray


@dataclass(frozen=True)
class VocEvaluation:
    """Per-class results and their mean.

    Attributes:
        per_class: results keyed by class name (classes present in the ground truth, sorted).
        mean_average_precision: mean AP over classes with non-difficult ground truth.
        iou_threshold, method, plus_one: the settings used.
    """

    per_class: dict[str, VocClassResult]
    mean_average_precision: float
    iou_threshold: float
    method: str
    plus_one: bool


def _as_xyxy(values: list[float], box_format: str) -> list[float]:
    if box_format == "xywh":
        x, y, w, h = values
        return [x, y, x + w, y + h]
    return values


def _parse_numbers(tokens: list[str], where: str, expected: str) -> list[float]:
    try:
        values = [float(token) for token in tokens]
    except ValueError:
        raise ValueError(f"{where}: expected {expected}, found non-numeric values {tokens}") from None
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"{where}: expected finite numbers in {expected}, got {tokens}")
    return values


def _check_box(box: list[float], where: str) -> list[float]:
    if box[2] < box[0] or box[3] < box[1]:
        raise ValueError(f"{where}: box {box} has x_max < x_min or y_max < y_min (negative size)")
    return box


def _class_token(token: str, class_names: list[str] | None, where: str) -> str:
    if class_names is not None and re.fullmatch(r"\d+", token):
        index = int(token)
        if index >= len(class_names):
            raise ValueError(f"{where}: class id {index} is outside the class-name list ({len(class_names)} names)")
        return class_names[index]
    return token


def read_class_names(path: str | Path) -> list[str]:
    """Reads a class-name list (one name per line, e.g. ``voc.names``); line ``i`` names class id ``i``."""
    path = Path(path)
    names = [line.strip() for line in read_input_text(path, "class-name file").splitlines() if line.strip()]
    if not names:
        raise ValueError(f"{path}: expected one class name per line, found none")
    return names


def _read_lines(path: Path) -> list[tuple[int, list[str]]]:
    text = read_input_text(path, "text file")
    return [(number, line.split()) for number, line in enumerate(text.splitlines(), start=1) if line.strip()]


def read_annotations(directory: str | Path, box_format: str = "xyxy",
                     class_names: list[str] | None = None) -> VocGroundTruth:
    """Reads ground truth from a directory of VOC XML files or of text files (one per image).

    Text lines are ``<class> <a> <b> <c> <d>`` with the box in ``box_format`` (absolute pixels);
    XML files are read by :func:`paz6d.datasets.voc.read_annotation` with their raw ``xmin ymin xmax ymax``
    numbers (any class name). The image id is the file stem.

    Args:
        directory: folder with ``*.xml`` or ``*.txt`` files (not both).
        box_format: ``"xyxy"`` or ``"xywh"`` for text files.
        class_names: maps integer class tokens of text files to names (``None``: use tokens as is).

    Raises:
        ValueError: naming the file (and line) for malformed content.
    """
    directory = Path(directory)
    if box_format not in BOX_FORMATS:
        raise ValueError(f"box_format: expected one of {BOX_FORMATS}, got {box_format!r}")
    if not directory.is_dir():
        raise ValueError(f"{directory}: annotation directory not found")
    xml_files = sorted(directory.glob("*.xml"))
    txt_files = sorted(directory.glob("*.txt"))
    if xml_files and txt_files:
        raise ValueError(f"{directory}: contains both .xml and .txt annotations; expected one kind")
    if not xml_files and not txt_files:
        raise ValueError(f"{directory}: no .xml or .txt annotation files")
    image_ids, image_index, names, boxes, difficult = [], [], [], [], []
    for row, path in enumerate(xml_files or txt_files):
        image_ids.append(path.stem)
        if xml_files:
            parsed = read_xml_annotation(path, class_names=None, voc_coordinates=True)
            objects = list(zip(parsed["names"], parsed["boxes"].tolist(), parsed["difficult"].tolist()))
        else:
            objects = []
            for number, tokens in _read_lines(path):
                where = f"{path}:{number}"
                expected = f"'<class> <4 box numbers ({box_format})>'"
                if len(tokens) != 5:
                    raise ValueError(f"{where}: expected {expected}, got {len(tokens)} fields")
                box = _as_xyxy(_parse_numbers(tokens[1:], where, expected), box_format)
                objects.append((_class_token(tokens[0], class_names, where), _check_box(box, where), False))
        for name, box, hard in objects:
            image_index.append(row)
            names.append(name)
            boxes.append(box)
            difficult.append(hard)
    return VocGroundTruth(image_ids=tuple(image_ids), image_index=np.array(image_index, dtype=np.int64),
                          class_names=tuple(names), boxes=np.array(boxes, dtype=np.float64).reshape(-1, 4),
                          difficult=np.array(difficult, dtype=bool))


def read_detections(directory: str | Path, ground_truth: VocGroundTruth, box_format: str = "xyxy",
                    layout: str = "auto", class_names: list[str] | None = None) -> VocDetections:
    """Reads detections in either text layout.

    * ``"per_image"``: one ``<image_id>.txt`` per image, lines ``<class> <score> <4 box numbers>``.
    * ``"per_class"``: VOC devkit results, one ``comp<N>_det_<set>_<class>.txt`` per class, lines
      ``<image_id> <score> <4 box numbers>``.
    * ``"auto"``: ``per_class`` when every file is named like the devkit results, else ``per_image``.

    Args:
        directory: folder of ``*.txt`` files (read in sorted name order).
        ground_truth: the images the detections must refer to.
        box_format: ``"xyxy"`` or ``"xywh"`` (absolute pixels).
        layout: ``"auto"``, ``"per_image"`` or ``"per_class"``.
        class_names: maps integer class tokens to names (``None``: use tokens as is).

    Raises:
        ValueError: naming the file and line for malformed lines or unknown image ids.
    """
    directory = Path(directory)
    if box_format not in BOX_FORMATS:
        raise ValueError(f"box_format: expected one of {BOX_FORMATS}, got {box_format!r}")
    if layout not in ("auto", "per_image", "per_class"):
        raise ValueError(f"layout: expected 'auto', 'per_image' or 'per_class', got {layout!r}")
    if not directory.is_dir():
        raise ValueError(f"{directory}: detection directory not found")
    files = sorted(directory.glob("*.txt"))
    if layout == "auto":
        layout = "per_class" if files and all(_DEVKIT_NAME.match(f.name) for f in files) else "per_image"
    image_rows = {image_id: row for row, image_id in enumerate(ground_truth.image_ids)}
    image_index, names, boxes, scores = [], [], [], []
    for path in files:
        file_class = None
        if layout == "per_class":
            match = _DEVKIT_NAME.match(path.name)
            if match is None:
                raise ValueError(f"{path}: expected a devkit results name comp<N>_det_<set>_<class>.txt")
            file_class = match["class_name"]
        elif path.stem not in image_rows:
            raise ValueError(f"{path}: image '{path.stem}' has no ground-truth annotation file")
        for number, tokens in _read_lines(path):
            where = f"{path}:{number}"
            first = "<image_id>" if file_class else "<class>"
            expected = f"'{first} <score> <4 box numbers ({box_format})>'"
            if len(tokens) != 6:
                raise ValueError(f"{where}: expected {expected}, got {len(tokens)} fields")
            values = _parse_numbers(tokens[1:], where, expected)
            if file_class is None:
                image_row, name = image_rows[path.stem], _class_token(tokens[0], class_names, where)
            else:
                if tokens[0] not in image_rows:
                    raise ValueError(f"{where}: image '{tokens[0]}' has no ground-truth annotation")
                image_row, name = image_rows[tokens[0]], file_class
            image_index.append(image_row)
            names.append(name)
            scores.append(values[0])
            boxes.append(_check_box(_as_xyxy(values[1:], box_format), where))
    return VocDetections(image_index=np.array(image_index, dtype=np.int64), class_names=tuple(names),
                         boxes=np.array(boxes, dtype=np.float64).reshape(-1, 4),
                         scores=np.array(scores, dtype=np.float64))


def box_iou(first: np.ndarray, second: np.ndarray, plus_one: bool = True) -> np.ndarray:
    """IoU of paired ``(x_min, y_min, x_max, y_max)`` boxes, shape (P, 4) each -> (P,).

    Args:
        plus_one: VOC convention (inclusive integer corners, ``+1`` on widths and heights).
    """
    extra = 1.0 if plus_one else 0.0
    width = np.maximum(np.minimum(first[:, 2], second[:, 2]) - np.maximum(first[:, 0], second[:, 0]) + extra, 0.0)
    height = np.maximum(np.minimum(first[:, 3], second[:, 3]) - np.maximum(first[:, 1], second[:, 1]) + extra, 0.0)
    intersection = width * height
    area_first = (first[:, 2] - first[:, 0] + extra) * (first[:, 3] - first[:, 1] + extra)
    area_second = (second[:, 2] - second[:, 0] + extra) * (second[:, 3] - second[:, 1] + extra)
    union = area_first + area_second - intersection
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(union > 0, intersection / np.where(union > 0, union, 1.0), 0.0)


def average_precision(recall: np.ndarray, precision: np.ndarray, method: str = "allpoint") -> float:
    """AP from a precision/recall curve (both (D,), in score order).

    Args:
        method: ``"11point"`` (VOC2007: mean of the best precision at recall >= 0, 0.1, ..., 1,
            sampled at ``np.linspace(0, 1, 11)``) or ``"allpoint"`` (area under the monotone
            precision envelope).
    """
    if method not in METHODS:
        raise ValueError(f"method: expected one of {METHODS}, got {method!r}")
    recall = np.asarray(recall, dtype=np.float64)
    precision = np.asarray(precision, dtype=np.float64)
    if method == "11point":
        total = 0.0
        for level in np.linspace(0, 1, 11):
            reached = recall >= level
            total += float(np.max(precision[reached])) if np.any(reached) else 0.0
        return total / 11.0
    padded_recall = np.concatenate([[0.0], recall, [1.0]])
    envelope = np.concatenate([[0.0], precision, [0.0]])
    envelope = np.maximum.accumulate(envelope[::-1])[::-1]
    steps = np.flatnonzero(padded_recall[1:] != padded_recall[:-1])
    return float(np.sum((padded_recall[steps + 1] - padded_recall[steps]) * envelope[steps + 1]))


def _evaluate_class(name: str, ground_truth: VocGroundTruth, detections: VocDetections, iou_threshold: float,
                    method: str, plus_one: bool) -> VocClassResult:
    gt_rows = np.flatnonzero(np.array(ground_truth.class_names, dtype=object) == name)
    det_rows = np.flatnonzero(np.array(detections.class_names, dtype=object) == name)
    det_rows = det_rows[np.argsort(-detections.scores[det_rows], kind="stable")]
    n_det = len(det_rows)
    # best ground truth per detection (first on ties), among all boxes of its image and class
    gt_image = ground_truth.image_index[gt_rows]
    gt_order = np.argsort(gt_image, kind="stable")
    sorted_image = gt_image[gt_order]
    det_image = detections.image_index[det_rows]
    starts = np.searchsorted(sorted_image, det_image, side="left")
    counts = np.searchsorted(sorted_image, det_image, side="right") - starts
    pair_det = np.repeat(np.arange(n_det), counts)
    pair_gt = gt_rows[gt_order[np.repeat(starts - np.cumsum(counts) + counts, counts) + np.arange(counts.sum())]]
    overlap = box_iou(detections.boxes[det_rows[pair_det]], ground_truth.boxes[pair_gt], plus_one)
    best_iou = np.full(n_det, -np.inf)
    best_gt = np.full(n_det, -1)
    has_pairs = counts > 0
    if len(overlap):
        first_pair = np.cumsum(counts) - counts
        best_iou[has_pairs] = np.maximum.reduceat(overlap, first_pair[has_pairs])
        # first pair reaching the maximum of its detection
        at_best = overlap == best_iou[pair_det]
        candidate = np.where(at_best, np.arange(len(overlap)), len(overlap))
        best_gt[has_pairs] = pair_gt[np.minimum.reduceat(candidate, first_pair[has_pairs])]
    hit = best_iou >= iou_threshold
    hard = np.zeros(n_det, dtype=bool)
    hard[hit] = ground_truth.difficult[best_gt[hit]]
    claims = hit & ~hard
    # a ground truth is taken by the first (highest-scored) detection claiming it
    first_claim = np.zeros(n_det, dtype=bool)
    claimed = np.flatnonzero(claims)
    _, first = np.unique(best_gt[claimed], return_index=True)
    first_claim[claimed[first]] = True
    true_positive = first_claim
    false_positive = ~hit | (claims & ~first_claim)
    tp = np.cumsum(true_positive).astype(np.float64)
    fp = np.cumsum(false_positive).astype(np.float64)
    positives = int(np.count_nonzero(~ground_truth.difficult[gt_rows]))
    with np.errstate(divide="ignore", invalid="ignore"):
        recall = tp / positives if positives else np.full(n_det, np.nan)
    precision = tp / np.maximum(tp + fp, np.finfo(np.float64).eps)
    ap = average_precision(recall, precision, method) if positives else math.nan
    return VocClassResult(class_name=name, average_precision=ap, ground_truth_count=positives,
                          detection_count=n_det, true_positives=int(true_positive.sum()),
                          false_positives=int(false_positive.sum()), recall=recall, precision=precision)


def evaluate(ground_truth: VocGroundTruth, detections: VocDetections, iou_threshold: float = 0.5,
             method: str = "allpoint", plus_one: bool = True) -> VocEvaluation:
    """VOC AP for every class present in the ground truth.

    Args:
        ground_truth: boxes from :func:`read_annotations`.
        detections: boxes from :func:`read_detections` (classes absent from the ground truth are ignored).
        iou_threshold: minimum IoU for a true positive, in (0, 1].
        method: ``"11point"`` or ``"allpoint"``.
        plus_one: VOC "+1 pixel" area convention (see module docstring).
    """
    if method not in METHODS:
        raise ValueError(f"method: expected one of {METHODS}, got {method!r}")
    if not (0.0 < iou_threshold <= 1.0):
        raise ValueError(f"iou_threshold: expected a value in (0, 1], got {iou_threshold}")
    per_class = {name: _evaluate_class(name, ground_truth, detections, iou_threshold, method, plus_one)
                 for name in sorted(set(ground_truth.class_names))}
    values = [r.average_precision for r in per_class.values() if not math.isnan(r.average_precision)]
    mean = float(np.mean(values)) if values else math.nan
    return VocEvaluation(per_class=per_class, mean_average_precision=mean, iou_threshold=iou_threshold,
                         method=method, plus_one=plus_one)


def evaluate_directories(annotations: str | Path, detections: str | Path, iou_threshold: float = 0.5,
                         method: str = "allpoint", box_format: str = "xyxy", plus_one: bool = True,
                         class_names: list[str] | None = None, layout: str = "auto") -> VocEvaluation:
    """Reads annotations and detections from directories and evaluates them (see :func:`evaluate`)."""
    ground_truth = read_annotations(annotations, box_format, class_names)
    found = read_detections(detections, ground_truth, box_format, layout, class_names)
    return evaluate(ground_truth, found, iou_threshold, method, plus_one)
