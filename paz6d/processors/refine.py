"""The depth-refinement step of the pose pipelines: :class:`RefineWithDepth` over
:class:`paz6d.backend.icp.ICPModel` (ICP with open3d against a depth image in metres).
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Sequence

import numpy as np

from paz6d.abstract.messages import Box2D, Pose6D
from paz6d.abstract.processor import Processor
from paz6d.backend.camera import Camera, as_camera
from paz6d.backend.checks import as_points, check_depth
from paz6d.backend.icp import ICPModel, ICPResult, ICPSettings


class RefineWithDepth(Processor):
    """``(candidates, depth (H, W) or None, box, camera) -> Pose6D``: without depth the first candidate as
    it is; with depth each candidate refined by :meth:`~paz6d.backend.icp.ICPModel.refine` and the accepted
    refinement with the highest agreement (then the lowest RMSE) returned, else the first candidate.

    ``candidates`` is a :class:`Pose6D` or a sequence of them (best first); the result keeps the chosen
    candidate's class name and score. :attr:`statistics` counts refinements (accepted, rejected by reason)
    and their process time.

    Args:
        model_points: ``(N, 3)`` surface points (metres, model frame), or a callable returning them that
            is called at the first refinement (e.g. to sample a mesh only when depth is given).
        diameter: the object's diameter, metres (default: the largest distance between the model points).
        settings: :class:`~paz6d.backend.icp.ICPSettings`.
    """

    def __init__(self, model_points: np.ndarray | Callable[[], np.ndarray], diameter: float | None = None,
                 settings: ICPSettings | None = None, name: str | None = None):
        super().__init__(name)
        if diameter is not None and (not np.isfinite(diameter) or diameter <= 0):
            raise ValueError(f"diameter: expected a positive length in metres, got {diameter}")
        self._model_points = model_points if callable(model_points) else as_points(model_points, "model_points")
        self._diameter, self.settings = None if diameter is None else float(diameter), settings or ICPSettings()
        self._icp_model: ICPModel | None = None
        self.statistics = {"refinements": 0, "accepted": 0, "rejected": Counter(), "seconds": 0.0}

    @property
    def model_points(self) -> np.ndarray:
        """``(N, 3)`` model points (loaded now when a callable was given)."""
        if callable(self._model_points):
            self._model_points = as_points(self._model_points(), "model_points")
        return self._model_points

    @property
    def diameter(self) -> float:
        """The object's diameter, metres (computed from :attr:`model_points` when not given)."""
        if self._diameter is None:
            from paz6d.backend.mesh import diameter  # here: paz6d.backend.mesh loads trimesh

            self._diameter = diameter(self.model_points)
        return self._diameter

    @property
    def icp_model(self) -> ICPModel:
        """The object's :class:`~paz6d.backend.icp.ICPModel` (KD-tree, point cloud), built at the first
        refinement and reused for every candidate and image."""
        if self._icp_model is None:
            self._icp_model = ICPModel(self.model_points, self.diameter)
        return self._icp_model

    def refine(self, pose: Pose6D, depth: np.ndarray, box, camera: Camera) -> ICPResult:
        """One candidate's :class:`~paz6d.backend.icp.ICPResult` (counted in :attr:`statistics`)."""
        box = Box2D.coordinates_of(box)
        started = time.process_time()
        result = self.icp_model.refine(pose.to_matrix(), depth, camera.K, box=box, settings=self.settings)
        self.statistics["seconds"] += time.process_time() - started
        self.statistics["refinements"] += 1
        if result.accepted:
            self.statistics["accepted"] += 1
        else:
            self.statistics["rejected"][result.check] += 1
        return result

    def call(self, candidates: Pose6D | Sequence[Pose6D], depth, box, camera) -> Pose6D:
        candidates = [candidates] if isinstance(candidates, Pose6D) else list(candidates)
        if not candidates:
            raise ValueError("candidates: expected at least one pose to refine")
        if depth is None:
            return candidates[0]
        camera = as_camera(camera)
        depth = check_depth(depth, shape=(camera.height, camera.width))
        best, best_key = candidates[0], None
        for candidate in candidates:
            result = self.refine(candidate, depth, box, camera)
            key = (result.agreement, -result.rmse)
            if result.accepted and (best_key is None or key > best_key):
                best_key = key
                best = Pose6D.from_matrix(result.T_model2cam, candidate.class_name, candidate.score)
        return best
