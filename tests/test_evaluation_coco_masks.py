"""COCO mask primitives (RLE strings, polygon rasterization, IoU) against pycocotools.mask."""

from __future__ import annotations

import numpy as np
import pytest

from evaluation import coco_masks

mask_utils = pytest.importorskip("pycocotools.mask")


def random_mask(rng: np.random.Generator, height: int, width: int) -> np.ndarray:
    mask = np.zeros((height, width), dtype=bool)
    y0, x0 = rng.integers(0, height), rng.integers(0, width)
    y1, x1 = rng.integers(y0, height + 1), rng.integers(x0, width + 1)
    mask[y0:y1, x0:x1] = rng.random((y1 - y0, x1 - x0)) < rng.uniform(0.3, 1.0)
    return mask


def reference_rle(mask: np.ndarray) -> dict:
    rle = mask_utils.encode(np.asfortranarray(mask.astype(np.uint8)))
    return {"size": rle["size"], "counts": rle["counts"].decode("ascii")}


def test_encode_and_decode_match_pycocotools():
    rng = np.random.default_rng(0)
    for _ in range(150):
        height, width = (int(v) for v in rng.integers(1, 40, 2))
        mask = random_mask(rng, height, width) if rng.random() < 0.8 else rng.random((height, width)) < 0.5
        expected = reference_rle(mask)
        assert coco_masks.encode_mask(mask) == expected
        np.testing.assert_array_equal(coco_masks.decode_rle(expected), mask)


def test_uncompressed_and_compressed_rle_give_the_same_mask():
    rng = np.random.default_rng(1)
    mask = random_mask(rng, 23, 31)
    counts = coco_masks.decode_counts_strings([reference_rle(mask)["counts"]])[0]
    uncompressed = {"size": [23, 31], "counts": counts.tolist()}
    np.testing.assert_array_equal(coco_masks.decode_rle(uncompressed), mask)
    expected = mask_utils.frPyObjects(uncompressed, 23, 31)["counts"].decode("ascii")
    assert coco_masks.encode_counts_string(counts) == expected


def random_polygon_parts(rng: np.random.Generator, height: int, width: int) -> list[list[float]]:
    parts = []
    for _ in range(rng.integers(1, 4)):
        count = int(rng.integers(3, 25))
        points = rng.uniform(-15, max(height, width) + 15, (count, 2))
        style = rng.random()
        if style < 0.3:
            points = np.round(points * 10) / 10
        elif style < 0.5:  # values where 5 * v + 0.5 sits exactly on an integer
            points = np.round(points * 5) / 5 + rng.choice([0.0, 0.1, -0.1])
        elif style < 0.6:
            points = np.round(points)
        if rng.random() < 0.15:
            points[1] = points[0]  # repeated vertex: zero-length edge
        parts.append(points.ravel().tolist())
    return parts


def test_polygon_rasterization_matches_pycocotools_pixel_for_pixel():
    rng = np.random.default_rng(2)
    for _ in range(400):
        height, width = (int(v) for v in rng.integers(1, 120, 2))
        parts = random_polygon_parts(rng, height, width)
        expected = mask_utils.merge(mask_utils.frPyObjects(parts, height, width))
        masks = coco_masks.segmentations_to_intervals([parts], [height], [width])
        np.testing.assert_array_equal(coco_masks.mask_from_intervals(masks, 0), mask_utils.decode(expected) > 0)
        assert masks.areas()[0] == mask_utils.area(expected)
        np.testing.assert_array_equal(masks.boxes()[0], mask_utils.toBbox(expected))


def test_long_and_steep_polygon_edges_match_pycocotools_in_one_batch():
    """Edges far longer than a pixel (the kernel jumps between column centres instead of walking
    every grid step), steep and shallow, partly outside the image, many masks in one call."""
    rng = np.random.default_rng(12)
    entries, sizes = [], []
    for _ in range(150):
        height, width = (int(v) for v in rng.integers(1, 700, 2))
        parts = []
        for _ in range(rng.integers(1, 4)):
            points = rng.uniform(-0.2, 1.2, (int(rng.integers(3, 9)), 2)) * [width, height]
            if rng.random() < 0.3:
                points[:, 0] = points[0, 0] + (points[:, 0] - points[0, 0]) * 0.02  # nearly vertical edges
            if rng.random() < 0.3:
                points = np.round(points * 5) / 5 + rng.choice([0.0, 0.1, -0.1])  # on the 5x grid
            parts.append(points.ravel().tolist())
        entries.append(parts)
        sizes.append((height, width))
    masks = coco_masks.segmentations_to_intervals(entries, [h for h, _ in sizes], [w for _, w in sizes])
    for index, (parts, (height, width)) in enumerate(zip(entries, sizes)):
        expected = mask_utils.merge(mask_utils.frPyObjects(parts, height, width))
        np.testing.assert_array_equal(coco_masks.mask_from_intervals(masks, index), mask_utils.decode(expected) > 0)
        assert masks.areas()[index] == mask_utils.area(expected)
        np.testing.assert_array_equal(masks.boxes()[index], mask_utils.toBbox(expected))


def test_mixed_segmentation_kinds_keep_entry_order():
    rng = np.random.default_rng(13)
    entries, singles = [], []
    for _ in range(60):
        kind = rng.integers(0, 3)
        mask = random_mask(rng, 21, 17)
        if kind == 0:
            entry = reference_rle(mask)
        elif kind == 1:
            entry = {"size": [21, 17], "counts": coco_masks.decode_counts_strings([reference_rle(mask)["counts"]])[0]
                     .tolist()}
        else:
            entry = random_polygon_parts(rng, 21, 17)
        entries.append(entry)
        singles.append(coco_masks.mask_from_intervals(coco_masks.segmentations_to_intervals([entry], [21], [17]), 0))
    masks = coco_masks.segmentations_to_intervals(entries, [21] * 60, [17] * 60)
    for index, expected in enumerate(singles):
        np.testing.assert_array_equal(coco_masks.mask_from_intervals(masks, index), expected)


def test_four_number_polygons_are_boxes_like_pycocotools():
    rng = np.random.default_rng(3)
    for _ in range(50):
        height, width = (int(v) for v in rng.integers(5, 60, 2))
        boxes = [rng.uniform(-3, 50, 4).round(1).tolist() for _ in range(rng.integers(1, 3))]
        expected = mask_utils.merge(mask_utils.frPyObjects(np.array(boxes), height, width))
        masks = coco_masks.segmentations_to_intervals([boxes], [height], [width])
        np.testing.assert_array_equal(coco_masks.mask_from_intervals(masks, 0), mask_utils.decode(expected) > 0)


def test_mask_and_box_iou_match_pycocotools_including_crowd():
    rng = np.random.default_rng(4)
    for _ in range(120):
        height, width = (int(v) for v in rng.integers(5, 50, 2))
        detections = [reference_rle(random_mask(rng, height, width)) for _ in range(rng.integers(1, 6))]
        truths = [reference_rle(random_mask(rng, height, width)) for _ in range(rng.integers(1, 6))]
        crowd = rng.random(len(truths)) < 0.4
        ours = coco_masks.mask_iou(coco_masks.segmentations_to_intervals(detections, [None] * len(detections),
                                                                         [None] * len(detections)),
                                   coco_masks.segmentations_to_intervals(truths, [None] * len(truths),
                                                                         [None] * len(truths)), crowd)
        expected = mask_utils.iou([dict(d, counts=d["counts"].encode()) for d in detections],
                                  [dict(t, counts=t["counts"].encode()) for t in truths], crowd.astype(np.uint8))
        np.testing.assert_array_equal(ours, expected)
        boxes_d, boxes_g = rng.uniform(0, 30, (len(detections), 4)), rng.uniform(0, 30, (len(truths), 4))
        np.testing.assert_array_equal(coco_masks.box_iou(boxes_d, boxes_g, crowd),
                                      mask_utils.iou(boxes_d, boxes_g, crowd.astype(np.uint8)))


def test_pair_intersections_agree_with_dense_masks():
    rng = np.random.default_rng(5)
    dense_a = [random_mask(rng, 17, 13) for _ in range(6)]
    dense_b = [random_mask(rng, 17, 13) for _ in range(4)]
    a = coco_masks.segmentations_to_intervals([reference_rle(m) for m in dense_a], [17] * 6, [13] * 6)
    b = coco_masks.segmentations_to_intervals([reference_rle(m) for m in dense_b], [17] * 4, [13] * 4)
    first, second = rng.integers(0, 6, 30), rng.integers(0, 4, 30)
    expected = [np.count_nonzero(dense_a[i] & dense_b[j]) for i, j in zip(first, second)]
    np.testing.assert_array_equal(coco_masks.pair_intersections(a, b, first, second), expected)


def test_bad_rle_and_polygons_raise_value_errors():
    with pytest.raises(ValueError, match=r"gt\[0\]: compressed RLE counts must use characters"):
        coco_masks.segmentations_to_intervals([{"size": [4, 4], "counts": "a b"}], [None], [None], "gt")
    with pytest.raises(ValueError, match=r"gt\[0\]: RLE run lengths sum to 3"):
        coco_masks.segmentations_to_intervals([{"size": [4, 4], "counts": [1, 2]}], [None], [None], "gt")
    with pytest.raises(ValueError, match=r"gt\[1\]: RLE run lengths sum to 3, expected height\*width = 4 \(2x2\)"):
        coco_masks.segmentations_to_intervals([{"size": [2, 2], "counts": "04"}, {"size": [2, 2], "counts": "12"}],
                                              [None, None], [None, None], "gt")
    with pytest.raises(ValueError, match=r"gt\[2\]: compressed RLE decodes to negative"):  # before any sum
        coco_masks.segmentations_to_intervals([{"size": [2, 2], "counts": "12"}, {"size": [2, 2], "counts": "04"},
                                               {"size": [2, 2], "counts": "0O"}], [None] * 3, [None] * 3, "gt")
    with pytest.raises(ValueError, match=r"gt\[1\]: RLE size \[2, 2\] differs from the image size \[3, 3\]"):
        coco_masks.segmentations_to_intervals([[[0, 0, 1, 0, 1, 1]], {"size": [2, 2], "counts": "04"}], [3, 3],
                                              [3, 3], "gt")
    with pytest.raises(ValueError, match=r"gt\[1\]: expected an RLE dict with 'size'"):
        coco_masks.segmentations_to_intervals([{"size": [2, 2], "counts": "04"}, {"size": [True, 2], "counts": "04"}],
                                              [None] * 2, [None] * 2, "gt")
    with pytest.raises(ValueError, match="polygon coordinates must be finite numbers"):
        coco_masks.segmentations_to_intervals([[[0, 0, 1, None, 1, 1]]], [3], [3], "gt")
    with pytest.raises(ValueError, match="polygon coordinates must be finite numbers"):
        coco_masks.segmentations_to_intervals([[[0, 0, "a", 1]]], [3], [3], "gt")
    with pytest.raises(ValueError, match="truncated"):
        coco_masks.decode_counts_strings(["0P"], "gt")
    with pytest.raises(ValueError, match="at least 3 points"):
        coco_masks.segmentations_to_intervals([[[1.0, 2.0]]], [10], [10], "gt")
    with pytest.raises(ValueError, match="expected a polygon list"):
        coco_masks.segmentations_to_intervals(["polygon"], [10], [10], "gt")
    with pytest.raises(ValueError, match="size of every ground-truth mask"):
        small = coco_masks.segmentations_to_intervals([{"size": [2, 2], "counts": [4]}], [None], [None])
        large = coco_masks.segmentations_to_intervals([{"size": [3, 3], "counts": [9]}], [None], [None])
        coco_masks.mask_iou(small, large)
