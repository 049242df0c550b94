"""Pose geometry of the implicit-pose pipeline: ray correction and translation from a box (no TensorFlow)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paz6d.assets.demo_object import make_demo_mesh
from paz6d.aae.pipeline import (fit_translation_to_box, pose_from_codebook_view, ray_rotation,
                                           silhouette_box, translation_from_box)
from paz6d.aae.views import ViewGeometry, silhouette_boxes

K = np.array([[572.4, 0.0, 325.3], [0.0, 573.6, 242.0], [0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def hull():
    return np.asarray(make_demo_mesh().convex_hull.vertices)


def test_ray_rotation_takes_the_optical_axis_onto_the_ray():
    rng = np.random.default_rng(0)
    for direction in list(rng.normal(size=(20, 3))) + [np.array([0, 0, 2.0]), np.array([0, 0, -1.0])]:
        R = ray_rotation(direction)
        np.testing.assert_allclose(R @ [0, 0, 1], direction / np.linalg.norm(direction), atol=1e-12)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
        if abs(direction[2]) < np.linalg.norm(direction) * (1 - 1e-9):
            # smallest rotation: its axis is perpendicular to both the optical axis and the ray
            axis = Rotation.from_matrix(R).as_rotvec()
            assert abs(axis[2]) < 1e-12 and abs(np.dot(axis, direction)) < 1e-9
    with pytest.raises(ValueError, match="direction"):
        ray_rotation([0, 0, 0])


def test_translation_is_exact_for_a_box_of_a_known_pose(hull):
    """Off-axis poses: the box of the object's silhouette at (R, t) gives back (R, t) exactly."""
    geometry = ViewGeometry.for_points(hull, 96)
    rng = np.random.default_rng(1)
    for R_true in Rotation.random(15, random_state=2).as_matrix():
        z = rng.uniform(0.3, 1.2)
        pixel = rng.uniform([60, 60], [580, 420])
        t_true = np.array([(pixel[0] - K[0, 2]) * z / K[0, 0], (pixel[1] - K[1, 2]) * z / K[1, 1], z])
        box = silhouette_box(hull, R_true, t_true, K)
        # the codebook view that shows the same appearance: the object turned onto the optical axis
        R_codebook = ray_rotation(t_true).T @ R_true
        render_box = silhouette_boxes(hull, R_codebook[None], geometry.K, [0, 0, geometry.distance])[0]
        R, t = pose_from_codebook_view(R_codebook, box, K, render_box, geometry.K, geometry.distance, hull)
        np.testing.assert_allclose(t, t_true, atol=1e-9)
        np.testing.assert_allclose(R, R_true, atol=1e-9)


def test_paper_formula_is_exact_on_axis_at_the_render_distance_and_close_elsewhere(hull):
    geometry = ViewGeometry.for_points(hull, 128)
    for R in Rotation.random(5, random_state=3).as_matrix():
        render_box = silhouette_boxes(hull, R[None], geometry.K, [0, 0, geometry.distance])[0]
        t = translation_from_box(render_box, geometry.K, render_box, geometry.K, geometry.distance)
        np.testing.assert_allclose(t, [0, 0, geometry.distance], atol=1e-12)
        # the same object twice as far, seen by a camera with twice the focal length: same image
        K2 = geometry.K.copy()
        K2[:2, :2] *= 2.0
        t2 = translation_from_box(render_box, K2, render_box, geometry.K, geometry.distance)
        np.testing.assert_allclose(t2, [0, 0, 2 * geometry.distance], atol=1e-12)
        # a different distance: perspective makes the scaling law approximate (within 3 %)
        far_box = silhouette_box(hull, R, np.array([0, 0, 1.5 * geometry.distance]), geometry.K)
        t3 = translation_from_box(far_box, geometry.K, render_box, geometry.K, geometry.distance)
        assert abs(t3[2] / (1.5 * geometry.distance) - 1) < 0.03


def test_box_fit_converges_from_a_rough_start(hull):
    R = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
    t_true = np.array([0.05, -0.03, 0.6])
    box = silhouette_box(hull, R, t_true, K)
    t = fit_translation_to_box(hull, R, box, K, t_true + [0.03, -0.02, 0.15])
    np.testing.assert_allclose(t, t_true, atol=1e-10)


def test_refinement_needs_the_hull(hull):
    with pytest.raises(ValueError, match="hull_points"):
        pose_from_codebook_view(np.eye(3), (10, 10, 50, 60), K, (10, 10, 50, 60), K, 0.5, None, refine=True)
