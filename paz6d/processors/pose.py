"""Pose processors over :mod:`paz6d.backend.pnp`, :mod:`paz6d.backend.camera` and
:mod:`paz6d.backend.transform`. Poses are ``T_model2cam`` (metres, OpenCV camera frame).
"""

from __future__ import annotations

import numpy as np

from paz6d.abstract.messages import Pose6D
from paz6d.abstract.processor import Processor
from paz6d.backend import keypoints as keypoints_backend
from paz6d.backend import transform
from paz6d.backend.camera import Camera
from paz6d.backend.checks import as_array
from paz6d.backend.pnp import solve_pnp


def _as_matrix(pose) -> np.ndarray:
    return pose.to_matrix() if isinstance(pose, Pose6D) else transform.as_pose_matrix(pose, "pose")


class SolvePnP(Processor):
    """``(points3d (N, 3) metres, points2d (N, 2) px)`` to a :class:`Pose6D` (see ``solve_pnp``).

    Args:
        camera: :class:`Camera` (its distortion is used) or 3×3 ``K``.
        method, ransac, refine, reprojection_threshold, seed: forwarded to ``solve_pnp``.
    """

    def __init__(self, camera: Camera | np.ndarray, method: str = "sqpnp", ransac: bool = False,
                 refine: bool = True, reprojection_threshold: float = 8.0, seed: int = 0,
                 class_name: str | None = None, name: str | None = None):
        super().__init__(name)
        self.camera = camera
        self.method, self.ransac, self.refine = method, ransac, refine
        self.reprojection_threshold, self.seed, self.class_name = reprojection_threshold, seed, class_name

    def call(self, points3d, points2d) -> Pose6D:
        K, distortion = ((self.camera.K, self.camera.distortion) if isinstance(self.camera, Camera)
                         else (self.camera, None))
        return solve_pnp(points3d, points2d, K, self.method, self.ransac, distortion, self.refine,
                         self.reprojection_threshold, seed=self.seed, class_name=self.class_name)


class ProjectPoints(Processor):
    """Projects ``(N, 3)`` points to ``(N, 2)`` pixels; called as ``(points)`` for camera-frame
    points or ``(points, pose)`` with a :class:`Pose6D` or ``(4, 4)`` ``T_model2cam``."""

    def __init__(self, camera: Camera | np.ndarray, name: str | None = None):
        super().__init__(name)
        self.camera = camera

    def call(self, points, pose=None) -> np.ndarray:
        return keypoints_backend.project(points, self.camera, None if pose is None else _as_matrix(pose))


class TransformPoints(Processor):
    """Applies a pose (``Pose6D`` or ``(4, 4)``) to ``(N, 3)`` points: called as ``(points, pose)``."""

    def call(self, points, pose) -> np.ndarray:
        return transform.apply(_as_matrix(pose), points)


class ToPose6D(Processor):
    """Builds a :class:`Pose6D` from common pose encodings.

    Accepts a ``Pose6D`` (returned with ``class_name``/``score`` replaced when given), a ``(4, 4)``
    matrix, a ``(7,)`` array ``[qx, qy, qz, qw, tx, ty, tz]``, or a pair ``(rotation, translation)``
    whose rotation is a ``(3, 3)`` matrix, a ``(4,)`` quaternion or a ``(3,)`` rotation vector.
    """

    def __init__(self, class_name: str | None = None, score: float | None = None, name: str | None = None):
        super().__init__(name)
        self.class_name, self.score = class_name, score

    def call(self, pose) -> Pose6D:
        class_name, score = self.class_name, self.score
        if isinstance(pose, Pose6D):
            return Pose6D(pose.quaternion, pose.translation, class_name or pose.class_name,
                          pose.score if score is None else score)
        score = 1.0 if score is None else score
        if isinstance(pose, tuple) and len(pose) == 2:
            rotation = np.asarray(pose[0], dtype=np.float64)
            if rotation.shape == (3, 3):
                return Pose6D.from_rotation_matrix(rotation, pose[1], class_name, score)
            if rotation.shape == (4,):
                return Pose6D(rotation, pose[1], class_name, score)
            if rotation.shape == (3,):
                return Pose6D.from_rotation_vector(rotation, pose[1], class_name, score)
            raise ValueError(f"pose[0]: expected a (3, 3) matrix, (4,) quaternion or (3,) rotation vector, "
                             f"got shape {rotation.shape}")
        values = np.asarray(pose, dtype=np.float64)
        if values.shape == (4, 4):
            return Pose6D.from_matrix(transform.as_pose_matrix(values, "pose"), class_name, score)
        if values.shape == (7,):
            return Pose6D.from_array(values, class_name, score)
        raise ValueError(f"pose: expected Pose6D, (4, 4), (7,) or (rotation, translation), got shape {values.shape}")


class PoseToMatrix(Processor):
    """:class:`Pose6D` to its ``(4, 4)`` ``T_model2cam``."""

    def call(self, pose: Pose6D) -> np.ndarray:
        if not isinstance(pose, Pose6D):
            raise ValueError(f"pose: expected a Pose6D, got {type(pose).__name__}")
        return pose.to_matrix()


class PoseFromKeypoints(Processor):
    """Pose from detected 2D keypoints of known 3D model points (PnP on a fixed model).

    Args:
        model_points: ``(N, 3)`` model-frame points (metres) matching the keypoint order.
        camera: :class:`Camera` or ``K``.
    Called as ``(keypoints (N, 2))``.
    """

    def __init__(self, model_points, camera: Camera | np.ndarray, method: str = "sqpnp", ransac: bool = False,
                 class_name: str | None = None, name: str | None = None):
        super().__init__(name)
        self.model_points = as_array(model_points, "model_points", (3,))
        self.solve = SolvePnP(camera, method=method, ransac=ransac, class_name=class_name)

    def call(self, keypoints) -> Pose6D:
        return self.solve(self.model_points, keypoints)
