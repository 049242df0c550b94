"""From a whole image to 6D poses: detect -> crop -> pose, ``DetectAndEstimatePose6D``.

A detector (``image -> list[Box2D]`` with class names, e.g. :class:`paz6d.ssd.pipeline.DetectSingleShot`)
finds the objects; every box whose class has a pose model goes to that model
(the pipeline of a pose method of :mod:`paz6d.methods`, ``pipeline(image, box, *, camera=None, depth=None)
-> Pose6D``, or any callable ``(image, box, camera=...) -> Pose6D``) with the image's camera::

    from paz6d.pipelines import DetectAndEstimatePose6D
    pipeline = DetectAndEstimatePose6D.from_run_dirs("runs/ssd", {5: "runs/aae_5", 8: "runs/kp_8"}, K)
    for box, pose in pipeline(image):          # image (H, W, 3) uint8 RGB
        print(box.class_name, box.score, pose.translation)   # metres, T_model2cam (OpenCV camera frame)
    overlay = pipeline.draw(image, pipeline(image))

Policy for a detected class that has no pose model: skipped with a :class:`MissingPoseModelWarning`
(default), or a ``ValueError`` with ``strict=True``. A pose model that fails on one box (e.g. PnP with too
few keypoints, a ``ValueError``) skips that box the same way. An image whose size does not match a given
:class:`~paz6d.backend.camera.Camera` raises ``ValueError``.
"""

from __future__ import annotations

import re
import warnings
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from paz6d.abstract import Box2D, KeyedStep, Pose6D, Processor, SequentialProcessor
from paz6d.backend.camera import Camera, as_camera
from paz6d.backend.draw import draw_box, draw_model_outline, draw_pose_axes, draw_projected_points, keypoint_colors
from paz6d.backend.checks import check_depth
from paz6d.backend.image import as_image
from paz6d.backend.viewpoints import ViewpointRange
from paz6d.methods import method_of, methods
from paz6d.processors.crops import BoxVariants

_BOP_CLASS = re.compile(r"^obj_(\d+)$")


class MissingPoseModelWarning(UserWarning):
    """A detected class has no pose model (or its pose model failed on a box); the box was skipped."""


def class_name_of(key: str | int) -> str:
    """The detector class name of an estimator key: a BOP object id ``5`` -> ``"obj_000005"``; a name as is.

    Raises:
        ValueError: a negative/zero id, an empty name or another type.
    """
    if isinstance(key, (int, np.integer)) and not isinstance(key, bool):
        if key < 1:
            raise ValueError(f"estimators: expected positive BOP object ids as keys, got {key}")
        return f"obj_{int(key):06d}"
    if isinstance(key, str) and key:
        return key
    raise ValueError(f"estimators: expected class names (str) or BOP object ids (int) as keys, got {key!r}")


def bop_object_id(class_name: str) -> int | None:
    """The BOP object id of an ``obj_XXXXXX`` class name, ``None`` for other names."""
    match = _BOP_CLASS.match(str(class_name))
    return int(match.group(1)) if match else None


def load_pose_estimator(run_dir: str | Path, camera=None, class_name: str | None = None, keypoint_crops: int = 1,
                        box_variants: BoxVariants | None = None, viewpoints: ViewpointRange | None = None):
    """The pose pipeline of a run directory, its method found by :func:`paz6d.methods.method_of`. The
    options go to the methods that take them (:attr:`paz6d.method.Method.options`): ``keypoint_crops``
    (KeypointNet's crops per box), ``box_variants`` (a :class:`~paz6d.processors.crops.BoxVariants`) and
    ``viewpoints`` (a :class:`~paz6d.backend.viewpoints.ViewpointRange`, the AAE's).

    Returns:
        ``(method name, pipeline)``, the pipeline a ``pipeline(image, box, *, camera=None, depth=None) -> Pose6D``.
    Raises:
        ValueError: not a directory, not a pose run directory (an SSD one, say) or a corrupt one (naming the file).
    """
    method = method_of(run_dir)
    if method.task != "pose":
        names = " or ".join(pose.name for pose in methods("pose"))
        raise ValueError(f"run_dir: {run_dir} is a {method.name} run directory, not a pose model ({names})")
    return method.name, method.load(run_dir, camera=camera, class_name=class_name, keypoint_crops=keypoint_crops,
                                    box_variants=box_variants, viewpoints=viewpoints)


def load_detector(run_dir: str | Path, score_threshold: float = 0.3, flip: bool = False,
                  vote_iou: float | None = None):
    """The detector pipeline (``image -> [Box2D]`` with class names) of a run directory of a detection method
    (:func:`paz6d.methods.method_of`); ``flip``: it also sees the mirror image; ``vote_iou``: box voting
    (``DetectSingleShot``'s).

    Raises:
        ValueError: not a directory, not a detector's run directory or a corrupt one (naming the file).
    """
    method = method_of(run_dir)
    if method.task != "detection":
        names = " or ".join(detector.name for detector in methods("detection"))
        raise ValueError(f"detector: {run_dir} is a {method.name} run directory, not a detector ({names})")
    return method.load(run_dir, score_threshold=score_threshold, flip=flip, vote_iou=vote_iou)


def run_mesh(run_dir: str | Path) -> tuple[Path, float] | None:
    """``(mesh file, scale to metres)`` a run directory was trained on, ``None`` when not recorded."""
    return method_of(run_dir).run_dir.training_mesh(run_dir)


# ------------------------------------------------------------------------------------------ steps
class ImageCamera(Processor):
    """``(image, camera) -> (image, Camera)``: checks an RGB ``uint8`` ``(H, W, 3)`` image and completes the
    camera (a 3x3 ``K`` takes the image's size; a :class:`Camera` must have it).

    Args:
        default: the camera used when the call gives none.
    Raises:
        ValueError: not an RGB image; no camera; a Camera of another size than the image.
    """

    def __init__(self, default=None, name: str | None = None):
        super().__init__(name)
        self.default = default

    def call(self, image, camera=None) -> tuple[np.ndarray, Camera]:
        image = as_image(image, "image", channels=3)
        return image, as_camera(self.default if camera is None else camera, image.shape[1], image.shape[0])


class SelectBoxes(Processor):
    """``detections [Box2D] -> boxes [Box2D]`` with a pose model, in detection order.

    Args:
        class_names: the classes that have a pose model.
        strict: a detection of another class raises ``ValueError`` instead of a
            :class:`MissingPoseModelWarning` and skipping it.
    """

    def __init__(self, class_names, strict: bool = False, name: str | None = None):
        super().__init__(name)
        self.class_names, self.strict = tuple(class_names), bool(strict)

    def call(self, detections) -> list[Box2D]:
        kept = []
        for box in detections:
            if box.class_name in self.class_names:
                kept.append(box)
                continue
            message = (f"detections: class {box.class_name!r} has no pose model (pose models: "
                       f"{list(self.class_names)}); box {[round(v, 1) for v in box.to_array().tolist()]} skipped")
            if self.strict:
                raise ValueError(message.replace("skipped", "found (strict=True)"))
            warnings.warn(message, MissingPoseModelWarning, stacklevel=2)
        return kept


class KeepTopPerClass(Processor):
    """``boxes [Box2D] -> (kept [Box2D], left_out [Box2D])``: the ``count`` highest-scoring boxes of each class
    (in their input order; equal scores keep the earlier box) and the others.

    For scenes where each object appears at most ``count`` times (LM-O: once), the left-out detections cannot
    be scored anyway (BOP keeps an object's best ``count`` estimates); skipping them saves their pose models.

    Args:
        count: boxes kept per class, at least 1.
    """

    def __init__(self, count: int, name: str | None = None):
        super().__init__(name)
        if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
            raise ValueError(f"poses_per_class: expected a whole number >= 1, got {count!r}")
        self.count = int(count)

    def call(self, boxes) -> tuple[list[Box2D], list[Box2D]]:
        taken, kept = Counter(), set()
        for index in sorted(range(len(boxes)), key=lambda index: -boxes[index].score):  # stable: ties keep order
            if taken[boxes[index].class_name] < self.count:
                taken[boxes[index].class_name] += 1
                kept.add(index)
        return ([box for index, box in enumerate(boxes) if index in kept],
                [box for index, box in enumerate(boxes) if index not in kept])


class EstimatePoses(Processor):
    """``(image, boxes [Box2D], camera, depth=None) -> poses [Pose6D | None]``: each box's pose model on the
    image, one pose per box (class name = the box's); ``None`` where the model raised ``ValueError`` (warned,
    or raised with ``strict``). A depth image (``(H, W)`` metres, the image's size) is passed on to every
    model as ``depth=`` (ICP refinement).

    Args:
        estimators: class name -> callable ``(image, box, camera=...) -> Pose6D``.
    """

    def __init__(self, estimators: Mapping[str, Callable], strict: bool = False, name: str | None = None):
        super().__init__(name)
        self.estimators, self.strict = dict(estimators), bool(strict)

    def call(self, image, boxes, camera, depth=None) -> list[Pose6D | None]:
        extra = {}  # depth only when given: a plain callable (image, box, camera=...) needs no depth argument
        if depth is not None:
            extra["depth"] = check_depth(depth, shape=image.shape[:2])
        poses = []
        for box in boxes:
            try:
                pose = self.estimators[box.class_name](image, box, camera=camera, **extra)
            except ValueError as error:
                if self.strict:
                    raise
                warnings.warn(f"pose model of {box.class_name!r} failed on box "
                              f"{[round(v, 1) for v in box.to_array().tolist()]}: {error}; skipped",
                              MissingPoseModelWarning, stacklevel=2)
                poses.append(None)
                continue
            poses.append(Pose6D(pose.quaternion, pose.translation, box.class_name, pose.score))
        return poses


class VerifyBoxes(Processor):
    """``(boxes [Box2D], poses [Pose6D | None]) -> boxes``: each box's score times its pose's score clipped to
    [0, 1], so that a detection its pose model does not recognise ranks lower. The AAE's pose score is the
    cosine similarity of the crop's code to its codebook match; a pose without a score (1) or a failed pose
    (``None``) leaves the box's score as it is."""

    def call(self, boxes, poses) -> list[Box2D]:
        return [box if pose is None else replace(box, score=box.score * min(max(pose.score, 0.0), 1.0))
                for box, pose in zip(boxes, poses)]


def pair_boxes_and_poses(boxes, poses) -> list[tuple[Box2D, Pose6D]]:
    """``[(box, pose)]`` for the boxes whose pose was found."""
    return [(box, pose) for box, pose in zip(boxes, poses) if pose is not None]


# ------------------------------------------------------------------------------------------ pipeline
class DetectAndEstimatePose6D(SequentialProcessor):
    """``image (H, W, 3) uint8 RGB [, camera] -> [(Box2D, Pose6D)]``: a detector, then one pose model per class.

    Steps (each a :class:`~paz6d.abstract.KeyedStep` over a dict of named values):

    ==============  ================================  ===============  ========================
    step            reads                             writes           processor
    ==============  ================================  ===============  ========================
    ``check``       ``image``, ``camera``             ``image``,       :class:`ImageCamera`
                                                      ``camera``
    ``detect``      ``image``                         ``detections``   the detector
    ``select``      ``detections``                    ``boxes``        :class:`SelectBoxes`
    ``top``         ``boxes``                         ``boxes``,       :class:`KeepTopPerClass` (only
                                                      ``left_out``     with ``poses_per_class``)
    ``estimate``    ``image``, ``boxes``, ``camera``, ``poses``        :class:`EstimatePoses`
                    ``depth`` (``None``: no ICP)
    ``verify``      ``boxes``, ``poses``              ``boxes``        :class:`VerifyBoxes` (only
                                                                       with ``verify=True``)
    ``pair``        ``boxes``, ``poses``              ``results``      :func:`pair_boxes_and_poses`
    ==============  ================================  ===============  ========================

    Poses are ``T_model2cam`` in metres (OpenCV camera frame), their ``class_name`` the detection's.

    Args:
        detector: ``image -> list[Box2D]`` with class names (e.g. ``DetectSingleShot``).
        estimators: class name (``"obj_000005"``) or BOP object id (``5``) -> pose pipeline
            ``(image, box, camera=...) -> Pose6D``.
        camera: default :class:`Camera` or ``3x3`` ``K`` of the images (a call may give another).
        strict: raise ``ValueError`` for a detected class without a pose model, or a pose model failing on a
            box, instead of warning (:class:`MissingPoseModelWarning`) and skipping the box.
        meshes: optional class -> ``(vertices (V, 3) metres, faces (F, 3))`` for :meth:`draw`'s outlines
            (default: the estimators' surface points, drawn as dots).
        verify: multiply each box's score by its pose's score (:class:`VerifyBoxes`): measured on the real
            LM-O frames, it ranks the detector's false positives lower (docs/real_photos.md).
        poses_per_class: estimate poses only for this many highest-scoring detections of each class per image
            (:class:`KeepTopPerClass`; the others are in ``left_out``); ``None``: every detection. Not with
            ``verify``, which re-ranks every detection by its pose.
    Raises:
        ValueError: no estimators, a bad key, a class the detector cannot output (when it lists
            ``class_names``), or ``verify`` with ``poses_per_class``.
    """

    def __init__(self, detector: Callable, estimators: Mapping[str | int, Callable], camera=None,
                 strict: bool = False, meshes: Mapping[str | int, tuple] | None = None, verify: bool = False,
                 poses_per_class: int | None = None):
        super().__init__(name="DetectAndEstimatePose6D")
        if not callable(detector):
            raise ValueError(f"detector: expected a callable image -> [Box2D], got {type(detector).__name__}")
        if not estimators:
            raise ValueError("estimators: expected at least one pose model (class name or BOP id -> pipeline)")
        if verify and poses_per_class is not None:
            raise ValueError("verify: not with poses_per_class (verify re-ranks every detection by its pose's score, "
                             "so every detection needs a pose)")
        named: dict[str, Callable] = {}
        for key, estimator in estimators.items():
            name = class_name_of(key)
            if name in named:
                raise ValueError(f"estimators: class {name!r} given twice (as a name and as an id?)")
            if not callable(estimator):
                raise ValueError(f"estimators[{key!r}]: expected a pose pipeline, got {type(estimator).__name__}")
            named[name] = estimator
        known = getattr(detector, "class_names", None)
        if known is not None:
            unknown = sorted(set(named) - set(known))
            if unknown:
                raise ValueError(f"estimators: classes {unknown} are not among the detector's classes {list(known)}")
        self.detector, self.estimators, self.camera = detector, named, camera
        self.meshes = {class_name_of(key): value for key, value in (meshes or {}).items()}
        self.add(KeyedStep(ImageCamera(camera), ("image", "camera"), ("image", "camera"), name="check"))
        self.add(KeyedStep(detector, "image", "detections", name="detect"))
        self.add(KeyedStep(SelectBoxes(tuple(named), strict), "detections", "boxes", name="select"))
        if poses_per_class is not None:
            self.add(KeyedStep(KeepTopPerClass(poses_per_class), "boxes", ("boxes", "left_out"), name="top"))
        self.add(KeyedStep(EstimatePoses(named, strict), ("image", "boxes", "camera", "depth"), "poses",
                           name="estimate"))
        if verify:
            self.add(KeyedStep(VerifyBoxes(), ("boxes", "poses"), "boxes", name="verify"))
        self.add(KeyedStep(pair_boxes_and_poses, ("boxes", "poses"), "results", name="pair"))

    @classmethod
    def from_run_dirs(cls, detector_dir: str | Path, pose_dirs: Mapping[str | int, str | Path], camera=None,
                      score_threshold: float = 0.3, strict: bool = False, load_meshes: bool = True,
                      verify: bool = False, flip: bool = False, box_variants: BoxVariants | None = None,
                      poses_per_class: int | None = None, viewpoints: ViewpointRange | None = None,
                      vote_iou: float | None = None) -> "DetectAndEstimatePose6D":
        """Loads a detector run (an SSD's) and one pose run directory per class (methods found by themselves).

        Args:
            detector_dir: SSD run directory (``paz6d train ssd``).
            pose_dirs: class name or BOP object id -> run directory of a pose method (``paz6d.methods``).
            load_meshes: load each pose run's mesh (when its file still exists) for :meth:`draw`.
            flip: the detector also sees the mirror image (``DetectSingleShot``'s ``flip``).
            box_variants: the AAE runs choose among these copies of each detected box
                (:class:`~paz6d.processors.crops.BoxVariants`, ``ImplicitPose6D``'s ``box_variants``).
            poses_per_class: poses only for each class's best detections (see the class).
            viewpoints: the AAE runs answer only with views in this range (``ImplicitPose6D``'s ``viewpoints``).
            vote_iou: the detector's box voting (``DetectSingleShot``'s ``vote_iou``; ``None``: off).
        """
        estimators, meshes = {}, {}
        for key, run_dir in pose_dirs.items():
            name = class_name_of(key)
            estimators[name] = load_pose_estimator(run_dir, camera, class_name=name, box_variants=box_variants,
                                                   viewpoints=viewpoints)[1]
            found = run_mesh(run_dir) if load_meshes else None
            if found is not None and found[0].is_file():
                from paz6d.backend.mesh import load_mesh  # trimesh, only when outlines are wanted

                mesh = load_mesh(found[0], found[1])
                meshes[name] = (np.asarray(mesh.vertices), np.asarray(mesh.faces))
        detector = load_detector(detector_dir, score_threshold, flip, vote_iou)
        return cls(detector, estimators, camera, strict, meshes, verify, poses_per_class)

    def run(self, image, camera=None, depth=None) -> dict:
        """All named values of one image (``detections``, ``boxes``, ``poses``, ``results``...)."""
        return self.run_steps({"image": image, "camera": camera, "depth": depth})

    def call(self, image, camera=None, depth=None) -> list[tuple[Box2D, Pose6D]]:
        """``[(box, pose)]`` for every detected object that has a pose model, in detection order.

        Args:
            image: ``(H, W, 3)`` uint8 RGB.
            camera: this image's Camera or ``K`` (default: the constructor's).
            depth: optional ``(H, W)`` depth image (metres, 0 = none) registered to ``image``: each pose
                model refines its pose by ICP (:class:`~paz6d.processors.refine.RefineWithDepth`).
        """
        return self.run(image, camera, depth)["results"]

    def _model_points(self, class_name: str) -> np.ndarray | None:
        """The ``model_points`` ``(N, 3)`` of a class's pose pipeline (``None`` for a callable without them)."""
        points = getattr(self.estimators.get(class_name), "model_points", None)
        return None if points is None else np.asarray(points)

    def draw(self, image, results, camera=None, axis_length: float | None = None) -> np.ndarray:
        """A copy of ``image`` with each result's box (class name, score), the model's outline under its
        pose (the silhouette contour of its mesh, or its surface points) and the pose's axes.

        Args:
            results: what a call returned, ``[(Box2D, Pose6D)]``.
            camera: the image's Camera or ``K`` (default: the constructor's).
            axis_length: metres (default: half the model's extent, else 5 cm).
        """
        image, camera = ImageCamera(self.camera)(image, camera)
        points = {name: self._model_points(name) for name in self.estimators if name not in self.meshes}
        return draw_estimates(image, [pose for _, pose in results], camera.K, self.meshes,
                              [box for box, _ in results], {k: v for k, v in points.items() if v is not None},
                              axis_length, class_names=sorted(self.estimators))


def draw_estimates(image, poses, K, meshes: Mapping[str, tuple] | None = None, boxes=(),
                   points: Mapping[str, np.ndarray] | None = None, axis_length: float | None = None,
                   class_names=None) -> np.ndarray:
    """A copy of ``image`` (uint8 RGB) with boxes (labelled with class and score), and for each pose the
    outline of its class's mesh (:func:`~paz6d.backend.draw.draw_model_outline`; else its model points as
    dots) and its axes, one colour per class.

    Args:
        poses: ``[Pose6D]`` (metres, ``T_model2cam``) with class names.
        K: ``(3, 3)`` intrinsics of the image.
        meshes: class name -> ``(vertices (V, 3) metres, faces (F, 3))``.
        boxes: ``[Box2D]`` to draw (e.g. the detections).
        points: class name -> ``(N, 3)`` model points (metres) for classes without a mesh.
        axis_length: metres (default: half the model's extent, else 5 cm).
        class_names: the classes in colour order (default: those of meshes, points, poses and boxes, sorted).
    """
    canvas = as_image(image, "image", channels=3).copy()
    meshes, points = dict(meshes or {}), dict(points or {})
    if class_names is None:
        class_names = sorted({*meshes, *points, *(pose.class_name for pose in poses if pose.class_name),
                              *(box.class_name for box in boxes if box.class_name)})
    names = list(class_names)
    colors = keypoint_colors(max(len(names), 1))

    def color_of(name) -> tuple[int, int, int]:
        return tuple(int(c) for c in colors[names.index(name) if name in names else 0])

    for box in boxes:
        color = color_of(box.class_name)
        canvas = draw_box(canvas, box.to_array(), color, thickness=1)
        cv2.putText(canvas, f"{box.class_name} {box.score:.2f}", (int(box.x_min), max(int(box.y_min) - 3, 10)),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.4, color, 1, cv2.LINE_AA)
    for pose in poses:
        color, T, extent = color_of(pose.class_name), pose.to_matrix(), None
        if pose.class_name in meshes:
            vertices, faces = meshes[pose.class_name]
            canvas = draw_model_outline(canvas, vertices, faces, T, K, color, thickness=2)
            extent = float(np.ptp(np.asarray(vertices), axis=0).max())
        elif pose.class_name in points and len(points[pose.class_name]):
            canvas = draw_projected_points(canvas, points[pose.class_name], T, K, color, radius=0)
            extent = float(np.ptp(np.asarray(points[pose.class_name]), axis=0).max())
        length = axis_length if axis_length is not None else (0.5 * extent if extent else 0.05)
        canvas = draw_pose_axes(canvas, T, K, length)
    return canvas
