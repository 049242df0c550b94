"""paz6d.backend.keypoints: normalization consistent with resizing, as the keypoint trainers use it."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from paz6d.backend import keypoints
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
def test_normalization_terms_equal_the_closed_form(seed, value_range):
    points = np.random.default_rng(seed).uniform(-10, 700, (3, 5, 2))
    scale, offset = keypoints.normalization((640, 480), value_range)
    size = np.array([640.0, 480.0])
    expected = (2 * points + 1) / size - 1 if value_range == (-1.0, 1.0) else (points + 0.5) / size
    np.testing.assert_allclose(points * scale + offset, expected, atol=1e-12)
    np.testing.assert_array_equal(keypoints.normalize(points, (640, 480), value_range), points * scale + offset)


def test_float32_terms_give_the_trainers_former_closed_form_bit_for_bit():
    """The keypoint trainers normalise float32 pixels with the float32 terms; the former inline
    ``uv * (2 / size) + (1 / size - 1)`` gave the same bits."""
    uv = np.random.default_rng(1).uniform(-20, 150, (64, 2)).astype(np.float32)
    scale, offset = (terms.astype(np.float32) for terms in keypoints.normalization((128.0, 128.0)))
    np.testing.assert_array_equal(uv * scale + offset, uv * (2.0 / 128.0) + (1.0 / 128.0 - 1.0))


def test_normalized_coordinates_survive_resizing():
    lens = Camera(K, 640, 480)
    half = lens.scaled(0.5)
    points = np.random.default_rng(0).uniform([-0.2, -0.2, 0.5], [0.2, 0.2, 1.5], (10, 3))
    np.testing.assert_allclose(keypoints.normalize(lens.project(points), (640, 480)),
                               keypoints.normalize(half.project(points), (320, 240)), atol=1e-12)


def test_bad_keypoint_input_names_the_argument():
    with pytest.raises(ValueError, match=r"keypoints: expected shape \(\.\.\., 2\), got \(4, 3\)"):
        keypoints.normalize(np.zeros((4, 3)), (10, 10))
    with pytest.raises(ValueError, match=r"image_size: expected positive \(width, height\)"):
        keypoints.normalize(np.zeros((4, 2)), (10, -1))
    with pytest.raises(ValueError, match=r"value_range: expected one of"):
        keypoints.normalization((10, 10), (-0.5, 0.5))
    with pytest.raises(ValueError, match=r"keypoints: contains NaN"):
        keypoints.normalize([[np.nan, 1.0]], (10, 10))
