"""COCO mask and box IoU, as pycocotools computes them (``maskApi.c`` in cocodataset/cocoapi).

The masks are :class:`~paz6d.backend.rle.MaskIntervals` (runs of flat column-major indices); decoding
segmentations, RLE strings and polygons lives in :mod:`paz6d.backend.rle`, shared with the COCO reader
:mod:`paz6d.datasets.coco`, and is re-exported here. IoU of a detection with a crowd region is
``intersection / area(detection)``.
"""

from __future__ import annotations

import numpy as np

from paz6d.backend.rle import (POLYGON_SCALE, MaskIntervals, concatenated_ranges, counts_from_intervals,
                               decode_counts_strings, decode_rle, encode_counts_string, encode_mask,
                               intervals_from_counts, intervals_from_mask, mask_from_intervals,
                               segmentations_to_intervals)

__all__ = ["POLYGON_SCALE", "MaskIntervals", "concatenated_ranges", "counts_from_intervals", "decode_counts_strings",
           "decode_rle", "encode_counts_string", "encode_mask", "intervals_from_counts", "intervals_from_mask",
           "mask_from_intervals", "segmentations_to_intervals", "pair_intersections", "iou_from_intersections",
           "box_overlap_areas", "box_iou_pairs", "box_iou", "mask_iou"]

# ----------------------------------------------------------------------------------------------
# IoU
# ----------------------------------------------------------------------------------------------

def pair_intersections(first: MaskIntervals, second: MaskIntervals, first_index: np.ndarray,
                       second_index: np.ndarray) -> np.ndarray:
    """(P,) int64 pixel counts of ``first[first_index[p]] & second[second_index[p]]``.

    Masks of a pair must have the same size; each pair is one merge walk over both run lists
    (:func:`paz6d.backend.rle_kernels.pair_intersections`).
    """
    from paz6d.backend import rle_kernels  # here: numba loads only when masks are compared

    return rle_kernels.pair_intersections(first.starts, first.ends, first.offsets, second.starts, second.ends,
                                          second.offsets, np.asarray(first_index, dtype=np.int64),
                                          np.asarray(second_index, dtype=np.int64))


def iou_from_intersections(intersection: np.ndarray, detection_area: np.ndarray, truth_area: np.ndarray,
                           truth_is_crowd: np.ndarray) -> np.ndarray:
    """IoU as pycocotools ``rleIou``: ``i / (a_d + a_g - i)``, or ``i / a_d`` against crowd regions."""
    intersection = np.asarray(intersection, dtype=np.float64)
    union = np.where(truth_is_crowd, detection_area, detection_area + truth_area - intersection)
    union = np.where(intersection == 0, 1.0, union)
    return intersection / union


def box_overlap_areas(first_boxes: np.ndarray, second_boxes: np.ndarray) -> np.ndarray:
    """(P,) intersection areas of paired ``[x, y, w, h]`` boxes (0 when disjoint)."""
    a, b = first_boxes, second_boxes
    width = np.minimum(a[:, 0] + a[:, 2], b[:, 0] + b[:, 2]) - np.maximum(a[:, 0], b[:, 0])
    height = np.minimum(a[:, 1] + a[:, 3], b[:, 1] + b[:, 3]) - np.maximum(a[:, 1], b[:, 1])
    return np.clip(width, 0, None) * np.clip(height, 0, None)


def box_iou_pairs(detection_boxes: np.ndarray, truth_boxes: np.ndarray, truth_is_crowd: np.ndarray) -> np.ndarray:
    """IoU of paired ``[x, y, w, h]`` boxes with pycocotools ``bbIou`` arithmetic.

    Args:
        detection_boxes: (P, 4) float64 ``[x, y, w, h]``.
        truth_boxes: (P, 4) float64 ``[x, y, w, h]``.
        truth_is_crowd: (P,) bool; crowd IoU is ``intersection / detection area``.
    """
    d, g = detection_boxes, truth_boxes
    width = np.minimum(d[:, 2] + d[:, 0], g[:, 2] + g[:, 0]) - np.maximum(d[:, 0], g[:, 0])
    height = np.minimum(d[:, 3] + d[:, 1], g[:, 3] + g[:, 1]) - np.maximum(d[:, 1], g[:, 1])
    overlap = (width > 0) & (height > 0)
    intersection = np.where(overlap, width * height, 0.0)
    detection_area = d[:, 2] * d[:, 3]
    union = np.where(truth_is_crowd, detection_area, detection_area + g[:, 2] * g[:, 3] - intersection)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(overlap, intersection / np.where(overlap, union, 1.0), 0.0)


def box_iou(detection_boxes, truth_boxes, truth_is_crowd=None) -> np.ndarray:
    """(D, G) IoU matrix of ``[x, y, w, h]`` boxes, equal to pycocotools ``maskUtils.iou`` on boxes.

    Args:
        detection_boxes: (D, 4) boxes ``[x, y, w, h]`` in pixels.
        truth_boxes: (G, 4) boxes ``[x, y, w, h]`` in pixels.
        truth_is_crowd: (G,) bool, default all False.
    """
    d = np.asarray(detection_boxes, dtype=np.float64).reshape(-1, 4)
    g = np.asarray(truth_boxes, dtype=np.float64).reshape(-1, 4)
    crowd = np.zeros(len(g), bool) if truth_is_crowd is None else np.asarray(truth_is_crowd, bool)
    if crowd.shape != (len(g),):
        raise ValueError(f"truth_is_crowd: expected shape ({len(g)},), got {crowd.shape}")
    di, gi = np.divmod(np.arange(len(d) * len(g)), len(g))
    return box_iou_pairs(d[di], g[gi], crowd[gi]).reshape(len(d), len(g))


def mask_iou(detections: MaskIntervals, truths: MaskIntervals, truth_is_crowd=None) -> np.ndarray:
    """(D, G) IoU matrix of masks, equal to pycocotools ``maskUtils.iou`` on RLEs of equal size.

    Raises:
        ValueError: if a detection and a ground-truth mask differ in size.
    """
    crowd = np.zeros(len(truths), bool) if truth_is_crowd is None else np.asarray(truth_is_crowd, bool)
    if crowd.shape != (len(truths),):
        raise ValueError(f"truth_is_crowd: expected shape ({len(truths)},), got {crowd.shape}")
    di, gi = np.divmod(np.arange(len(detections) * len(truths)), max(len(truths), 1))
    if np.any((detections.heights[di] != truths.heights[gi]) | (detections.widths[di] != truths.widths[gi])):
        raise ValueError("mask_iou: every detection mask must have the size of every ground-truth mask")
    intersection = pair_intersections(detections, truths, di, gi)
    iou = iou_from_intersections(intersection, detections.areas()[di], truths.areas()[gi], crowd[gi])
    return iou.reshape(len(detections), len(truths))
