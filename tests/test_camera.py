"""paz6d.backend.camera against OpenCV (projectPoints, Rodrigues) and a hand-written
Brown-Conrady distortion model."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from paz6d.backend import camera, quaternion, transform
from paz6d.backend.camera import Camera

PROPERTY = settings(max_examples=40, deadline=None)
seeds = st.integers(0, 2**32 - 1)
K = np.array([[572.4114, 0.0, 325.2611], [0.0, 573.57043, 242.04899], [0.0, 0.0, 1.0]])
DISTORTION = np.array([-0.28, 0.07, 0.001, -0.0005, 0.01])


def points_in_front(seed: int, count: int = 30) -> np.ndarray:
    generator = np.random.default_rng(seed)
    return np.column_stack([generator.uniform(-0.3, 0.3, (count, 2)), generator.uniform(0.4, 2.0, count)])


def brown_conrady(points_cam: np.ndarray, K: np.ndarray, coefficients: np.ndarray) -> np.ndarray:
    """Reference distortion (OpenCV's k1, k2, p1, p2, k3 model), written out term by term."""
    k1, k2, p1, p2, k3 = coefficients
    x = points_cam[:, 0] / points_cam[:, 2]
    y = points_cam[:, 1] / points_cam[:, 2]
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.column_stack([K[0, 0] * xd + K[0, 2], K[1, 1] * yd + K[1, 2]])


@PROPERTY
@given(seeds)
def test_project_points_matches_opencv_without_distortion(seed):
    points = points_in_front(seed)
    expected, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), K, None)
    np.testing.assert_allclose(camera.project_points(points, K), expected.reshape(-1, 2), atol=1e-9)


@PROPERTY
@given(seeds)
def test_project_points_with_distortion_matches_reference_and_opencv(seed):
    points = points_in_front(seed)
    pixels = camera.project_points(points, K, DISTORTION)
    np.testing.assert_allclose(pixels, brown_conrady(points, K, DISTORTION), atol=1e-9)
    expected, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), K, DISTORTION)
    np.testing.assert_allclose(pixels, expected.reshape(-1, 2), atol=1e-9)


def test_zero_distortion_equals_no_distortion_and_skew_is_applied():
    points = points_in_front(1)
    np.testing.assert_array_equal(camera.project_points(points, K, np.zeros(5)), camera.project_points(points, K))
    skewed = K.copy()
    skewed[0, 1] = 2.0
    expected = camera.project_points(points, K)
    expected[:, 0] += 2.0 * points[:, 1] / points[:, 2]
    np.testing.assert_allclose(camera.project_points(points, skewed), expected, atol=1e-9)


def test_points_behind_the_camera_project_to_nan():
    pixels = camera.project_points([[0.0, 0.0, -1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]], K)
    assert np.all(np.isnan(pixels[:2])) and np.all(np.isfinite(pixels[2]))


@PROPERTY
@given(seeds)
def test_rotation_vectors_match_rodrigues(seed):
    vector = np.random.default_rng(seed).uniform(-3.0, 3.0, 3)
    expected, _ = cv2.Rodrigues(vector)
    np.testing.assert_allclose(quaternion.to_rotation_matrix(quaternion.from_rotation_vector(vector)), expected,
                               atol=1e-12)
    back, _ = cv2.Rodrigues(expected)
    np.testing.assert_allclose(quaternion.to_rotation_vector(quaternion.from_rotation_matrix(expected)),
                               back.ravel(), atol=1e-9)


@PROPERTY
@given(seeds)
def test_transform_and_project_matches_opencv_with_pose(seed):
    generator = np.random.default_rng(seed)
    rotation_vector = generator.uniform(-1.0, 1.0, 3)
    translation = np.array([0.05, -0.02, 1.0])
    model = generator.uniform(-0.1, 0.1, (20, 3))
    T = transform.from_rotation_translation(cv2.Rodrigues(rotation_vector)[0], translation)
    for distortion in (None, DISTORTION):
        expected, _ = cv2.projectPoints(model, rotation_vector, translation, K, distortion)
        np.testing.assert_allclose(camera.transform_and_project(model, T, K, distortion), expected.reshape(-1, 2),
                                   atol=1e-9)


@PROPERTY
@given(seeds)
def test_unproject_inverts_project(seed):
    points = points_in_front(seed)
    np.testing.assert_allclose(camera.unproject(camera.project_points(points, K), points[:, 2], K), points,
                               atol=1e-12)


def test_depth_to_points_back_projects_pixel_centres():
    depth = np.zeros((4, 5), np.float32)
    depth[1, 2] = 2.0
    depth[3, 0] = 0.5
    points = camera.points_from_depth(depth, K)
    assert points.shape == (2, 3)
    np.testing.assert_allclose(points[:, 2], [2.0, 0.5])
    np.testing.assert_allclose(camera.project_points(points, K), [[2, 1], [0, 3]], atol=1e-9)
    with pytest.raises(ValueError, match=r"depth: expected shape \(H, W\)"):
        camera.points_from_depth(np.zeros((2, 2, 1)), K)


def test_camera_object_projects_undistorts_and_serializes():
    lens = Camera(K, 640, 480, DISTORTION)
    points = points_in_front(2)
    distorted = lens.project(points)
    np.testing.assert_allclose(lens.undistort_points(distorted), camera.project_points(points, K), atol=1e-9)
    pinhole = Camera(K, 640, 480)
    assert pinhole.distortion is None
    np.testing.assert_array_equal(pinhole.undistort_points(distorted), distorted)
    image = np.random.default_rng(0).integers(0, 255, (480, 640, 3), dtype=np.uint8)
    assert pinhole.undistort_image(image) is image
    restored = Camera.from_dict(json.loads(json.dumps(lens.to_dict())))
    np.testing.assert_array_equal(restored.K, lens.K)
    np.testing.assert_array_equal(restored.distortion, lens.distortion)
    assert (restored.width, restored.height) == (640, 480)
    np.testing.assert_allclose(lens.unproject(camera.project_points(points, K), points[:, 2]), points, atol=1e-12)


def test_scaled_camera_keeps_pixel_centre_convention():
    original = Camera(K, 640, 480)
    half = original.scaled(0.5)
    assert (half.width, half.height) == (320, 240)
    points = points_in_front(4)
    # A point at pixel centre u of the full image is at (u + 0.5) * s - 0.5 after resizing by s.
    np.testing.assert_allclose(half.project(points), (original.project(points) + 0.5) * 0.5 - 0.5, atol=1e-9)


def test_bad_camera_input_names_the_argument():
    with pytest.raises(ValueError, match=r"K: expected \[\[fx, s, cx\], \[0, fy, cy\], \[0, 0, 1\]\]"):
        Camera(np.diag([-1.0, 1.0, 1.0]), 10, 10)
    with pytest.raises(ValueError, match=r"K: expected shape \(\.\.\., 3, 3\), got \(2, 2\)"):
        camera.project_points(points_in_front(0), np.eye(2))
    with pytest.raises(ValueError, match=r"width/height: expected positive pixel sizes"):
        Camera(K, 0, 480)
    with pytest.raises(ValueError, match=r"distortion: expected 4, 5, 8, 12 or 14 OpenCV coefficients, got 3"):
        Camera(K, 640, 480, [0.1, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"distortion: expected 4, 5, 8, 12 or 14 OpenCV coefficients, got 1"):
        Camera(K, 640, 480, 0.1)
    with pytest.raises(ValueError, match=r"distortion: contains NaN"):
        Camera(K, 640, 480, [np.nan, 0.0, 0.0, 0.0])
    assert Camera(K, 640, 480, np.array([[0.1, 0.0, 0.0, 0.0, 0.0]])).distortion.shape == (5,)  # OpenCV's (1, 5)
    with pytest.raises(ValueError, match=r"points_cam: expected shape \(\.\.\., 3\), got \(4, 2\)"):
        camera.project_points(np.ones((4, 2)), K)
    with pytest.raises(ValueError, match=r"points_cam: contains NaN"):
        camera.project_points([[0.0, np.nan, 1.0]], K)
    with pytest.raises(ValueError, match=r"depths: expected shape \(2,\) to match pixels"):
        camera.unproject(np.zeros((2, 2)), np.ones(3), K)
    with pytest.raises(ValueError, match="camera dict: missing field 'height'"):
        Camera.from_dict({"K": K.tolist(), "width": 640})


def test_rotation_vector_conventions_agree_with_scipy_and_opencv_for_a_pose():
    vector = np.array([0.2, -0.5, 1.3])
    np.testing.assert_allclose(cv2.Rodrigues(vector)[0], Rotation.from_rotvec(vector).as_matrix(), atol=1e-12)


def test_as_camera_takes_a_camera_or_a_matrix_with_the_image_size():
    lens = Camera(K, 640, 480)
    assert camera.as_camera(lens) is lens and camera.as_camera(lens, 640, 480) is lens
    made = camera.as_camera(K, 640, 480)
    assert isinstance(made, Camera) and (made.width, made.height) == (640, 480) and made.distortion is None
    np.testing.assert_array_equal(made.K, K)
    with pytest.raises(ValueError, match=r"image: 320x240 pixels does not match the camera's 640x480"):
        camera.as_camera(lens, 320, 240)
    with pytest.raises(ValueError, match=r"camera: a 3x3 K needs the image size \(width, height\)"):
        camera.as_camera(K)
    with pytest.raises(ValueError, match="camera: none given"):
        camera.as_camera(None, 640, 480)
    with pytest.raises(ValueError, match=r"camera: expected shape \(\.\.\., 3, 3\), got \(2, 2\)"):
        camera.as_camera(np.eye(2), 640, 480)
