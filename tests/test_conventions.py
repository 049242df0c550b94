"""renderers.conventions: the one OpenGL projection agrees with paz6d.backend.camera's pinhole projection."""

from __future__ import annotations

import numpy as np
import pytest

from paz6d.backend.camera import project_points
from renderers.conventions import FLIP_YZ, projection_matrix

K = np.array([[572.4, 0.7, 325.3], [0.0, 573.6, 242.0], [0.0, 0.0, 1.0]])


def test_opengl_projection_lands_on_the_pixel_centres_of_project_points():
    width, height, near, far = 640, 480, 0.1, 10.0
    P = projection_matrix(K, width, height, near, far)
    points = np.random.default_rng(0).uniform([-0.3, -0.2, 0.5], [0.3, 0.2, 3.0], (50, 3))
    clip = (FLIP_YZ @ np.column_stack([points, np.ones(len(points))]).T).T @ P.T
    ndc = clip[:, :3] / clip[:, 3:]
    # window coordinates count pixel edges from the bottom-left; OpenCV pixel centres sit half a pixel in
    u = (ndc[:, 0] + 1) / 2 * width - 0.5
    v = (1 - ndc[:, 1]) / 2 * height - 0.5
    np.testing.assert_allclose(np.column_stack([u, v]), project_points(points, K), atol=1e-9)
    depth_ndc = [(P @ [0, 0, -z, 1])[2] / (P @ [0, 0, -z, 1])[3] for z in (near, far)]
    np.testing.assert_allclose(depth_ndc, [-1.0, 1.0], atol=1e-12)
    with pytest.raises(ValueError, match="znear/zfar"):
        projection_matrix(K, width, height, 1.0, 0.5)
