"""paz6d.backend.boxes against brute-force references, pycocotools IoU and OpenCV's NMS."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pycocotools import mask as coco_mask

from paz6d.backend import boxes

PROPERTY = settings(max_examples=40, deadline=None)
seeds = st.integers(0, 2**32 - 1)
SSD300 = dict(image_size=300, feature_map_sizes=[38, 19, 10, 5, 3, 1], steps=[8, 16, 32, 64, 100, 300],
              min_sizes=[30, 60, 111, 162, 213, 264], max_sizes=[60, 111, 162, 213, 264, 315],
              aspect_ratios=[[2], [2, 3], [2, 3], [2, 3], [2], [2]])


def random_boxes(generator: np.random.Generator, count: int, extent: float = 100.0) -> np.ndarray:
    corner = generator.uniform(0, extent, (count, 2))
    size = generator.uniform(extent / 100, extent / 3, (count, 2))
    return np.concatenate([corner, corner + size], axis=1)


def brute_force_iou(a, b) -> float:
    width = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    height = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    intersection = width * height
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - intersection
    return intersection / union if union > 0 else 0.0


def brute_force_nms(candidates, scores, threshold) -> list[int]:
    remaining = sorted(range(len(scores)), key=lambda index: -scores[index])
    kept = []
    while remaining:
        best = remaining.pop(0)
        kept.append(best)
        remaining = [index for index in remaining if brute_force_iou(candidates[best], candidates[index]) <= threshold]
    return kept


@PROPERTY
@given(seeds)
def test_format_conversions_round_trip_and_match_definitions(seed):
    xyxy = random_boxes(np.random.default_rng(seed), 7)
    xywh = boxes.convert(xyxy, "xyxy", "xywh")
    cxcywh = boxes.convert(xyxy, "xyxy", "cxcywh")
    np.testing.assert_allclose(xywh, np.column_stack([xyxy[:, :2], xyxy[:, 2:] - xyxy[:, :2]]))
    np.testing.assert_allclose(cxcywh, np.column_stack([(xyxy[:, :2] + xyxy[:, 2:]) / 2, xyxy[:, 2:] - xyxy[:, :2]]))
    for source, values in (("xywh", xywh), ("cxcywh", cxcywh)):
        np.testing.assert_allclose(boxes.convert(values, source, "xyxy"), xyxy, atol=1e-12)
    np.testing.assert_allclose(boxes.convert(xywh, "xywh", "cxcywh"), cxcywh, atol=1e-12)
    np.testing.assert_allclose(boxes.convert(cxcywh, "cxcywh", "xywh"), xywh, atol=1e-12)
    same = boxes.convert(xyxy, "xyxy", "xyxy")
    assert same is not xyxy and np.array_equal(same, xyxy)
    batched = boxes.convert(xyxy.reshape(1, 7, 4), "xyxy", "cxcywh")
    np.testing.assert_array_equal(batched[0], cxcywh)


def test_normalize_denormalize_clip_area_flip():
    pixels = np.array([[64.0, 48.0, 320.0, 480.0], [-10.0, 5.0, 700.0, 500.0]])
    normalized = boxes.normalize(pixels, (640, 480))
    np.testing.assert_allclose(normalized[0], [0.1, 0.1, 0.5, 1.0])
    np.testing.assert_allclose(boxes.denormalize(normalized, (640, 480)), pixels)
    np.testing.assert_array_equal(boxes.clip(pixels, (640, 480))[1], [0, 5, 640, 480])
    np.testing.assert_array_equal(boxes.clip(normalized, (1, 1))[1], boxes.normalize([0, 5, 640, 480], (640, 480)))
    np.testing.assert_allclose(boxes.area(pixels), [256 * 432, 710 * 495])
    assert boxes.area([5.0, 5.0, 1.0, 9.0]) == 0.0  # inverted box
    np.testing.assert_array_equal(boxes.flip_left_right([[2.0, 1.0, 5.0, 3.0]], 10), [[5.0, 1.0, 8.0, 3.0]])


@PROPERTY
@given(seeds, st.integers(1, 12), st.integers(1, 12))
def test_iou_matrix_matches_brute_force_and_pycocotools(seed, rows, columns):
    generator = np.random.default_rng(seed)
    first, second = random_boxes(generator, rows), random_boxes(generator, columns)
    second[0] = first[0]  # guarantee one perfect overlap
    matrix = boxes.iou_matrix(first, second)
    expected = [[brute_force_iou(a, b) for b in second] for a in first]
    np.testing.assert_allclose(matrix, expected, atol=1e-12)
    assert matrix[0, 0] == pytest.approx(1.0)
    coco = coco_mask.iou(boxes.convert(first, "xyxy", "xywh").tolist(), boxes.convert(second, "xyxy", "xywh").tolist(),
                         [0] * columns)
    np.testing.assert_allclose(matrix, coco, atol=1e-9)


def test_iou_of_degenerate_boxes_is_zero():
    matrix = boxes.iou_matrix([[0, 0, 0, 0], [0, 0, 2, 2]], [[0, 0, 0, 0], [1, 1, 1, 5], [0, 0, 1, 2]])
    np.testing.assert_allclose(matrix, [[0, 0, 0], [0, 0, 0.5]])
    assert boxes.iou_matrix(np.zeros((0, 4)), [[0, 0, 1, 1]]).shape == (0, 1)


@PROPERTY
@given(seeds, st.integers(1, 60), st.floats(0.1, 0.9))
def test_nms_matches_brute_force_and_opencv(seed, count, threshold):
    generator = np.random.default_rng(seed)
    candidates = random_boxes(generator, count, extent=60.0)
    scores = generator.random(count)
    kept = boxes.nms(candidates, scores, threshold)
    assert kept.dtype == np.int64
    assert kept.tolist() == brute_force_nms(candidates, scores, threshold)
    opencv = cv2.dnn.NMSBoxes(boxes.convert(candidates, "xyxy", "xywh").tolist(), scores.tolist(), 0.0, threshold)
    assert kept.tolist() == np.asarray(opencv, dtype=int).ravel().tolist()


def test_nms_score_threshold_max_outputs_and_ties():
    candidates = np.array([[0, 0, 10, 10], [0, 0, 10, 10], [20, 20, 30, 30], [40, 40, 50, 50]], float)
    assert boxes.nms(candidates, [0.5, 0.5, 0.5, 0.1], 0.5).tolist() == [0, 2, 3]  # equal scores keep input order
    assert boxes.nms(candidates, [0.5, 0.9, 0.6, 0.1], 0.5, score_threshold=0.2).tolist() == [1, 2]
    assert boxes.nms(candidates, [0.5, 0.9, 0.6, 0.1], 0.5, max_outputs=2).tolist() == [1, 2]
    assert boxes.nms(candidates, [0.5, 0.9, 0.6, 0.1], 1.0).tolist() == [1, 2, 0, 3]
    assert boxes.nms(np.zeros((0, 4)), np.zeros(0)).tolist() == []


@PROPERTY
@given(seeds, st.integers(1, 60), st.integers(1, 4))
def test_nms_per_class_equals_separate_runs_and_opencv_batched(seed, count, classes):
    generator = np.random.default_rng(seed)
    candidates = random_boxes(generator, count, extent=50.0)
    scores = generator.random(count)
    class_ids = generator.integers(0, classes, count) * 7 - 3  # arbitrary, negative ids too
    kept = boxes.nms_per_class(candidates, scores, class_ids, 0.4, score_threshold=0.2)
    expected = []
    for class_id in np.unique(class_ids):
        members = np.flatnonzero((class_ids == class_id) & (scores >= 0.2))
        expected += members[boxes.nms(candidates[members], scores[members], 0.4)].tolist()
    assert kept.tolist() == sorted(expected, key=lambda index: -scores[index])
    opencv = cv2.dnn.NMSBoxesBatched(boxes.convert(candidates, "xyxy", "xywh").tolist(), scores.tolist(),
                                     class_ids.tolist(), 0.2, 0.4)
    assert sorted(kept.tolist()) == sorted(np.asarray(opencv, dtype=int).ravel().tolist())


def test_prior_boxes_ssd300_layout():
    priors = boxes.prior_boxes(**SSD300)
    assert priors.shape == (8732, 4)
    assert priors.min() >= 0 and priors.max() <= 1
    # Brute-force the first cell and the last feature map, in the documented order.
    first = [[4 / 300, 4 / 300, 30 / 300, 30 / 300], [4 / 300, 4 / 300, np.sqrt(30 * 60) / 300, np.sqrt(30 * 60) / 300],
             [4 / 300, 4 / 300, 30 * np.sqrt(2) / 300, 30 / np.sqrt(2) / 300],
             [4 / 300, 4 / 300, 30 / np.sqrt(2) / 300, 30 * np.sqrt(2) / 300]]
    np.testing.assert_allclose(priors[:4], first, atol=1e-12)
    last = [[0.5, 0.5, 264 / 300, 264 / 300], [0.5, 0.5, np.sqrt(264 * 315) / 300, np.sqrt(264 * 315) / 300],
            [0.5, 0.5, min(1.0, 264 * np.sqrt(2) / 300), 264 / np.sqrt(2) / 300],
            [0.5, 0.5, 264 / np.sqrt(2) / 300, min(1.0, 264 * np.sqrt(2) / 300)]]
    np.testing.assert_allclose(priors[-4:], last, atol=1e-12)
    # Cell (row 1, col 2) of the 38x38 map starts at prior index (1 * 38 + 2) * 4.
    np.testing.assert_allclose(priors[(38 + 2) * 4, :2], [2.5 * 8 / 300, 1.5 * 8 / 300])
    unclipped = boxes.prior_boxes(**{**SSD300, "clip_to_image": False})
    assert unclipped.max() > 1


def test_prior_boxes_on_a_rectangular_input_match_a_brute_force_loop():
    width, height = 96.0, 64.0
    maps, steps = [(8, 12), (4, 6)], [(8.0, 8.0), (16.0, 16.0)]
    mins, maxs, ratios = [10.0, 30.0], [30.0, 50.0], [[2.0], [3.0]]
    expected = []
    for (rows, cols), (step_x, step_y), low, high, extra in zip(maps, steps, mins, maxs, ratios):
        for row in range(rows):
            for col in range(cols):
                cx, cy = (col + 0.5) * step_x, (row + 0.5) * step_y
                shapes = [(low, low), (np.sqrt(low * high),) * 2]
                for ratio in extra:
                    shapes += [(low * np.sqrt(ratio), low / np.sqrt(ratio)),
                               (low / np.sqrt(ratio), low * np.sqrt(ratio))]
                expected += [(cx / width, cy / height, w / width, h / height) for w, h in shapes]
    priors = boxes.prior_boxes((width, height), maps, steps, mins, maxs, ratios, clip_to_image=False)
    np.testing.assert_allclose(priors, expected, atol=1e-12)
    square = boxes.prior_boxes(64, [8, 4], [8, 16], mins, maxs, ratios)
    np.testing.assert_array_equal(square, boxes.prior_boxes((64, 64), [(8, 8), (4, 4)], [(8, 8), (16, 16)], mins,
                                                             maxs, ratios))
    with pytest.raises(ValueError, match="expected a number or a pair"):
        boxes.prior_boxes((64, 64, 3), [8], [8], [10], [20], [[2]])


def test_match_assigns_best_prior_to_every_object_and_thresholds_the_rest():
    priors = boxes.prior_boxes(300, [5], [60], [60], [100], [[2]])
    truth = np.array([[0.0, 0.0, 0.24, 0.24], [0.62, 0.6, 0.7, 0.66], [0.15, 0.62, 0.45, 0.78]])
    matched = boxes.match(truth, priors, iou_threshold=0.5)
    # objects 0 and 2 overlap several priors by >= 0.5; object 1 overlaps none that much
    assert np.bincount(matched[matched >= 0]).tolist() == [4, 1, 3]
    overlaps = boxes.iou_matrix(truth, boxes.convert(priors, "cxcywh", "xyxy"))
    for object_index in range(len(truth)):
        assert matched[np.argmax(overlaps[object_index])] == object_index
    for prior_index, object_index in enumerate(matched):
        if object_index >= 0 and prior_index not in np.argmax(overlaps, axis=1):
            assert overlaps[object_index, prior_index] >= 0.5
            assert object_index == np.argmax(overlaps[:, prior_index])
        if object_index < 0:
            assert overlaps[:, prior_index].max() < 0.5
    assert (boxes.match(np.zeros((0, 4)), priors) == -1).all()


@PROPERTY
@given(seeds)
def test_encode_matches_ssd_formula_and_decode_inverts_it(seed):
    generator = np.random.default_rng(seed)
    truth = random_boxes(generator, 10, extent=1.0)
    priors = boxes.convert(random_boxes(generator, 10, extent=1.0), "xyxy", "cxcywh")
    offsets = boxes.encode(truth, priors)
    center = (truth[:, :2] + truth[:, 2:]) / 2
    size = truth[:, 2:] - truth[:, :2]
    expected = np.column_stack([(center - priors[:, :2]) / (0.1 * priors[:, 2:]),
                                np.log(size / priors[:, 2:]) / 0.2])
    np.testing.assert_allclose(offsets, expected, atol=1e-12)
    np.testing.assert_allclose(boxes.decode(offsets, priors), truth, atol=1e-12)
    np.testing.assert_allclose(boxes.decode(boxes.encode(truth, priors, (1, 1, 1, 1)), priors, (1, 1, 1, 1)), truth,
                               atol=1e-12)
    np.testing.assert_allclose(boxes.decode(np.zeros((10, 4)), priors), boxes.convert(priors, "cxcywh", "xyxy"))


def test_bad_box_input_names_the_argument():
    with pytest.raises(ValueError, match=r"boxes: expected shape \(\.\.\., 4\), got \(3,\)"):
        boxes.convert([1, 2, 3], "xyxy", "xywh")
    with pytest.raises(ValueError, match=r"target: expected one of \('xyxy', 'xywh', 'cxcywh'\), got 'yolo'"):
        boxes.convert([1, 2, 3, 4], "xyxy", "yolo")
    with pytest.raises(ValueError, match=r"boxes_b: expected shape \(N, 4\), got \(4,\)"):
        boxes.iou_matrix([[0, 0, 1, 1]], [0, 0, 1, 1])
    with pytest.raises(ValueError, match=r"boxes_a: contains NaN"):
        boxes.iou_matrix([[0, 0, np.nan, 1]], [[0, 0, 1, 1]])
    with pytest.raises(ValueError, match=r"scores: expected shape \(2,\) matching boxes, got \(3,\)"):
        boxes.nms([[0, 0, 1, 1], [0, 0, 1, 1]], [1, 2, 3])
    with pytest.raises(ValueError, match=r"iou_threshold: expected a value in \[0, 1\]"):
        boxes.nms([[0, 0, 1, 1]], [1.0], iou_threshold=1.5)
    with pytest.raises(ValueError, match=r"class_ids: expected \(1,\) integers matching boxes"):
        boxes.nms_per_class([[0, 0, 1, 1]], [1.0], [0.5])
    with pytest.raises(ValueError, match=r"image_size: expected positive \(width, height\)"):
        boxes.normalize([0, 0, 1, 1], (0, 10))
    with pytest.raises(ValueError, match=r"variances: expected 4 positive numbers"):
        boxes.decode(np.zeros(4), [0.5, 0.5, 1, 1], (0.1, 0.2))
    with pytest.raises(ValueError, match=r"boxes: expected positive width and height to encode"):
        boxes.encode([0.5, 0.5, 0.5, 0.7], [0.5, 0.5, 1, 1])
    with pytest.raises(ValueError, match=r"feature_map_sizes/steps/min_sizes/max_sizes/aspect_ratios"):
        boxes.prior_boxes(300, [38, 19], [8], [30], [60], [[2]])


def test_overlaps_image_at_the_borders():
    # pixel i covers [i, i+1): a box ending at 0 or starting at the width touches no pixel
    assert boxes.overlaps_image([-5, -5, 0.5, 0.5], 10, 8)
    assert not boxes.overlaps_image([-5, 2, 0, 4], 10, 8) and not boxes.overlaps_image([2, -5, 4, 0], 10, 8)
    assert not boxes.overlaps_image([10, 2, 12, 4], 10, 8) and not boxes.overlaps_image([2, 8, 4, 9], 10, 8)
    assert boxes.overlaps_image([9.9, 7.9, 20, 20], 10, 8)
    with pytest.raises(ValueError, match="lies outside the 10x8 image"):
        boxes.check_box_in_image([10, 2, 12, 4], 10, 8)


def test_move_box_shifts_by_fractions_of_the_sides_and_scales_about_the_centre():
    # 20 x 40 px, centre (20, 40): right by 10 % of the width, up by 25 % of the height; then half size
    moved = boxes.move_box([10, 20, 30, 60], [(0.1, -0.25, 1.0), (0.0, 0.0, 0.5), (0.0, 0.0, 1.0)])
    np.testing.assert_allclose(moved, [[12, 10, 32, 50], [15, 30, 25, 50], [10, 20, 30, 60]])
