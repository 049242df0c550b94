"""PCK against a brute-force loop over instances and keypoints."""

from __future__ import annotations

import math

import numpy as np
import pytest

from evaluation.keypoints import pck, reference_sizes_from_boxes


def brute_force_pck(predicted, target, sizes, alpha, visible):
    correct = visible_count = 0
    per_keypoint_correct = [0] * predicted.shape[1]
    per_keypoint_visible = [0] * predicted.shape[1]
    for n in range(predicted.shape[0]):
        for k in range(predicted.shape[1]):
            if not visible[n][k]:
                continue
            dx = predicted[n][k][0] - target[n][k][0]
            dy = predicted[n][k][1] - target[n][k][1]
            hit = math.sqrt(dx * dx + dy * dy) <= alpha * sizes[n]
            correct += hit
            visible_count += 1
            per_keypoint_correct[k] += hit
            per_keypoint_visible[k] += 1
    per_keypoint = [c / v if v else math.nan for c, v in zip(per_keypoint_correct, per_keypoint_visible)]
    return correct / visible_count, per_keypoint


@pytest.mark.parametrize("seed", range(5))
def test_pck_matches_brute_force(seed):
    rng = np.random.default_rng(seed)
    count, keypoints = 40, 7
    target = rng.uniform(0, 200, (count, keypoints, 2))
    predicted = target + rng.normal(0, 8, (count, keypoints, 2))
    boxes = np.concatenate([target.min(axis=1), target.max(axis=1)], axis=1)
    sizes = reference_sizes_from_boxes(boxes)
    visible = rng.random((count, keypoints)) < 0.8
    visible[:, 3] = False  # a keypoint that is never visible
    for alpha in (0.02, 0.05, 0.1, 0.2):
        result = pck(predicted, target, sizes, alpha, visible)
        expected, per_keypoint = brute_force_pck(predicted, target, sizes, alpha, visible)
        assert result.pck == pytest.approx(expected, abs=1e-12)
        np.testing.assert_allclose(result.per_keypoint, per_keypoint, atol=1e-12, equal_nan=True)
        assert np.isnan(result.per_keypoint[3])
        assert not np.any(result.correct & ~visible)


def test_threshold_is_inclusive_and_defaults_to_all_visible():
    target = np.zeros((1, 3, 2))
    predicted = np.array([[[3.0, 4.0], [0.0, 5.000001], [0.0, 0.0]]])
    result = pck(predicted, target, reference_size=25.0, alpha=0.2)  # threshold 5 px
    np.testing.assert_array_equal(result.correct, [[True, False, True]])
    assert result.pck == pytest.approx(2 / 3)
    np.testing.assert_allclose(result.distances, [[5.0, 5.000001, 0.0]])


def test_reference_sizes_from_boxes():
    boxes = np.array([[0.0, 0.0, 30.0, 40.0], [10.0, 10.0, 15.0, 12.0]])
    np.testing.assert_allclose(reference_sizes_from_boxes(boxes), [40.0, 5.0])
    np.testing.assert_allclose(reference_sizes_from_boxes(boxes, "diagonal"), [50.0, math.hypot(5, 2)])


def test_bad_inputs_raise_value_errors():
    points = np.zeros((2, 4, 2))
    with pytest.raises(ValueError, match="target"):
        pck(points, np.zeros((2, 3, 2)), [1.0, 1.0])
    with pytest.raises(ValueError, match="reference_size"):
        pck(points, points, [1.0, 0.0])
    with pytest.raises(ValueError, match="visible"):
        pck(points, points, [1.0, 1.0], visible=np.ones((2, 3), bool))
    with pytest.raises(ValueError, match="alpha"):
        pck(points, points, [1.0, 1.0], alpha=-0.1)
    with pytest.raises(ValueError, match="predicted"):
        pck(np.zeros((4, 2)), np.zeros((4, 2)), [1.0])
    with pytest.raises(ValueError, match="mode"):
        reference_sizes_from_boxes([[0, 0, 1, 1]], "area")
    assert math.isnan(pck(points, points, [1.0, 1.0], visible=np.zeros((2, 4), bool)).pck)
