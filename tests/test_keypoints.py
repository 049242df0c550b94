"""paz6d.backend.keypoints: normalization and left-right flips consistent with images."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from paz6d.backend import image, keypoints
from paz6d.backend.camera import Camera

PROPERTY = settings(max_examples=40, deadline=None)
K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])


def test_normalize_maps_the_image_extent():
    size = (100, 50)
    corners = [[-0.5, -0.5], [99.5, 49.5], [49.5, 24.5]]
    np.testing.assert_allclose(keypoints.normalize(corners, size), [[-1, -1], [1, 1], [0, 0]], atol=1e-15)
    np.testing.assert_allclose(keypoints.normalize(corners, size, (0, 1)), [[0, 0], [1, 1], [0.5, 0.5]], atol=1e-15)


@PROPERTY
@given(st.integers(0, 2**32 - 1), st.sampled_from([(-1.0, 1.0), (0.0, 1.0)]))
def test_denormalize_inverts_normalize(seed, value_range):
    points = np.random.default_rng(seed).uniform(-10, 700, (3, 5, 2))
    normalized = keypoints.normalize(points, (640, 480), value_range)
    assert normalized.shape == points.shape
    np.testing.assert_allclose(keypoints.denormalize(normalized, (640, 480), value_range), points, atol=1e-9)


def test_normalized_coordinates_survive_resizing():
    lens = Camera(K, 640, 480)
    half = lens.scaled(0.5)
    points = np.random.default_rng(0).uniform([-0.2, -0.2, 0.5], [0.2, 0.2, 1.5], (10, 3))
    np.testing.assert_allclose(keypoints.normalize(lens.project(points), (640, 480)),
                               keypoints.normalize(half.project(points), (320, 240)), atol=1e-12)


def test_flip_left_right_follows_the_image_flip():
    picture = np.zeros((20, 30, 3), np.uint8)
    spots = np.array([[3, 4], [27, 15], [0, 0]])  # (u, v) = (column, row) pixel centres
    for index, (u, v) in enumerate(spots):
        picture[v, u] = (index + 1) * 50
    flipped_picture = image.flip_left_right(picture)
    flipped = keypoints.flip_left_right(spots, 30)
    for index, (u, v) in enumerate(flipped.astype(int)):
        assert flipped_picture[v, u, 0] == (index + 1) * 50
    np.testing.assert_array_equal(keypoints.flip_left_right(flipped, 30), spots)


def test_flip_left_right_permutation_swaps_semantic_pairs():
    eyes_and_nose = np.array([[10.0, 5.0], [20.0, 5.0], [15.0, 9.0]])  # left eye, right eye, nose
    flipped = keypoints.flip_left_right(eyes_and_nose, 40, permutation=[1, 0, 2])
    np.testing.assert_array_equal(flipped, [[19.0, 5.0], [29.0, 5.0], [24.0, 9.0]])
    batch = np.stack([eyes_and_nose, eyes_and_nose + 1])
    np.testing.assert_array_equal(keypoints.flip_left_right(batch, 40, [1, 0, 2])[1], flipped + [-1, 1])
    with pytest.raises(ValueError, match=r"permutation: expected a permutation of range\(3\), got \[0, 0, 2\]"):
        keypoints.flip_left_right(eyes_and_nose, 40, [0, 0, 2])


def test_bad_keypoint_input_names_the_argument():
    with pytest.raises(ValueError, match=r"keypoints: expected shape \(\.\.\., 2\), got \(4, 3\)"):
        keypoints.normalize(np.zeros((4, 3)), (10, 10))
    with pytest.raises(ValueError, match=r"image_size: expected positive \(width, height\)"):
        keypoints.normalize(np.zeros((4, 2)), (10, -1))
    with pytest.raises(ValueError, match=r"value_range: expected one of"):
        keypoints.denormalize(np.zeros((4, 2)), (10, 10), (-0.5, 0.5))
    with pytest.raises(ValueError, match=r"keypoints: contains NaN"):
        keypoints.flip_left_right([[np.nan, 1.0]], 10)
