"""Keypoint-based 6D pose with uncertain keypoints: ``(image, box, camera) -> Pose6D`` by
covariance-weighted PnP.

:class:`ProbabilisticKeypointPose6D` loads a ``paz6d train probabilistic-keypoints`` run
(:mod:`paz6d.probabilistic_keypoints.run_dir`), crops the square around the box, predicts each
keypoint's mean and covariance, maps both to image pixels and solves
:func:`~paz6d.backend.pnp.solve_pnp_weighted`. Its named steps (``crop``, ``predict``, ``gaussians``,
``to_image``, ``to_keypoints2d``, ``solve_pnp``, ``refine_with_depth``) can be read, replaced, inserted
or removed.

Example:
    >>> estimator = ProbabilisticKeypointPose6D("runs/gaussian", camera)      # doctest: +SKIP
    >>> pose = estimator(image, (210, 140, 330, 260))                         # doctest: +SKIP
    >>> keypoints, covariances = estimator.detect(image, (210, 140, 330, 260))  # doctest: +SKIP
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from paz6d.abstract import Box2D, KeyedStep, Keypoints2D, Pose6D, Processor, SequentialProcessor
from paz6d.backend.camera import Camera, as_camera
from paz6d.backend.checks import as_array, check_depth
from paz6d.backend.image import as_image
from paz6d.backend.pnp import PnPError
from paz6d.probabilistic_keypoints import run_dir as run_files
from paz6d.probabilistic_keypoints.config import RANSAC_THRESHOLD, ROBUST_SCALE
from paz6d.probabilistic_keypoints.run_dir import ProbabilisticKeypointsRunDir
from paz6d.processors.crops import CropToImage, SquareCrop
from paz6d.processors.keypoints import ToKeypoints2D
from paz6d.processors.pose import SolveWeightedPnP
from paz6d.processors.predict import Predict
from paz6d.processors.refine import RefineWithDepth


class DecodeGaussians(Processor):
    """Network outputs -> means ``(B, N, 2)`` and covariances ``(B, N, 2, 2)`` in crop pixels (×
    ``covariance_scale``)."""

    def __init__(self, covariance_scale: float = 1.0, name: str | None = None):
        super().__init__(name)
        self.covariance_scale = float(covariance_scale)

    def call(self, outputs: dict) -> tuple[np.ndarray, np.ndarray]:
        cholesky = np.asarray(outputs["cholesky"], dtype=np.float64)
        covariances = self.covariance_scale * (cholesky @ np.swapaxes(cholesky, -1, -2))
        return np.asarray(outputs["uv"], dtype=np.float64), covariances


class CovariancesToImage(Processor):
    """``(covariances (N, 2, 2) crop pixels², window) -> (N, 2, 2)`` image pixels² (the crop is the window
    scaled by ``size / side``)."""

    def __init__(self, size: int, name: str | None = None):
        super().__init__(name)
        self.size = int(size)

    def call(self, covariances, window: tuple[int, int, int]) -> np.ndarray:
        return np.asarray(covariances) * (window[2] / self.size) ** 2


class WeightedPnP(Processor):
    """``(keypoints: Keypoints2D, covariances (N, 2, 2), window, camera) -> Pose6D`` by
    :class:`~paz6d.processors.pose.SolveWeightedPnP` (RANSAC threshold in crop pixels, scaled to the image).

    Args:
        points_model: ``(N, 3)`` metres, object frame, in keypoint order.
        input_size: side of the network's crops.
    """

    def __init__(self, points_model, input_size: int, ransac_threshold: float = RANSAC_THRESHOLD,
                 robust_scale: float | None = ROBUST_SCALE, class_name: str | None = None, name: str | None = None):
        super().__init__(name)
        self.points_model = as_array(points_model, "points_model", (3,))
        self.input_size, self.ransac_threshold = int(input_size), float(ransac_threshold)
        self.solve = SolveWeightedPnP(robust_scale, class_name)

    def call(self, keypoints: Keypoints2D, covariances, window: tuple[int, int, int], camera: Camera) -> Pose6D:
        threshold = self.ransac_threshold * window[2] / self.input_size
        return self.solve(self.points_model, keypoints.points, covariances, camera, threshold)


class ProbabilisticKeypointPose6D(SequentialProcessor):
    """``(image, box, *, camera=None, depth=None) -> Pose6D`` with a trained probabilistic-keypoints run.

    Steps over a dict of per-sample lists (:class:`~paz6d.abstract.KeyedStep`): ``crop`` (``images``,
    ``boxes`` -> ``crops``, ``windows``), ``predict`` (``crops`` -> ``outputs``), ``gaussians`` (``outputs``
    -> ``uv``, ``covariances_crop``), ``to_image`` (``uv``, ``windows`` -> ``points``), ``covariances_to_image``
    (``covariances_crop``, ``windows`` -> ``covariances``), ``to_keypoints2d`` (``points`` -> ``keypoints``),
    ``solve_pnp`` (``keypoints``, ``covariances``, ``windows``, ``cameras`` -> ``poses``), ``refine_with_depth``
    (``poses``, ``depths``, ``boxes``, ``cameras`` -> ``poses``: ICP against a depth image when the call gives one,
    :class:`~paz6d.processors.refine.RefineWithDepth`, on points sampled from the run's training mesh).

    Args:
        run_dir: the run directory.
        camera: default camera (a Camera, or ``3×3`` K completed by each image's size).
        robust_scale: Huber knee of the weighted refinement in standard deviations (None: least squares).
    Raises:
        ValueError: missing or corrupt run files; PnPError from a call when PnP fails.
    """

    def __init__(self, run_dir: str | Path, camera: Camera | np.ndarray | None = None,
                 robust_scale: float | None = ROBUST_SCALE, class_name: str | None = None):
        super().__init__(name="ProbabilisticKeypointPose6D")
        from paz6d.probabilistic_keypoints.model import inference_function

        self.run_dir = ProbabilisticKeypointsRunDir.validate(run_dir)
        self.camera = camera
        config = ProbabilisticKeypointsRunDir.read_config(self.run_dir)
        self.input_size, self.margin = int(config["input_size"]), float(config["margin"])
        self.points_model, self.covariance_scale = ProbabilisticKeypointsRunDir.read_keypoints(self.run_dir)
        self.model = run_files.read_model(self.run_dir)
        count = int(self.model.output["uv"].shape[1])
        if count != len(self.points_model):
            raise ValueError(f"{self.run_dir / run_files.KEYPOINTS_FILE}: {len(self.points_model)} keypoints, but "
                             f"the model predicts {count}")
        self.add(KeyedStep(SquareCrop(self.margin, self.input_size), ("images", "boxes"), ("crops", "windows"),
                           "crop", per_sample=True))
        self.add(KeyedStep(Predict(inference_function(self.model)), "crops", "outputs", "predict"))
        self.add(KeyedStep(DecodeGaussians(self.covariance_scale), "outputs", ("uv", "covariances_crop"), "gaussians"))
        self.add(KeyedStep(CropToImage(self.input_size), ("uv", "windows"), "points", "to_image", per_sample=True))
        self.add(KeyedStep(CovariancesToImage(self.input_size), ("covariances_crop", "windows"), "covariances",
                           "covariances_to_image", per_sample=True))
        self.add(KeyedStep(ToKeypoints2D(class_name), "points", "keypoints", "to_keypoints2d", per_sample=True))
        self.add(KeyedStep(WeightedPnP(self.points_model, self.input_size, robust_scale=robust_scale,
                                       class_name=class_name), ("keypoints", "covariances", "windows", "cameras"),
                           "poses", "solve_pnp", per_sample=True, failures=(PnPError,)))
        surface_points = ProbabilisticKeypointsRunDir.surface_points
        self.add(KeyedStep(RefineWithDepth(lambda: surface_points(self.run_dir)),
                           ("poses", "depths", "boxes", "cameras"), "poses", "refine_with_depth", per_sample=True))

    @property
    def model_points(self) -> np.ndarray:
        """``(N, 3)`` the run's 3D keypoints (metres, model frame), e.g. to draw the object under a pose."""
        return self.points_model

    def _values(self, image, box, camera, depth=None) -> dict:
        image = as_image(image)
        height, width = image.shape[:2]
        box = box if isinstance(box, Box2D) else Box2D.from_array(box)
        return {"images": [image], "boxes": [box],
                "cameras": [as_camera(self.camera if camera is None else camera, width, height)],
                "depths": [None if depth is None else check_depth(depth, shape=image.shape[:2])]}

    def detect(self, image, box2d, camera=None) -> tuple[Keypoints2D, np.ndarray]:
        """Keypoints (image pixels) and their covariances ``(N, 2, 2)`` (image pixels²) in ``box2d``."""
        values = self.run_steps(self._values(image, box2d, camera), stop="solve_pnp")
        return values["keypoints"][0], values["covariances"][0]

    def call(self, image, box, *, camera=None, depth=None) -> Pose6D:
        """Pose ``T_model2cam`` (metres) of the object inside ``box`` (``Box2D`` or ``xyxy`` pixels).

        Args:
            camera: this image's Camera or ``K`` (default: the constructor's).
            depth: optional ``(H, W)`` depth image (metres, 0 = none) registered to ``image``: ICP refinement.
        """
        pose = self.run_steps(self._values(image, box, camera, depth))["poses"][0]
        if isinstance(pose, Exception):
            raise pose
        return pose
