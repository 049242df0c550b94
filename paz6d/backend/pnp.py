"""Perspective-n-Point: object pose from 3D↔2D correspondences (OpenCV solvers).

Points are in metres (model frame) and pixels; the result is a :class:`~paz6d.abstract.Pose6D`
``T_model2cam``.
"""

from __future__ import annotations

import cv2
import numpy as np

from paz6d.abstract.messages import Pose6D
from paz6d.backend.checks import as_camera_matrix, as_points

METHODS = {"iterative": cv2.SOLVEPNP_ITERATIVE, "epnp": cv2.SOLVEPNP_EPNP, "sqpnp": cv2.SOLVEPNP_SQPNP}
COLLINEARITY_TOLERANCE = 1e-6


class PnPError(ValueError):
    """Degenerate input or a solver failure."""


def _check_correspondences(points3d, points2d) -> tuple[np.ndarray, np.ndarray]:
    points3d = as_points(points3d, "points3d", dimension=3)
    points2d = as_points(points2d, "points2d", dimension=2)
    if len(points3d) != len(points2d):
        raise PnPError(f"points3d/points2d: expected the same number of points, got {len(points3d)} and {len(points2d)}")
    if len(points3d) < 4:
        raise PnPError(f"points3d: expected at least 4 correspondences of shape (N, 3), got {len(points3d)}")
    singular = np.linalg.svd(points3d - points3d.mean(axis=0), compute_uv=False)
    if singular[0] <= 0 or singular[1] <= COLLINEARITY_TOLERANCE * singular[0]:
        raise PnPError("points3d: points are collinear (or coincident); PnP needs points spanning a plane or volume")
    return points3d, points2d


def reprojection_errors(points3d, points2d, pose: Pose6D, K, distortion=None) -> np.ndarray:
    """Pixel distance ``(N,)`` between ``points2d`` and the projections of ``points3d`` under ``pose``."""
    projected, _ = cv2.projectPoints(np.asarray(points3d, dtype=np.float64), pose.rotation_vector,
                                     pose.translation, as_camera_matrix(K), distortion)
    return np.linalg.norm(projected.reshape(-1, 2) - np.asarray(points2d, dtype=np.float64), axis=1)


def solve_pnp(points3d, points2d, K, method: str = "sqpnp", ransac: bool = False, distortion=None,
              refine: bool = True, reprojection_threshold: float = 8.0, iterations: int = 200,
              confidence: float = 0.999, seed: int = 0, class_name: str | None = None) -> Pose6D:
    """Estimates ``T_model2cam`` from ``(N, 3)`` model points (m) and ``(N, 2)`` pixels.

    Args:
        method: ``"sqpnp"`` (default, globally optimal), ``"epnp"`` or ``"iterative"``.
        ransac: reject outliers with RANSAC (threshold ``reprojection_threshold`` px); the
            resulting pose's ``score`` is the inlier fraction.
        refine: finish with Levenberg–Marquardt on the (inlier) correspondences.
        seed: seeds OpenCV's RNG for reproducible RANSAC.
    Raises:
        PnPError: fewer than 4 points, collinear points, or no solution.
    """
    points3d, points2d = _check_correspondences(points3d, points2d)
    K = as_camera_matrix(K)
    if method not in METHODS:
        raise PnPError(f"method: expected one of {sorted(METHODS)}, got {method!r}")
    distortion = None if distortion is None else np.asarray(distortion, dtype=np.float64)
    inliers = np.arange(len(points3d))
    if ransac:
        cv2.setRNGSeed(seed)
        found, rotation_vector, translation, inlier_index = cv2.solvePnPRansac(
            points3d, points2d, K, distortion, iterationsCount=iterations,
            reprojectionError=reprojection_threshold, confidence=confidence, flags=METHODS[method])
        if not found or inlier_index is None or len(inlier_index) < 4:
            raise PnPError("solve_pnp: RANSAC found no pose with at least 4 inliers")
        inliers = inlier_index.ravel()
    else:
        found, rotation_vector, translation = cv2.solvePnP(points3d, points2d, K, distortion, flags=METHODS[method])
        if not found:
            raise PnPError(f"solve_pnp: OpenCV {method} found no solution")
    if refine:
        rotation_vector, translation = cv2.solvePnPRefineLM(points3d[inliers], points2d[inliers], K, distortion,
                                                            rotation_vector, translation)
    score = len(inliers) / len(points3d)
    return Pose6D.from_rotation_vector(rotation_vector.ravel(), translation.ravel(), class_name, score)
