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


def _whitening_matrices(covariances, count: int) -> np.ndarray:
    """``(N, 2, 2)`` matrices ``W_i = L_i^-1`` with ``Σ_i = L_i L_iᵀ`` (Cholesky), so ``W_i r`` has unit covariance."""
    try:
        covariances = np.asarray(covariances, dtype=np.float64)
    except (TypeError, ValueError):
        raise PnPError(f"covariances: expected ({count}, 2, 2) numbers, got {type(covariances).__name__}") from None
    if covariances.shape != (count, 2, 2):
        raise PnPError(f"covariances: expected shape ({count}, 2, 2) (one 2x2 pixel covariance per point), "
                       f"got {covariances.shape}")
    if not np.all(np.isfinite(covariances)):
        raise PnPError("covariances: expected finite values, got NaN or infinity")
    if not np.allclose(covariances, np.swapaxes(covariances, 1, 2), rtol=1e-6, atol=1e-9):
        raise PnPError("covariances: expected symmetric 2x2 matrices")
    determinant = covariances[:, 0, 0] * covariances[:, 1, 1] - covariances[:, 0, 1] ** 2
    bad = np.flatnonzero((covariances[:, 0, 0] <= 0) | (determinant <= 0))
    if len(bad):
        raise PnPError(f"covariances: matrices {bad[:10].tolist()} are not positive definite")
    cholesky = np.linalg.cholesky(covariances)
    return np.linalg.inv(cholesky)


def solve_pnp_weighted(points3d, points2d, K, covariances, method: str = "epnp", ransac: bool = True,
                       distortion=None, reprojection_threshold: float = 8.0, robust_scale: float | None = 3.0,
                       iterations: int = 200, confidence: float = 0.999, seed: int = 0,
                       max_evaluations: int = 100) -> PnPSolution:
    """Covariance-weighted PnP: ``T_model2cam`` minimising the whitened reprojection error.

    Each correspondence ``i`` has a ``2×2`` pixel covariance ``Σ_i = L_i L_iᵀ``; the pose minimises
    ``Σ_i ρ(‖L_i⁻¹ (π(R X_i + t) − x_i)‖²)`` (squared Mahalanobis distances), so uncertain keypoints
    count less and along their uncertain direction only. It starts from :func:`solve_pnp` (``method``,
    RANSAC with ``reprojection_threshold`` px when ``ransac``, LM refinement) and refines with
    Levenberg–Marquardt-style trust-region least squares (``scipy.optimize.least_squares``, Jacobians
    from ``cv2.projectPoints``) over *all* correspondences; with ``robust_scale`` the loss ``ρ`` is
    Huber's with that many standard deviations as its knee (outliers with small covariances still
    count only linearly), else plain least squares.

    Args:
        covariances: ``(N, 2, 2)`` symmetric positive-definite pixel covariances.
        max_evaluations: limit on residual evaluations of the refinement.
    Returns:
        A :class:`PnPSolution`; ``inliers`` are the correspondences whose Mahalanobis distance is at most
        ``robust_scale`` (all of them without a robust loss).
    Raises:
        PnPError: the checks of :func:`solve_pnp`, covariances of the wrong shape or not positive definite.
    """
    points3d, points2d = _check_correspondences(points3d, points2d)
    whitening = _whitening_matrices(covariances, len(points3d))
    if robust_scale is not None and not (np.isfinite(robust_scale) and robust_scale > 0):
        raise PnPError(f"robust_scale: expected a positive number of standard deviations or None, got {robust_scale}")
    if int(max_evaluations) < 1:
        raise PnPError(f"max_evaluations: expected a positive integer, got {max_evaluations}")
    start = solve_pnp(points3d, points2d, K, method, ransac, distortion, True, reprojection_threshold, iterations,
                      confidence, seed)
    from scipy.optimize import least_squares  # here: scipy.optimize is heavy and only needed for this solver

    K = as_camera_matrix(K)
    distortion = _checked_distortion(distortion)
    count = len(points3d)

    def residuals(parameters):
        projected, _ = cv2.projectPoints(points3d, parameters[:3], parameters[3:], K, distortion)
        return np.einsum("nij,nj->ni", whitening, projected.reshape(count, 2) - points2d).ravel()

    def jacobian(parameters):
        _, derivatives = cv2.projectPoints(points3d, parameters[:3], parameters[3:], K, distortion)
        return np.einsum("nij,njk->nik", whitening, derivatives[:, :6].reshape(count, 2, 6)).reshape(2 * count, 6)

    initial = np.concatenate([start.rotation_vector, start.translation])
    robust = robust_scale is not None
    try:
        result = least_squares(residuals, initial, jac=jacobian, method="trf" if robust else "lm",
                               loss="huber" if robust else "linear", f_scale=float(robust_scale) if robust else 1.0,
                               max_nfev=int(max_evaluations), x_scale="jac")
    except (ValueError, np.linalg.LinAlgError, cv2.error) as error:
        raise PnPError(f"solve_pnp_weighted: refinement failed ({str(error)[:200]})") from None
    parameters = result.x if np.all(np.isfinite(result.x)) and result.x[5] > 0 else initial
    distances = np.linalg.norm(residuals(parameters).reshape(count, 2), axis=1)
    inliers = np.flatnonzero(distances <= robust_scale) if robust else np.arange(count)
    return PnPSolution(parameters[:3].copy(), parameters[3:].copy(), inliers, count)
