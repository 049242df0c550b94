"""Pose processors over :mod:`paz6d.backend.pnp` and :mod:`paz6d.backend.square_crop`: the steps that turn
2D evidence into a :class:`~paz6d.abstract.Pose6D` ``T_model2cam`` (metres, OpenCV camera frame).
"""

from __future__ import annotations

from paz6d.abstract.messages import Box2D, Pose6D
from paz6d.abstract.processor import Processor
from paz6d.backend.camera import Camera, as_camera
from paz6d.backend.checks import as_points
from paz6d.backend.pnp import solve_pnp, solve_pnp_weighted
from paz6d.backend.square_crop import projected_box


class SolvePnP(Processor):
    """``(points3d (N, 3) metres, points2d (N, 2) px, camera)`` to a :class:`Pose6D` whose ``score`` is
    the inlier fraction (see :func:`paz6d.backend.pnp.solve_pnp`).

    Args:
        method, ransac, refine, reprojection_threshold, seed: forwarded to ``solve_pnp``.
        class_name: written into the poses.

    Called with an optional fourth argument, ``reprojection_threshold`` (pixels) for this call.
    The camera's distortion is used.
    """

    def __init__(self, method: str = "sqpnp", ransac: bool = False, refine: bool = True,
                 reprojection_threshold: float = 8.0, seed: int = 0, class_name: str | None = None,
                 name: str | None = None):
        super().__init__(name)
        self.method, self.ransac, self.refine = method, ransac, refine
        self.reprojection_threshold, self.seed, self.class_name = reprojection_threshold, seed, class_name

    def call(self, points3d, points2d, camera: Camera, reprojection_threshold: float | None = None) -> Pose6D:
        camera = as_camera(camera)
        threshold = self.reprojection_threshold if reprojection_threshold is None else reprojection_threshold
        solution = solve_pnp(points3d, points2d, camera.K, self.method, self.ransac, camera.distortion, self.refine,
                             threshold, seed=self.seed)
        return Pose6D.from_rotation_vector(solution.rotation_vector, solution.translation, self.class_name,
                                           solution.inlier_fraction)


class SolveWeightedPnP(Processor):
    """``(points3d (N, 3) metres, points2d (N, 2) px, covariances (N, 2, 2) px², camera, reprojection_threshold)``
    to a :class:`Pose6D` whose ``score`` is the inlier fraction: RANSAC EPnP with that threshold (pixels),
    then the refinement weighted by the covariances (see :func:`paz6d.backend.pnp.solve_pnp_weighted`).

    Args:
        robust_scale: Huber knee in standard deviations (``None``: plain least squares).
        class_name: written into the poses.

    The camera's distortion is used.
    """

    def __init__(self, robust_scale: float | None = 3.0, class_name: str | None = None, name: str | None = None):
        super().__init__(name)
        self.robust_scale, self.class_name = robust_scale, class_name

    def call(self, points3d, points2d, covariances, camera: Camera, reprojection_threshold: float) -> Pose6D:
        camera = as_camera(camera)
        solution = solve_pnp_weighted(points3d, points2d, camera.K, covariances, "epnp", True, camera.distortion,
                                      reprojection_threshold, self.robust_scale)
        return Pose6D.from_rotation_vector(solution.rotation_vector, solution.translation, self.class_name,
                                           solution.inlier_fraction)


class DepthFromBox(Processor):
    """``(pose, box, camera) -> pose`` moved along its viewing ray so that the projected silhouette box
    of ``hull_points`` has the size of ``box``.

    Moving the object along the ray through its origin scales its image by ``1 / factor``; the
    factor is the mean of the width and height ratios of the projected box to ``box``, applied
    ``iterations`` times (perspective makes one step approximate). Rotation is unchanged.

    Args:
        hull_points: ``(M, 3)`` convex-hull vertices of the object (metres, model frame).
        iterations: fixed-point steps.
    """

    def __init__(self, hull_points, iterations: int = 3, name: str | None = None):
        super().__init__(name)
        self.hull_points = as_points(hull_points, "hull_points", dimension=3)
        self.iterations = int(iterations)

    def call(self, pose: Pose6D, box, camera: Camera) -> Pose6D:
        box = box if isinstance(box, Box2D) else Box2D.from_array(box)
        if box.width <= 0 or box.height <= 0:
            raise ValueError(f"box: expected positive width and height, got {box.to_array().tolist()}")
        K = as_camera(camera).K
        T = pose.to_matrix()
        for _ in range(self.iterations):
            projected = projected_box(self.hull_points, T, K)
            factor = 0.5 * ((projected[2] - projected[0]) / box.width + (projected[3] - projected[1]) / box.height)
            T[:3, 3] *= factor
        return Pose6D.from_matrix(T, pose.class_name, pose.score)
