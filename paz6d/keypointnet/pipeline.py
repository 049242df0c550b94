"""Keypoint-based 6D pose: KeypointNet keypoints in a box crop + 3D keypoints + PnP (RANSAC, LM).

:class:`KeypointPose6D` loads a KeypointNet run directory (:mod:`paz6d.keypointnet.run_dir`), crops
the square around a box, predicts the ``N`` keypoints, maps them back to image pixels and solves PnP.
It is a :class:`~paz6d.abstract.SequentialProcessor` of named steps (see its docstring) that can be
read, replaced, inserted or removed.

Example:
    >>> estimator = KeypointPose6D("runs/keypoints", camera)          # doctest: +SKIP
    >>> pose = estimator(image, (210, 140, 330, 260))                  # doctest: +SKIP
    >>> estimator.names                                                # doctest: +SKIP
    ['jitter', 'crop', 'predict', 'decode', 'to_image', 'merge_crops', 'score', 'to_keypoints2d', 'solve_pnp']
    >>> KeypointPose6D("runs/keypoints", camera, crops=13)(image, box)  # doctest: +SKIP

With ``crops > 1`` each box is cropped several times, shifted and scaled a little
(:data:`CROP_JITTERS`); the keypoints are averaged and their scatter over the crops weights PnP (the
most accurate setting, ``crops`` network inputs per object; see ``docs/keypointnet.md``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from paz6d.abstract import Box2D, KeyedStep, Keypoints2D, Pose6D, Processor, SequentialProcessor
from paz6d.backend.boxes import check_box_in_image, move_box
from paz6d.backend.camera import Camera, as_camera
from paz6d.backend.checks import as_array
from paz6d.backend.image import as_image
from paz6d.backend.pnp import PnPError
from paz6d.backend.square_crop import square_window
from paz6d.keypointnet import run_dir as run_files
from paz6d.keypointnet.config import CROP_JITTERS, check_crops
from paz6d.keypointnet.keypoints import DECODERS, decode_keypoints, keypoint_spread
from paz6d.keypointnet.run_dir import KeypointNetRunDir
from paz6d.processors.crops import CropToImage, SquareCrop
from paz6d.processors.keypoints import ToKeypoints2D
from paz6d.processors.pose import DepthFromBox, SolvePnP, SolveWeightedPnP
from paz6d.processors.predict import Predict
from paz6d.processors.refine import RefineWithDepth

#: Smallest keypoint uncertainty (crop pixels) used to weight PnP.
MIN_SIGMA = 0.5


class JitterBoxes(Processor):
    """``(images, boxes)`` lists of ``B`` -> the same repeated ``count`` times per sample (``B * count``
    entries, sample-major), the boxes moved by the first ``count`` of :data:`CROP_JITTERS`."""

    def __init__(self, count: int, name: str | None = None):
        super().__init__(name)
        self.jitters = np.asarray(CROP_JITTERS[:check_crops(count)])

    def call(self, images: list, boxes: list) -> tuple[list, list]:
        moved = []
        for box in boxes:
            moved.extend(move_box(Box2D.coordinates_of(box), self.jitters))
        return [image for image in images for _ in self.jitters], moved


class MergeCrops(Processor):
    """Keypoints of ``count`` crops per sample -> one set per sample, and how uncertain each keypoint is.

    Inputs are lists of ``B * count`` entries (sample-major): image ``points (N, 2)``, ``spread (N,)`` in
    pixels of each crop, ``windows``. Outputs are lists of ``B``: ``points`` (the crops' mean, weighted by
    ``1 / spread²``), ``spread`` (mean) and ``sigma`` (the keypoint's uncertainty, at least
    :data:`MIN_SIGMA`: the spread for one crop, the RMS scatter of the crops' keypoints around their mean
    for several), both in pixels of the sample's plain crop, and the plain crop's ``windows``.

    Args:
        count: crops per sample.
        size: side of the crops in pixels.
    """

    def __init__(self, count: int, size: int, name: str | None = None):
        super().__init__(name)
        self.count, self.size = int(count), int(size)

    def call(self, points: list, spread: list, windows: list) -> tuple[list, list, list, list]:
        merged_points, merged_spread, sigmas, plain_windows = [], [], [], []
        for start in range(0, len(points), self.count):
            sides = np.array([window[2] for window in windows[start:start + self.count]], dtype=np.float64)
            spread_plain = np.asarray(spread[start:start + self.count], np.float64) * sides[:, None] / sides[0]
            keypoints = np.asarray(points[start:start + self.count], np.float64)
            weights = 1.0 / np.maximum(spread_plain, MIN_SIGMA) ** 2
            mean = (keypoints * weights[..., None]).sum(axis=0) / weights.sum(axis=0)[:, None]
            if self.count == 1:
                sigma = spread_plain[0]
            else:  # image pixels -> pixels of the plain crop
                sigma = np.sqrt(((keypoints - mean) ** 2).sum(axis=-1).mean(axis=0) / 2.0) * self.size / sides[0]
            merged_points.append(mean)
            merged_spread.append(spread_plain.mean(axis=0))
            sigmas.append(np.maximum(sigma, MIN_SIGMA))
            plain_windows.append(windows[start])
        return merged_points, merged_spread, sigmas, plain_windows


class DecodeKeypoints(Processor):
    """KeypointNet outputs ``{"uv", "probabilities", ...}`` -> keypoints ``(B, N, 2)`` in crop pixels
    (:func:`decode_keypoints`) and their spread ``(B, N)`` in crop pixels (:func:`keypoint_spread`).

    Args:
        stride: the network's downsampling (pixels per probability-map cell).
        method: ``"local"`` or ``"global"`` (see :func:`decode_keypoints`).
    """

    def __init__(self, stride: int, method: str = "local", name: str | None = None):
        super().__init__(name)
        if method not in DECODERS:
            raise ValueError(f"decode: expected one of {DECODERS}, got {method!r}")
        self.stride, self.method = int(stride), method

    def call(self, outputs: dict) -> tuple[np.ndarray, np.ndarray]:
        uv = decode_keypoints(outputs, self.stride, self.method)
        return uv, keypoint_spread(outputs["probabilities"], uv, self.stride)


class ScoreKeypoints(Processor):
    """Keypoint spreads and uncertainties ``(N,)`` (crop pixels, :class:`MergeCrops`) -> scores ``(N,)``:
    ``1 / (1 + sigma)``, and 0 for keypoints whose 3D point is not ``usable`` or whose spread exceeds
    ``max_spread``."""

    def __init__(self, usable, max_spread: float, name: str | None = None):
        super().__init__(name)
        self.usable, self.max_spread = np.asarray(usable, dtype=bool), float(max_spread)

    def call(self, spread, sigma) -> np.ndarray:
        spread = np.asarray(spread, dtype=np.float64)
        scores = 1.0 / (1.0 + np.asarray(sigma, dtype=np.float64))
        scores[(spread > self.max_spread) | ~self.usable] = 0.0
        return scores


class KeypointPnP(Processor):
    """``(keypoints: Keypoints2D, window, camera) -> Pose6D``: PnP of the keypoints with a positive score
    against ``points_model``: RANSAC EPnP, then Levenberg–Marquardt on the reprojection error, each keypoint
    weighted by its uncertainty when ``weighted``.

    A score is ``1 / (1 + sigma)`` with ``sigma`` the keypoint's uncertainty in crop pixels
    (:class:`ScoreKeypoints`); weighted, each keypoint's pixel covariance is ``(sigma * side / input_size)² I``
    (:class:`~paz6d.processors.pose.SolveWeightedPnP`, Huber loss at 3 standard deviations).

    Args:
        points_model: ``(N, 3)`` metres, object frame, in keypoint order.
        ransac_threshold: RANSAC inlier threshold in pixels *of the crop*, scaled by ``window[2] / input_size``.
        input_size: side of the network's crops.
        min_keypoints: fewest usable keypoints accepted.
        weighted: weight the keypoints by their uncertainty (else all alike).
        class_name: written into the poses.
    Raises:
        PnPError: fewer than ``min_keypoints`` usable keypoints, or no PnP solution.
    """

    def __init__(self, points_model, ransac_threshold: float, input_size: int, min_keypoints: int = 4,
                 weighted: bool = True, class_name: str | None = None, name: str | None = None):
        super().__init__(name)
        self.points_model = as_array(points_model, "points_model", (3,))
        self.ransac_threshold, self.input_size = float(ransac_threshold), int(input_size)
        self.min_keypoints, self.weighted = int(min_keypoints), bool(weighted)
        self.solve = SolvePnP(method="epnp", ransac=True, class_name=class_name)
        self.solve_weighted = SolveWeightedPnP(class_name=class_name)

    def call(self, keypoints: Keypoints2D, window: tuple[int, int, int], camera: Camera) -> Pose6D:
        scores = np.asarray(keypoints.scores, dtype=np.float64)
        usable = scores > 0
        if usable.sum() < self.min_keypoints:
            raise PnPError(f"keypoints: only {int(usable.sum())} of {len(usable)} keypoints are usable "
                           f"(need at least {self.min_keypoints} for PnP)")
        to_image = window[2] / self.input_size
        threshold = self.ransac_threshold * to_image
        if not self.weighted:
            return self.solve(self.points_model[usable], keypoints.points[usable], camera, threshold)
        sigma = np.maximum(1.0 / scores[usable] - 1.0, MIN_SIGMA) * to_image
        return self.solve_weighted(self.points_model[usable], keypoints.points[usable],
                                   sigma[:, None, None] ** 2 * np.eye(2), camera, threshold)


class KeypointPose6D(SequentialProcessor):
    """``(image, box, *, camera=None, depth=None) -> Pose6D`` with a trained KeypointNet run and PnP.

    The steps pass a dict of per-sample lists (a batch) along; each is a
    :class:`~paz6d.abstract.KeyedStep` that reads and writes named values:

    - ``jitter``: ``images``, ``boxes`` -> ``crop_images``, ``crop_boxes``, ``crops`` entries per sample
      (:class:`JitterBoxes`);
    - ``crop``: ``crop_images``, ``crop_boxes`` -> ``crops``, ``windows``
      (:class:`~paz6d.processors.crops.SquareCrop`);
    - ``predict``: ``crops`` -> ``outputs`` (:class:`~paz6d.processors.predict.Predict`);
    - ``decode``: ``outputs`` -> ``uv``, ``spread`` (:class:`DecodeKeypoints`);
    - ``to_image``: ``uv``, ``windows`` -> ``points`` (:class:`~paz6d.processors.crops.CropToImage`);
    - ``merge_crops``: ``points``, ``spread``, ``windows`` -> ``points``, ``spread``, ``sigma``, ``windows``,
      one entry per sample (:class:`MergeCrops`);
    - ``score``: ``spread``, ``sigma`` -> ``scores`` (:class:`ScoreKeypoints`);
    - ``to_keypoints2d``: ``points``, ``scores`` -> ``keypoints`` (:class:`~paz6d.processors.keypoints.ToKeypoints2D`);
    - ``solve_pnp``: ``keypoints``, ``windows``, ``cameras`` -> ``poses`` (:class:`KeypointPnP`);
    - ``depth_from_box`` (only with ``depth_from_box=True``): ``poses``, ``boxes``, ``cameras`` -> ``poses``
      (:class:`~paz6d.processors.pose.DepthFromBox`);
    - ``refine_with_depth``: ``poses``, ``depths``, ``boxes``, ``cameras`` -> ``poses``
      (:class:`~paz6d.processors.refine.RefineWithDepth`, ICP against the depth image; a sample without one
      keeps its pose). Its model points are sampled on the run's mesh (``mesh_path`` of ``config.json``) at
      the first depth image.

    ``cameras`` holds a :class:`~paz6d.backend.camera.Camera` per image. A sample whose PnP fails
    carries its :class:`~paz6d.backend.pnp.PnPError` as its pose (raised by a call, ``None`` from
    :meth:`estimate_batch`).

    Args:
        run_dir: KeypointNet run directory (:mod:`paz6d.keypointnet.run_dir`).
        camera: default camera of the images: a :class:`~paz6d.backend.camera.Camera` or ``3×3`` ``K``
            (then each image's size completes it); a call may pass another one.
        ransac_threshold: RANSAC inlier threshold in pixels *of the crop* (scaled to the image).
        max_spread: keypoints whose probability map has a standard deviation above this many crop
            pixels are not used (default: ``input_size / 4``).
        min_keypoints: fewest usable keypoints accepted (PnP needs 4).
        decode: ``"local"`` (expectation around each map's peak, :func:`local_expectation`) or
            ``"global"`` (the network's expectation over the whole map).
        crops: crops per box (1 to 13, :data:`CROP_JITTERS`): more are more accurate (the keypoints are
            averaged and their scatter weights PnP) and take that many network inputs.
        weighted_pnp: weight each keypoint in PnP by its uncertainty (:class:`KeypointPnP`).
        depth_from_box: after PnP, move the object along its viewing ray until its projected
            silhouette box has the size of ``box2d`` (:class:`~paz6d.processors.pose.DepthFromBox`). Much
            more accurate in depth when boxes are tight (ground truth, unoccluded objects); wrong for
            occluded or truncated objects and as noisy as the detector's boxes otherwise.
        class_name: written into the returned poses.
    """

    def __init__(self, run_dir: str | Path, camera: Camera | np.ndarray | None = None, ransac_threshold: float = 5.0,
                 max_spread: float | None = None, min_keypoints: int = 4, decode: str = "local",
                 crops: int = 1, weighted_pnp: bool = True, depth_from_box: bool = False,
                 class_name: str | None = None):
        super().__init__(name="KeypointPose6D")
        from paz6d.keypointnet.model import inference_function

        self.run_dir = Path(run_dir)
        self.camera = camera
        config = KeypointNetRunDir.read_config(self.run_dir)
        self.input_size, self.margin = int(config["input_size"]), float(config["margin"])
        self.stride = int(config["downsample"])
        self.points_model, self.usable = KeypointNetRunDir.read_keypoints(self.run_dir)
        self.model = run_files.read_model(self.run_dir)
        count = int(self.model.output["uv"].shape[1])
        if count != len(self.points_model):
            raise ValueError(f"{self.run_dir / run_files.KEYPOINTS_FILE}: {len(self.points_model)} keypoints, but "
                             f"the model predicts {count}")
        if min_keypoints < 4:
            raise ValueError(f"min_keypoints: PnP needs at least 4, got {min_keypoints}")
        if self.usable.sum() < min_keypoints:
            raise PnPError(f"{self.run_dir / run_files.KEYPOINTS_FILE}: only {int(self.usable.sum())} usable "
                           f"keypoints, PnP needs at least {min_keypoints}")
        self.hull_points = run_files.read_object(self.run_dir)["hull_points"] if depth_from_box else None
        self.class_name = class_name if class_name is not None else config.get("class_name")
        max_spread = self.input_size / 4.0 if max_spread is None else float(max_spread)
        self.add(KeyedStep(JitterBoxes(crops), ("images", "boxes"), ("crop_images", "crop_boxes"), "jitter"))
        self.add(KeyedStep(SquareCrop(self.margin, self.input_size), ("crop_images", "crop_boxes"),
                           ("crops", "windows"), "crop", per_sample=True))
        self.add(KeyedStep(Predict(inference_function(self.model)), "crops", "outputs", "predict"))
        self.add(KeyedStep(DecodeKeypoints(self.stride, decode), "outputs", ("uv", "spread"), "decode"))
        self.add(KeyedStep(CropToImage(self.input_size), ("uv", "windows"), "points", "to_image", per_sample=True))
        self.add(KeyedStep(MergeCrops(crops, self.input_size), ("points", "spread", "windows"),
                           ("points", "spread", "sigma", "windows"), "merge_crops"))
        self.add(KeyedStep(ScoreKeypoints(self.usable, max_spread), ("spread", "sigma"), "scores", "score",
                           per_sample=True))
        self.add(KeyedStep(ToKeypoints2D(self.class_name), ("points", "scores"), "keypoints", "to_keypoints2d",
                           per_sample=True))
        self.add(KeyedStep(KeypointPnP(self.points_model, ransac_threshold, self.input_size, min_keypoints,
                                       weighted_pnp, self.class_name), ("keypoints", "windows", "cameras"), "poses",
                           "solve_pnp",
                           per_sample=True, failures=(PnPError,)))
        if depth_from_box:
            self.add(KeyedStep(DepthFromBox(self.hull_points), ("poses", "boxes", "cameras"), "poses",
                               "depth_from_box", per_sample=True))
        self.add(KeyedStep(RefineWithDepth(lambda: KeypointNetRunDir.surface_points(self.run_dir)),
                           ("poses", "depths", "boxes", "cameras"), "poses", "refine_with_depth", per_sample=True))

    # -- inputs ---------------------------------------------------------------------------------
    def _camera(self, camera, width: int | None = None, height: int | None = None) -> Camera:
        """The call's camera, else the constructor's, completed by the image size."""
        return as_camera(self.camera if camera is None else camera, width, height)

    def _sample(self, image, box, camera) -> tuple[np.ndarray, Box2D, Camera]:
        image = as_image(image)
        height, width = image.shape[:2]
        camera = self._camera(camera, width, height)
        box = Box2D.coerce(box)
        check_box_in_image(box.to_array(), width, height, "box2d")
        return image, box, camera

    def _values(self, images, boxes, cameras, depths=None) -> dict:
        if len(images) != len(boxes):
            raise ValueError(f"images/boxes: expected equal lengths, got {len(images)} and {len(boxes)}")
        cameras = [None] * len(images) if cameras is None else list(cameras)
        if len(cameras) != len(images):
            raise ValueError(f"cameras: expected one per image ({len(images)}), got {len(cameras)}")
        depths = [None] * len(images) if depths is None else list(depths)
        if len(depths) != len(images):
            raise ValueError(f"depths: expected one per image ({len(images)}), got {len(depths)}")
        samples = [self._sample(*sample) for sample in zip(images, boxes, cameras)]
        return {"images": [sample[0] for sample in samples], "boxes": [sample[1] for sample in samples],
                "cameras": [sample[2] for sample in samples], "depths": depths}

    # -- public API -----------------------------------------------------------------------------
    def detect_batch(self, images, boxes, cameras: Sequence | None = None) -> list[Keypoints2D]:
        """Keypoints in image pixels for each ``(image, box)`` (the steps before ``solve_pnp``); scores
        are ``1 / (1 + sigma)`` (uncertainty in crop pixels, :class:`MergeCrops`), and keypoints with an
        unusable 3D point or a spread above ``max_spread`` get score 0."""
        if len(images) == 0 and len(boxes) == 0:
            return []
        return self.run_steps(self._values(images, boxes, cameras), stop="solve_pnp")["keypoints"]

    def detect(self, image, box2d, camera=None) -> Keypoints2D:
        """Keypoints of one ``(image, box)`` (see :meth:`detect_batch`)."""
        return self.detect_batch([image], [box2d], [camera])[0]

    def pose_from_keypoints(self, keypoints: Keypoints2D, window_side: float, camera=None) -> Pose6D:
        """The ``solve_pnp`` step alone: PnP on the keypoints with a positive score.

        Args:
            window_side: side of the crop window in image pixels (scales the RANSAC threshold).
            camera: a Camera (default: the constructor's, which must then be a Camera).
        Raises:
            PnPError: fewer than ``min_keypoints`` usable keypoints, or no PnP solution.
        """
        return self["solve_pnp"].processor(keypoints, (0, 0, window_side), self._camera(camera))

    def estimate_from_keypoints(self, keypoints: Keypoints2D, box2d, camera=None) -> Pose6D:
        """The steps from ``solve_pnp`` on, for keypoints found in ``box2d``."""
        box = Box2D.coerce(box2d)
        values = {"keypoints": [keypoints], "boxes": [box], "windows": [square_window(box.to_array(), self.margin)],
                  "cameras": [self._camera(camera)], "depths": [None]}
        pose = self.run_steps(values, start="solve_pnp")["poses"][0]
        if isinstance(pose, Exception):
            raise pose
        return pose

    def estimate_batch(self, images, boxes, cameras: Sequence | None = None,
                       depths: Sequence | None = None) -> list[Pose6D | None]:
        """Poses for many ``(image, box)`` pairs with one network call; ``None`` where PnP fails.

        Args:
            depths: optional ``(H, W)`` depth image (metres, 0 = none) or ``None`` per image: ICP refinement.
        """
        if len(images) == 0 and len(boxes) == 0:
            return []
        poses = self.run_steps(self._values(images, boxes, cameras, depths))["poses"]
        return [None if isinstance(pose, Exception) else pose for pose in poses]

    @property
    def model_points(self) -> np.ndarray:
        """``(N, 3)`` points of the object (metres, model frame) to draw it under a pose: its convex hull with
        ``depth_from_box``, else its 3D keypoints."""
        return self.points_model if self.hull_points is None else self.hull_points

    def call(self, image, box, *, camera=None, depth=None) -> Pose6D:
        """Pose ``T_model2cam`` (metres) of the object inside ``box`` (``Box2D`` or ``xyxy`` pixels).

        Args:
            camera: this image's Camera or ``K`` (default: the constructor's).
            depth: optional ``(H, W)`` depth image (metres, 0 = none) registered to ``image``: the PnP pose
                is refined by ICP (open3d; kept as it is when the refinement fails its checks).
        Raises:
            PnPError: too few usable keypoints or no PnP solution.
        """
        pose = self.run_steps(self._values([image], [box], [camera], [depth]))["poses"][0]
        if isinstance(pose, Exception):
            raise pose
        return pose
