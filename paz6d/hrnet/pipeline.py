"""2D keypoints with an HRNet, and 6D pose from them with PnP.

:class:`HRNetKeypoints2D` loads an HRNet run directory (:mod:`paz6d.hrnet.run_dir`) and maps
``(image, box) -> Keypoints2D`` (image pixels) with named steps: ``crop`` (the square window of
``margin`` × the box's longer side, resampled to the network's input), ``predict`` (heatmaps),
``decode`` (heatmaps to crop pixels with sub-pixel refinement, :func:`paz6d.hrnet.heatmaps.decode_heatmaps`),
``to_image`` (crop pixels back to image pixels) and ``to_keypoints2d``. :class:`HRNetPose6D` adds
``solve_pnp``: RANSAC PnP of those keypoints against the 3D keypoints the network was trained on, and
``refine_with_depth`` (ICP, when a call gives a depth image).

Example:
    >>> detector = HRNetKeypoints2D("runs/hrnet")                     # doctest: +SKIP
    >>> keypoints = detector(image, (210, 140, 330, 260))             # doctest: +SKIP
    >>> detector.names                                                 # doctest: +SKIP
    ['crop', 'predict', 'decode', 'to_image', 'to_keypoints2d']
    >>> pose = HRNetPose6D("runs/hrnet", camera)(image, box)          # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from paz6d.abstract import Box2D, KeyedStep, Keypoints2D, Pose6D, Processor, SequentialProcessor
from paz6d.backend.boxes import check_box_in_image
from paz6d.backend.camera import Camera, as_camera
from paz6d.backend.checks import check_depth
from paz6d.backend.image import as_image
from paz6d.backend.pnp import PnPError
from paz6d.hrnet import run_dir as run_files
from paz6d.hrnet.heatmaps import DECODERS, DEFAULT_DECODER, decode_heatmaps
from paz6d.hrnet.run_dir import HRNetRunDir
from paz6d.keypointnet.pipeline import KeypointPnP
from paz6d.processors.crops import CropToImage, SquareCrop
from paz6d.processors.keypoints import ToKeypoints2D
from paz6d.processors.predict import Predict
from paz6d.processors.refine import RefineWithDepth


class DecodeHeatmaps(Processor):
    """Heatmaps ``(B, h, w, N)`` -> keypoints ``(B, N, 2)`` in crop pixels and scores ``(B, N)``
    (:func:`~paz6d.hrnet.heatmaps.decode_heatmaps`).

    Args:
        stride: crop pixels per heatmap cell.
        domain: ``"log"`` (softmax logits) or ``"value"`` (Gaussians of peak 1).
        method: one of :data:`~paz6d.hrnet.heatmaps.DECODERS`.
        sigma: the training Gaussian's width in cells (scales log-domain scores to about 1 at best).
    """

    def __init__(self, stride: int, domain: str, method: str = DEFAULT_DECODER, sigma: float | None = None,
                 name: str | None = None):
        super().__init__(name)
        if method not in DECODERS:
            raise ValueError(f"decode: expected one of {DECODERS}, got {method!r}")
        if domain not in run_files.DOMAINS:
            raise ValueError(f"domain: expected one of {run_files.DOMAINS}, got {domain!r}")
        self.stride, self.domain, self.method, self.sigma = int(stride), domain, method, sigma

    def call(self, heatmaps) -> tuple[np.ndarray, np.ndarray]:
        return decode_heatmaps(heatmaps, self.stride, self.method, self.domain, self.sigma)


class HRNetKeypoints2D(SequentialProcessor):
    """``(image, box2d) -> Keypoints2D``: the object's ``N`` keypoints in image pixels, with scores.

    The steps pass a dict of per-sample lists (a batch); each is a :class:`~paz6d.abstract.KeyedStep`:

    - ``crop``: ``images``, ``boxes`` -> ``crops``, ``windows`` (:class:`~paz6d.processors.crops.SquareCrop`);
    - ``predict``: ``crops`` -> ``heatmaps`` (:class:`~paz6d.processors.predict.Predict`);
    - ``decode``: ``heatmaps`` -> ``uv`` (crop pixels), ``scores`` (:class:`DecodeHeatmaps`);
    - ``to_image``: ``uv``, ``windows`` -> ``points`` (:class:`~paz6d.processors.crops.CropToImage`);
    - ``to_keypoints2d``: ``points``, ``scores`` -> ``keypoints`` (:class:`~paz6d.processors.keypoints.ToKeypoints2D`).

    Args:
        run_dir: HRNet run directory.
        decode: heatmap decoder (default ``"soft_argmax"``: expectation over the 5×5 cells around the peak;
            ``"quadratic"``: peak + Newton step on the log-map; see :mod:`paz6d.hrnet.heatmaps`).
        batch_size: crops per network call.
        class_name: written into the messages (default: the run's ``class_name``).
    Raises:
        ValueError: the run directory is missing a file or a file is malformed (named in the message).
    """

    def __init__(self, run_dir: str | Path, decode: str = DEFAULT_DECODER, batch_size: int = 32,
                 class_name: str | None = None, name: str = "HRNetKeypoints2D"):
        super().__init__(name=name)
        from paz6d.hrnet.model import inference_function

        self.run_dir = Path(run_dir)
        description = HRNetRunDir.validate(self.run_dir)
        self.input_size, self.margin = int(description["input_size"]), float(description["margin"])
        self.stride, self.points_model = int(description["stride"]), description["points_model"]
        self.model = run_files.read_model(self.run_dir, description)
        self.class_name = class_name if class_name is not None else description.get("class_name")
        self.add(KeyedStep(SquareCrop(self.margin, self.input_size), ("images", "boxes"), ("crops", "windows"),
                           "crop", per_sample=True))
        self.add(KeyedStep(Predict(inference_function(self.model), batch_size), "crops", "heatmaps", "predict"))
        self.add(KeyedStep(DecodeHeatmaps(self.stride, description["domain"], decode, description["sigma"]),
                           "heatmaps", ("uv", "scores"), "decode"))
        self.add(KeyedStep(CropToImage(self.input_size), ("uv", "windows"), "points", "to_image", per_sample=True))
        self.add(KeyedStep(ToKeypoints2D(self.class_name), ("points", "scores"), "keypoints", "to_keypoints2d",
                           per_sample=True))

    def _sample(self, image, box) -> tuple[np.ndarray, Box2D]:
        image = as_image(image)
        box = Box2D.coerce(box)
        check_box_in_image(box.to_array(), image.shape[1], image.shape[0], "box2d")
        return image, box

    def _values(self, images, boxes) -> dict:
        if len(images) != len(boxes):
            raise ValueError(f"images/boxes: expected equal lengths, got {len(images)} and {len(boxes)}")
        samples = [self._sample(image, box) for image, box in zip(images, boxes)]
        return {"images": [sample[0] for sample in samples], "boxes": [sample[1] for sample in samples]}

    def detect_batch(self, images, boxes) -> list[Keypoints2D]:
        """Keypoints (image pixels) for each ``(image, box)``, with one network call per ``batch_size`` crops."""
        if len(images) == 0 and len(boxes) == 0:
            return []
        return self.run_steps(self._values(images, boxes), stop=self._after_keypoints())["keypoints"]

    def _after_keypoints(self) -> str | None:
        names = self.names
        index = names.index("to_keypoints2d") + 1
        return names[index] if index < len(names) else None

    def call(self, image, box2d) -> Keypoints2D:
        """Keypoints ``(N, 2)`` in image pixels of the object inside ``box2d`` (``Box2D`` or ``xyxy`` pixels)."""
        return self.detect_batch([image], [box2d])[0]


class HRNetPose6D(HRNetKeypoints2D):
    """``(image, box, *, camera=None, depth=None) -> Pose6D``: :class:`HRNetKeypoints2D` + ``solve_pnp``
    (RANSAC EPnP then Levenberg–Marquardt, :class:`~paz6d.keypointnet.pipeline.KeypointPnP`) against the run's
    3D keypoints + ``refine_with_depth`` (:class:`~paz6d.processors.refine.RefineWithDepth`: ICP against a
    depth image when the call gives one, on points sampled from the run's training mesh; without one the
    PnP pose as it is).

    Args:
        run_dir: HRNet run directory.
        camera: default camera (a :class:`~paz6d.backend.camera.Camera` or ``3×3`` ``K``, completed by
            each image's size); a call may pass another one.
        ransac_threshold: RANSAC inlier threshold in pixels *of the crop* (scaled to the image).
        decode, batch_size, class_name: as :class:`HRNetKeypoints2D`.
    Raises:
        PnPError (a ``ValueError``): from a call, when PnP finds no pose.
    """

    def __init__(self, run_dir: str | Path, camera: Camera | np.ndarray | None = None, ransac_threshold: float = 5.0,
                 decode: str = DEFAULT_DECODER, batch_size: int = 32, class_name: str | None = None):
        super().__init__(run_dir, decode, batch_size, class_name, name="HRNetPose6D")
        self.camera = camera
        self.add(KeyedStep(KeypointPnP(self.points_model, ransac_threshold, self.input_size, 4, self.class_name),
                           ("keypoints", "windows", "cameras"), "poses", "solve_pnp", per_sample=True,
                           failures=(PnPError,)))
        self.add(KeyedStep(RefineWithDepth(lambda: HRNetRunDir.surface_points(self.run_dir)),
                           ("poses", "depths", "boxes", "cameras"), "poses", "refine_with_depth", per_sample=True))

    @property
    def model_points(self) -> np.ndarray:
        """``(N, 3)`` the run's 3D keypoints (metres, model frame), e.g. to draw the object under a pose."""
        return self.points_model

    def _poses(self, images, boxes, cameras, depths=None) -> list:
        values = self._values(images, boxes)
        cameras = [None] * len(images) if cameras is None else list(cameras)
        depths = [None] * len(images) if depths is None else list(depths)
        if len(cameras) != len(images) or len(depths) != len(images):
            raise ValueError(f"cameras/depths: expected one per image ({len(images)}), got {len(cameras)} and "
                             f"{len(depths)}")
        values["cameras"] = [as_camera(self.camera if camera is None else camera, image.shape[1], image.shape[0])
                             for image, camera in zip(values["images"], cameras)]
        values["depths"] = [None if depth is None else check_depth(depth, shape=image.shape[:2])
                            for image, depth in zip(values["images"], depths)]
        return self.run_steps(values)["poses"]

    def estimate_batch(self, images, boxes, cameras: Sequence | None = None,
                       depths: Sequence | None = None) -> list[Pose6D | None]:
        """Poses for many ``(image, box)`` pairs; ``None`` where PnP fails (``depths``: optional ``(H, W)``
        metres or ``None`` per image, for ICP refinement)."""
        if len(images) == 0 and len(boxes) == 0:
            return []
        return [None if isinstance(pose, Exception) else pose
                for pose in self._poses(images, boxes, cameras, depths)]

    def call(self, image, box, *, camera=None, depth=None) -> Pose6D:
        """Pose ``T_model2cam`` (metres) of the object inside ``box`` (``Box2D`` or ``xyxy`` pixels).

        Args:
            camera: this image's Camera or ``K`` (default: the constructor's).
            depth: optional ``(H, W)`` depth image (metres, 0 = none) registered to ``image``: ICP refinement.
        Raises:
            PnPError: no PnP solution.
        """
        pose = self._poses([image], [box], [camera], [depth])[0]
        if isinstance(pose, Exception):
            raise pose
        return pose
