"""6D pose error functions, vectorized over many estimates of one object.

Every function takes a batch of estimated poses ``T_est`` ``(E, 4, 4)`` and the matching
ground-truth poses ``T_gt`` ``(E, 4, 4)`` (or one ``(4, 4)`` broadcast to all), both
``T_model2cam`` in the OpenCV camera frame, and returns ``(E,)`` errors.

Units: lengths come out in the unit of the inputs (model points and pose translations): millimetres
in BOP mode, metres elsewhere. Angles are in degrees, image errors in pixels, VSD is unitless.

Definitions follow Hodaň et al., "BOP: Benchmark for 6D Object Pose Estimation" (ECCV 2018) and
the BOP Challenge 2019 (MSSD, MSPD, VSD with the "bop19" visibility test), Hinterstoisser et al.
ACCV 2012 (ADD, ADI = ADD-S), Brachmann et al. CVPR 2016 (2D projection error) and Xiang et al.
"PoseCNN" RSS 2018 (area under the ADD/ADD-S accuracy-threshold curve).

Example:
    >>> model = ObjectModel(points_mm, diameter=102.1)                        # doctest: +SKIP
    >>> adi_error(T_est, T_gt, model.points, tree=model.tree)                 # doctest: +SKIP
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from evaluation.point_tree import PointTree
from paz6d.backend.checks import as_array, as_camera_matrix, as_points, as_rotation_matrix
# Largest accepted max |R^T R - I| of a pose rotation (BOP's rounded rotations pass); errors are
# computed with the matrices as given, as BOP does.
from paz6d.datasets.bop.results import ROTATION_TOLERANCE

#: BOP's default discretization of continuous symmetries: the vertex farthest from the axis moves
#: at most this fraction of the diameter between consecutive samples (ceil(pi / 0.01) = 315 steps).
MAX_SYMMETRY_STEP = 0.01
#: ``max |R^T R - I|`` below which an estimated rotation is treated as exactly orthonormal by ADI.
ORTHONORMAL_TO_MACHINE = 1e-12


def as_pose_batch(T, name: str) -> np.ndarray:
    """Validates ``(..., 4, 4)`` poses (finite, last row ``[0, 0, 0, 1]``, rotation within
    :data:`ROTATION_TOLERANCE` of orthonormal with det > 0) and returns them as ``(E, 4, 4)``."""
    T = as_array(T, name, (4, 4)).reshape(-1, 4, 4)
    if not np.allclose(T[:, 3, :], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise ValueError(f"{name}: expected last row [0, 0, 0, 1] of a rigid transform")
    as_rotation_matrix(T[:, :3, :3], f"{name}[..., :3, :3]", tolerance=ROTATION_TOLERANCE)
    return T


def _pose_batch(T_est, T_gt) -> tuple[np.ndarray, np.ndarray]:
    """Validates and broadcasts both pose arrays to ``(E, 4, 4)``."""
    T_est = as_pose_batch(T_est, "T_est")
    T_gt = as_pose_batch(T_gt, "T_gt")
    if len(T_gt) == 1 and len(T_est) != 1:
        T_gt = np.broadcast_to(T_gt, T_est.shape)
    elif len(T_est) == 1 and len(T_gt) != 1:
        T_est = np.broadcast_to(T_est, T_gt.shape)
    if T_est.shape != T_gt.shape:
        raise ValueError(f"T_est/T_gt: expected the same number of poses, got {len(T_est)} and {len(T_gt)}")
    return T_est, T_gt


def _camera_batch(K, count: int) -> np.ndarray:
    """``(count, 3, 3)`` intrinsics from one ``(3, 3)`` or ``(count, 3, 3)`` array."""
    K = as_array(K, "K", (3, 3))
    if K.ndim == 2:
        as_camera_matrix(K)
        return np.broadcast_to(K, (count, 3, 3))
    K = K.reshape(-1, 3, 3)
    if len(K) != count:
        raise ValueError(f"K: expected one (3, 3) matrix or {count} of them, got {len(K)}")
    for matrix in np.unique(K, axis=0):
        as_camera_matrix(matrix)
    return K


def _transform(R: np.ndarray, t: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``R (..., 3, 3) @ points (N, 3) + t (..., 3)`` -> ``(..., N, 3)`` (batched matmul)."""
    return points @ np.swapaxes(R, -1, -2) + t[..., None, :]


def _image_transforms(K: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``K R`` ``(E, ..., 3, 3)`` and ``K t`` ``(E, ..., 3)`` of poses ``T`` ``(E, ..., 4, 4)`` seen by
    ``K`` ``(E, 3, 3)``: a point ``x`` projects to ``(K R x + K t)`` divided by its last coordinate,
    as BOP divides (no clipping; a point exactly on the camera plane gives inf/NaN)."""
    K = K.reshape(K.shape[:1] + (1,) * (T.ndim - 3) + (3, 3))
    return (np.ascontiguousarray(K @ T[..., :3, :3]),
            np.ascontiguousarray(np.einsum("...ij,...j->...i", K, T[..., :3, 3])))


def _finite_or_inf(errors: np.ndarray) -> np.ndarray:
    """Maps NaN (a point on the camera plane) to ``inf``: such a pose is never correct."""
    return np.where(np.isnan(errors), np.inf, errors)


def add_error(T_est, T_gt, points) -> np.ndarray:
    """ADD: mean distance between model points under the two poses, ``(E,)`` (length unit of inputs).

    Args:
        T_est: ``(E, 4, 4)`` or ``(4, 4)`` estimated ``T_model2cam``.
        T_gt: ``(E, 4, 4)`` or ``(4, 4)`` ground-truth ``T_model2cam``.
        points: ``(N, 3)`` model points (e.g. the vertices of a BOP ``models_eval`` mesh).
    """
    T_est, T_gt = _pose_batch(T_est, T_gt)
    points = as_points(points, "points")
    A = T_est[:, :3, :3] - T_gt[:, :3, :3]
    b = T_est[:, :3, 3] - T_gt[:, :3, 3]
    from evaluation.pose_error_kernels import mean_distances

    return mean_distances(np.ascontiguousarray(A), np.ascontiguousarray(b), np.ascontiguousarray(points))


def adi_error(T_est, T_gt, points, tree: PointTree | None = None, workers: int = 1) -> np.ndarray:
    """ADI (ADD-S): mean over ground-truth posed points of the distance to the nearest estimated
    posed point, ``(E,)`` (length unit of inputs).

    Rigid motions preserve distances, so every query is mapped into the model frame of the
    estimate, ``x -> R_est^T (R_gt x + t_gt - t_est)``, and answered by one KD-tree on the model
    points built once per object (:class:`evaluation.point_tree.PointTree`). An estimate whose
    rotation is not orthonormal to 1e-12 (where that mapping would not preserve distances) gets
    its own ``scipy`` KD-tree on its posed points instead.

    Args:
        T_est: ``(E, 4, 4)`` or ``(4, 4)`` estimated ``T_model2cam``.
        T_gt: ``(E, 4, 4)`` or ``(4, 4)`` ground-truth ``T_model2cam``.
        points: ``(N, 3)`` model points.
        tree: ``PointTree(points)`` to reuse (e.g. :attr:`ObjectModel.tree`); built when ``None``.
        workers: threads (-1 = all cores); results do not depend on it.
    """
    T_est, T_gt = _pose_batch(T_est, T_gt)
    points = as_points(points, "points")
    if tree is None:
        tree = PointTree(points)
    elif tree.n != len(points):
        raise ValueError(f"tree: built on {tree.n} points, expected the {len(points)} given points")
    R_est_inverse = np.swapaxes(T_est[:, :3, :3], -1, -2)
    A = R_est_inverse @ T_gt[:, :3, :3]
    b = np.einsum("eij,ej->ei", R_est_inverse, T_gt[:, :3, 3] - T_est[:, :3, 3])
    orthonormal = np.abs(R_est_inverse @ T_est[:, :3, :3] - np.eye(3)).max(axis=(1, 2)) <= ORTHONORMAL_TO_MACHINE
    errors = np.empty(len(T_est))
    errors[orthonormal] = tree.mean_nearest_distance(A[orthonormal], b[orthonormal], workers=workers)
    if not orthonormal.all():
        from scipy.spatial import cKDTree  # only for such estimates: scipy.spatial costs ~0.3 s to import
    for row in np.flatnonzero(~orthonormal):
        posed_est = _transform(T_est[row, :3, :3], T_est[row, :3, 3], points)
        posed_gt = _transform(T_gt[row, :3, :3], T_gt[row, :3, 3], points)
        errors[row] = cKDTree(posed_est).query(posed_gt, k=1, workers=workers)[0].mean()
    return errors


def rotation_error_deg(R_est, R_gt) -> np.ndarray:
    """Rotation error in degrees, ``(...)``, from ``(..., 3, 3)`` matrices, as BOP defines it:
    ``acos((trace(R_est R_gt^-1) - 1) / 2)`` with the cosine clipped to [-1, 1].

    ``R_gt^-1`` is the matrix inverse, not the transpose, because BOP ground-truth rotations are
    rounded (not exactly orthonormal). ``acos`` limits the resolution near 0 to about 1e-6 deg.
    """
    R_est = as_array(R_est, "R_est", (3, 3))
    R_gt = as_array(R_gt, "R_gt", (3, 3))
    cosine = (np.trace(R_est @ np.linalg.inv(R_gt), axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def translation_error(t_est, t_gt) -> np.ndarray:
    """Euclidean distance between ``(..., 3)`` translations (length unit of inputs)."""
    return np.linalg.norm(as_array(t_est, "t_est", (3,)) - as_array(t_gt, "t_gt", (3,)), axis=-1)


def projection_error(T_est, T_gt, points, K) -> np.ndarray:
    """2D projection error: mean pixel distance between the projected model points, ``(E,)`` px.

    Args:
        T_est, T_gt: ``(E, 4, 4)`` or ``(4, 4)`` poses.
        points: ``(N, 3)`` model points.
        K: ``(3, 3)`` or ``(E, 3, 3)`` intrinsics of each image.
    """
    T_est, T_gt = _pose_batch(T_est, T_gt)
    points = as_points(points, "points")
    K = _camera_batch(K, len(T_est))
    from evaluation.pose_error_kernels import mean_pixel_distances

    errors = mean_pixel_distances(*_image_transforms(K, T_est), *_image_transforms(K, T_gt),
                                  np.ascontiguousarray(points))
    return _finite_or_inf(errors)


def symmetry_transformations(discrete=None, continuous=(), max_step: float = MAX_SYMMETRY_STEP) -> np.ndarray:
    """The set of symmetry transformations of an object as ``(S, 4, 4)`` (identity first).

    As BOP's ``get_symmetry_transformations``: each continuous symmetry (rotation about ``axis``
    through ``offset``) is sampled at ``ceil(pi / max_step)`` angles over a full turn (315 for the
    default 0.01), and every sampled rotation is composed with every discrete symmetry
    (``T_continuous @ T_discrete``).

    Args:
        discrete: ``(D, 4, 4)`` discrete symmetries (BOP ``symmetries_discrete``), identity implied.
        continuous: ``[(axis (3,), offset (3,)), ...]`` (BOP ``symmetries_continuous``); ``offset``
            in the length unit of the model.
        max_step: largest angular step as a fraction of pi (BOP ``max_sym_disc_step``).
    """
    transforms = [np.eye(4)]
    if discrete is not None and len(discrete):
        transforms += list(as_array(discrete, "symmetries_discrete", (4, 4)).reshape(-1, 4, 4))
    discrete_set = np.stack(transforms)
    if not continuous:
        return discrete_set
    if not max_step > 0:
        raise ValueError(f"max_step: expected a positive fraction, got {max_step}")
    from scipy.spatial.transform import Rotation  # here: only objects with continuous symmetries need it

    steps = int(np.ceil(np.pi / max_step))
    sampled = []
    for index, (axis, offset) in enumerate(continuous):
        axis = as_array(axis, f"symmetries_continuous[{index}].axis", (3,)).reshape(3)
        offset = as_array(offset, f"symmetries_continuous[{index}].offset", (3,)).reshape(3)
        norm = np.linalg.norm(axis)
        if norm == 0:
            raise ValueError(f"symmetries_continuous[{index}].axis: expected a non-zero vector")
        angles = np.arange(steps) * (2.0 * np.pi / steps)
        rotations = Rotation.from_rotvec(angles[:, None] * (axis / norm)).as_matrix()
        T = np.tile(np.eye(4), (steps, 1, 1))
        T[:, :3, :3] = rotations
        T[:, :3, 3] = offset - rotations @ offset
        sampled.append(T)
    continuous_set = np.concatenate(sampled)
    return np.einsum("cij,djk->dcik", continuous_set, discrete_set).reshape(-1, 4, 4)


def _symmetric_gt(T_gt: np.ndarray, symmetries: np.ndarray) -> np.ndarray:
    """``(E, S, 4, 4)`` ground-truth poses composed with each symmetry: ``T_gt @ S``."""
    symmetries = as_array(symmetries, "symmetries", (4, 4)).reshape(-1, 4, 4)
    return np.einsum("eij,sjk->esik", T_gt, symmetries)


def mssd_error(T_est, T_gt, points, symmetries) -> np.ndarray:
    """MSSD: min over symmetries of the max distance between posed model points, ``(E,)``.

    Computed by a numba kernel (:mod:`evaluation.pose_error_kernels`) that drops a symmetry as soon
    as it cannot beat the best one (all 1,407 LM-O estimates on all ``models_eval`` points: 0.02 s;
    restricting the points to their convex hull, which gives the same value, saves nothing once the
    hull is counted).

    Args:
        T_est, T_gt: ``(E, 4, 4)`` or ``(4, 4)`` poses.
        points: ``(N, 3)`` model points.
        symmetries: ``(S, 4, 4)`` symmetry transformations (:func:`symmetry_transformations`).
    """
    T_est, T_gt = _pose_batch(T_est, T_gt)
    points = as_points(points, "points")
    T_sym = _symmetric_gt(T_gt, symmetries)
    A = T_est[:, None, :3, :3] - T_sym[..., :3, :3]
    b = T_est[:, None, :3, 3] - T_sym[..., :3, 3]
    from evaluation.pose_error_kernels import min_max_distances

    return min_max_distances(np.ascontiguousarray(A), np.ascontiguousarray(b), np.ascontiguousarray(points))


def mspd_error(T_est, T_gt, points, K, symmetries) -> np.ndarray:
    """MSPD: min over symmetries of the max pixel distance between projected model points, ``(E,)`` px.

    Args:
        T_est, T_gt: ``(E, 4, 4)`` or ``(4, 4)`` poses.
        points: ``(N, 3)`` model points (all of them: projection does not preserve convexity).
        K: ``(3, 3)`` or ``(E, 3, 3)`` intrinsics.
        symmetries: ``(S, 4, 4)`` symmetry transformations.
    """
    T_est, T_gt = _pose_batch(T_est, T_gt)
    points = as_points(points, "points")
    K = _camera_batch(K, len(T_est))
    T_sym = _symmetric_gt(T_gt, symmetries)
    from evaluation.pose_error_kernels import min_max_pixel_distances

    return min_max_pixel_distances(*_image_transforms(K, T_est), *_image_transforms(K, T_sym),
                                   np.ascontiguousarray(points))


def distance_image(depth: np.ndarray, K) -> np.ndarray:
    """Distance from the camera centre of each pixel's 3D point, ``(H, W)`` (depth unit, 0 = none).

    Pixel ``(row, col)`` is taken at its centre ``(u, v) = (col, row)`` (OpenCV convention).
    """
    depth = np.asarray(depth, dtype=np.float64)
    if depth.ndim != 2:
        raise ValueError(f"depth: expected shape (H, W), got {depth.shape}")
    K = as_camera_matrix(K)
    rows, cols = np.indices(depth.shape)
    x = (cols - K[0, 2]) / K[0, 0]
    y = (rows - K[1, 2]) / K[1, 1]
    return depth * np.sqrt(x * x + y * y + 1.0)


def vsd_error(depth_test, depth_est, depth_gt, K, delta: float, taus, diameter: float = 1.0) -> np.ndarray:
    """VSD (Visible Surface Discrepancy, BOP'19 visibility) for each tolerance in ``taus``, ``(T,)``.

    A pixel is visible for the ground truth where the model is rendered and either the test
    depth is missing or the rendered distance is at most ``delta`` behind the test distance;
    for the estimate, the same test or the ground-truth visibility where the estimate is
    rendered. The error is ``(#inter with |d_gt - d_est| >= tau * diameter + #(union - inter))
    / #union`` (1 when the union is empty).

    Args:
        depth_test: ``(H, W)`` depth of the test image (0 = missing).
        depth_est: ``(H, W)`` rendered depth of the model in the estimated pose (0 = background).
        depth_gt: ``(H, W)`` rendered depth of the model in the ground-truth pose.
        K: ``(3, 3)`` intrinsics.
        delta: visibility tolerance (depth unit, BOP: 15 mm).
        taus: ``(T,)`` misalignment tolerances as fractions of ``diameter`` (BOP: 0.05..0.5).
        diameter: object diameter (depth unit); 1 makes ``taus`` absolute.
    """
    shapes = {np.shape(depth_test), np.shape(depth_est), np.shape(depth_gt)}
    if len(shapes) != 1:
        raise ValueError(f"depth_test/depth_est/depth_gt: expected the same (H, W) shape, got {sorted(shapes)}")
    taus = np.atleast_1d(np.asarray(taus, dtype=np.float64))
    dist_test = distance_image(depth_test, K)
    dist_est = distance_image(depth_est, K)
    dist_gt = distance_image(depth_gt, K)
    missing = dist_test == 0
    visible_gt = (dist_gt > 0) & ((dist_gt - dist_test <= delta) | missing)
    visible_est = (dist_est > 0) & ((dist_est - dist_test <= delta) | missing)
    visible_est |= visible_gt & (dist_est > 0)
    inter = visible_gt & visible_est
    union_count = np.count_nonzero(visible_gt | visible_est)
    if union_count == 0:
        return np.ones(len(taus))
    misaligned = np.abs(dist_gt[inter] - dist_est[inter]) / diameter
    complement = union_count - np.count_nonzero(inter)
    costs = (misaligned[None, :] >= taus[:, None]).sum(axis=1)
    return (costs + complement) / union_count


def accuracy_auc(errors, max_threshold: float) -> float:
    """Area under the accuracy-threshold curve on ``[0, max_threshold]``, normalized to [0, 1].

    The YCB-Video metric (PoseCNN): accuracy(t) = fraction of ``errors`` <= t; missed targets
    count as ``inf``. The integral of that step function has the closed form
    ``mean(max(0, 1 - e / max_threshold))``.
    """
    errors = np.asarray(errors, dtype=np.float64).ravel()
    if not max_threshold > 0:
        raise ValueError(f"max_threshold: expected a positive length, got {max_threshold}")
    if errors.size == 0:
        return 0.0
    if np.any(np.isnan(errors)) or np.any(errors < 0):
        raise ValueError("errors: expected non-negative values (inf for a missed target)")
    return float(np.mean(np.clip(1.0 - errors / max_threshold, 0.0, 1.0)))


@dataclass
class ObjectModel:
    """The evaluation data of one object: points, diameter and symmetries, with cached search
    structures (one KD-tree per object, built on first use).

    Attributes:
        points: ``(N, 3)`` model points (BOP: vertices of the ``models_eval`` mesh, mm).
        diameter: largest distance between two model points (same unit).
        symmetries: ``(S, 4, 4)`` symmetry transformations, identity first.
    """

    points: np.ndarray
    diameter: float
    symmetries: np.ndarray = field(default_factory=lambda: np.eye(4)[None])

    def __post_init__(self):
        self.points = as_points(self.points, "points")
        if not (np.isfinite(self.diameter) and self.diameter > 0):
            raise ValueError(f"diameter: expected a positive length, got {self.diameter}")
        self.symmetries = as_array(self.symmetries, "symmetries", (4, 4)).reshape(-1, 4, 4)

    @property
    def is_symmetric(self) -> bool:
        """Whether the object has symmetries besides the identity (ADI is used for ADD(-S))."""
        return len(self.symmetries) > 1

    @cached_property
    def tree(self) -> PointTree:
        """KD-tree on :attr:`points` for :func:`adi_error`."""
        return PointTree(self.points)
