"""Perspective-n-Point: object pose from 3D↔2D correspondences (OpenCV solvers).

Points are in metres (model frame) and pixels; the result is ``T_model2cam`` as arrays
(:class:`PnPSolution`). The backend knows no messages: :class:`paz6d.processors.pose.SolvePnP`
turns a solution into a :class:`~paz6d.abstract.Pose6D`.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np

from paz6d.backend.camera import transform_and_project
from paz6d.backend.checks import as_camera_matrix, as_points

METHODS = {"iterative": cv2.SOLVEPNP_ITERATIVE, "epnp": cv2.SOLVEPNP_EPNP, "sqpnp": cv2.SOLVEPNP_SQPNP}
COLLINEARITY_TOLERANCE = 1e-6
#: Numbers of distortion coefficients OpenCV accepts.
DISTORTION_SIZES = (4, 5, 8, 12, 14)


class PnPError(ValueError):
    """Degenerate input or a solver failure."""


class PnPSolution(NamedTuple):
    """A PnP result: ``T_model2cam = [R(rotation_vector) | translation]``.

    Attributes:
        rotation_vector: ``(3,)`` axis-angle (radians) of ``R_model2cam``.
        translation: ``(3,)`` metres.
        inliers: ``(M,)`` indices of the correspondences used (all of them without RANSAC).
        count: number of correspondences given.
    """

    rotation_vector: np.ndarray
    translation: np.ndarray
    inliers: np.ndarray
    count: int

    @property
    def inlier_fraction(self) -> float:
        """``len(inliers) / count``."""
        return len(self.inliers) / self.count

    @property
    def T_model2cam(self) -> np.ndarray:
        """``(4, 4)`` homogeneous pose."""
        T = np.eye(4)
        T[:3, :3] = cv2.Rodrigues(self.rotation_vector)[0]
        T[:3, 3] = self.translation
        return T


def _check_correspondences(points3d, points2d) -> tuple[np.ndarray, np.ndarray]:
    points3d = as_points(points3d, "points3d", dimension=3)
    points2d = as_points(points2d, "points2d", dimension=2)
    if len(points3d) != len(points2d):
        raise PnPError(f"points3d/points2d: expected the same number of points, got {len(points3d)} and "
                       f"{len(points2d)}")
    if len(points3d) < 4:
        raise PnPError(f"points3d: expected at least 4 correspondences of shape (N, 3), got {len(points3d)}")
    singular = np.linalg.svd(points3d - points3d.mean(axis=0), compute_uv=False)
    if singular[0] <= 0 or singular[1] <= COLLINEARITY_TOLERANCE * singular[0]:
        raise PnPError("points3d: points are collinear (or coincident); PnP needs points spanning a plane or volume")
    spread = np.linalg.svd(points2d - points2d.mean(axis=0), compute_uv=False)
    if spread[0] <= 0 or spread[1] <= COLLINEARITY_TOLERANCE * spread[0]:
        raise PnPError("points2d: pixels are collinear or identical; PnP needs them to span an area")
    return points3d, points2d


def reprojection_errors(points3d, points2d, T_model2cam, K, distortion=None) -> np.ndarray:
    """Pixel distance ``(N,)`` between ``points2d`` and the projections of ``points3d`` posed by
    ``T_model2cam`` ``(4, 4)``."""
    projected = transform_and_project(np.asarray(points3d, dtype=np.float64), T_model2cam, as_camera_matrix(K),
                                      distortion)
    return np.linalg.norm(projected.reshape(-1, 2) - np.asarray(points2d, dtype=np.float64), axis=1)


def solve_pnp(points3d, points2d, K, method: str = "sqpnp", ransac: bool = False, distortion=None,
              refine: bool = True, reprojection_threshold: float = 8.0, iterations: int = 200,
              confidence: float = 0.999, seed: int = 0) -> PnPSolution:
    """Estimates ``T_model2cam`` from ``(N, 3)`` model points (m) and ``(N, 2)`` pixels.

    Args:
        method: ``"sqpnp"`` (default, globally optimal), ``"epnp"`` or ``"iterative"``.
        ransac: reject outliers with RANSAC (threshold ``reprojection_threshold`` px); the
            solution's ``inliers`` are the correspondences RANSAC kept.
        refine: finish with Levenberg–Marquardt on the (inlier) correspondences.
        seed: seeds OpenCV's RNG for reproducible RANSAC.
    Raises:
        PnPError: fewer than 4 points, collinear points, or no solution.
    """
    points3d, points2d = _check_correspondences(points3d, points2d)
    K = as_camera_matrix(K)
    if method not in METHODS:
        raise PnPError(f"method: expected one of {sorted(METHODS)}, got {method!r}")
    distortion = _checked_distortion(distortion)
    if not (np.isfinite(reprojection_threshold) and reprojection_threshold > 0):
        raise PnPError(f"reprojection_threshold: expected a positive number of pixels, got {reprojection_threshold}")
    if not 0.0 < confidence < 1.0:
        raise PnPError(f"confidence: expected a probability in (0, 1), got {confidence}")
    if isinstance(iterations, bool) or not float(iterations).is_integer() or iterations < 1:
        raise PnPError(f"iterations: expected a positive integer, got {iterations!r}")
    try:
        return _solve(points3d, points2d, K, method, ransac, distortion, refine, float(reprojection_threshold),
                      int(iterations), float(confidence), seed)
    except cv2.error as error:  # inputs OpenCV rejects despite the checks above
        message = str(error).strip().splitlines()[-1] if str(error).strip() else "cv2.error"
        raise PnPError(f"solve_pnp: OpenCV could not solve these correspondences ({message[:200]})") from None


def _checked_distortion(distortion) -> np.ndarray | None:
    """``None`` or the OpenCV distortion coefficients as a finite float64 vector of 4, 5, 8, 12 or 14."""
    if distortion is None:
        return None
    try:
        values = np.asarray(distortion, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise PnPError(f"distortion: expected 4, 5, 8, 12 or 14 numbers, got {type(distortion).__name__}") from None
    if values.size not in DISTORTION_SIZES or not np.all(np.isfinite(values)):
        raise PnPError(f"distortion: expected 4, 5, 8, 12 or 14 finite numbers, got {values.size} "
                       f"({'with NaN/inf' if not np.all(np.isfinite(values)) else 'finite'})")
    return values


def _solve(points3d, points2d, K, method, ransac, distortion, refine, reprojection_threshold, iterations,
           confidence, seed) -> PnPSolution:
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
    return PnPSolution(rotation_vector.ravel(), translation.ravel(), inliers, len(points3d))
