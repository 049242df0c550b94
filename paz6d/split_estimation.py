"""The loop of ``paz6d estimate`` (:mod:`paz6d.estimate` handles its arguments): :func:`estimate_frames` runs
one box source over the frames of one frame source, with the per-image time BOP asks for.

A frame (:class:`EstimationFrame`) is an image with its camera, BOP ids, and optionally its depth (ICP
refinement, :func:`checked_depth`) and its ground-truth boxes. Frame sources: :class:`SplitFrames` (the RGB
images of a BOP split, through :class:`~paz6d.datasets.bop.reader.BOPDataset`) and :class:`FolderFrames` (a
folder of images and one camera file, through :func:`paz6d.video.frames.open_frames`). Box sources, the only
difference between the ways to estimate: :class:`GroundTruthBoxes` (each annotated instance's box) and
:class:`DetectorBoxes` (a detector's boxes, :class:`~paz6d.detect_and_estimate.DetectAndEstimatePose6D`).

Pose models load once per run directory (:func:`load_estimators`, each through its method in
:mod:`paz6d.methods`); each image's camera is given per call.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from paz6d.abstract import Box2D, Pose6D
from paz6d.backend.camera import Camera
from paz6d.backend.checks import check_depth
from paz6d.datasets.bop import Target
from paz6d.datasets.bop.fields import box_field
from paz6d.datasets.bop.targets import TARGET_MIN_VISIBLE_FRACTION, read_targets
from paz6d.processors.crops import BoxVariants
from paz6d.video.records import FrameRecord, result_entries

#: Detections scoring below this are dropped (``paz6d estimate --score-threshold``).
DEFAULT_SCORE_THRESHOLD = 0.1


class Estimates:
    """Rows of the results CSV, grouped per image so that every row of an image gets its time."""

    def __init__(self):
        self.rows: dict[str, list] = {key: [] for key in ("scene_ids", "im_ids", "obj_ids", "scores", "rotations",
                                                           "translations", "times")}

    def add_image(self, scene_id: int, im_id: int, poses: list[tuple[int, float, np.ndarray]], seconds: float) -> None:
        for obj_id, score, T in poses:
            for key, value in zip(("scene_ids", "im_ids", "obj_ids", "scores", "rotations", "translations", "times"),
                                  (scene_id, im_id, obj_id, score, T[:3, :3], T[:3, 3], seconds)):
                self.rows[key].append(value)

    def __len__(self) -> int:
        return len(self.rows["im_ids"])

    def arrays(self) -> dict[str, np.ndarray]:
        result = {key: np.asarray(values) for key, values in self.rows.items()}
        result["rotations"] = result["rotations"].reshape(-1, 3, 3)
        result["translations"] = result["translations"].reshape(-1, 3)
        return result


def object_class(obj_id: int) -> str:
    """The detector class name of a BOP object: ``5`` -> ``"obj_000005"``."""
    return f"obj_{int(obj_id):06d}"


def _estimator(run_dir: Path, **options):
    """The pose pipeline of one run directory (its method found from its files), loaded once; each image's
    camera is given per call. ``options``: ``class_name``, ``keypoint_crops``, ``box_variants``,
    ``viewpoints`` of :func:`~paz6d.detect_and_estimate.load_pose_estimator`."""
    from paz6d.detect_and_estimate import load_pose_estimator

    return load_pose_estimator(run_dir, **options)[1]


def load_estimators(runs: dict[int, tuple[Path, str]], **options) -> tuple[dict[int, object], dict[int, str]]:
    """``({obj_id: estimator}, {obj_id: reason})`` (``options`` as :func:`_estimator`'s; each estimator writes
    its object's class name into its poses): a run that loads but can never give a pose (a KeypointNet with
    fewer than 4 usable keypoints, a ``PnPError``) is left out with a warning, so its instances score as misses
    and the other objects are still estimated.

    Raises:
        ValueError: a corrupt run directory, or no run that can give a pose.
    """
    from paz6d.backend.pnp import PnPError

    estimators, unusable = {}, {}
    for obj_id, (run_dir, _) in runs.items():
        try:
            estimators[obj_id] = _estimator(run_dir, class_name=object_class(obj_id), **options)
        except PnPError as error:
            unusable[obj_id] = str(error)
    if not estimators:
        raise ValueError("no pose model can estimate: " + "; ".join(unusable.values()))
    for obj_id, reason in unusable.items():
        warnings.warn(f"object {obj_id} is not estimated (its instances score as misses): {reason}", stacklevel=2)
    return estimators, unusable


# ------------------------------------------------------------------------------------------ frames
@dataclass(frozen=True)
class EstimationFrame:
    """One image to estimate.

    Attributes:
        scene_id, im_id: its BOP ids (an image folder: scene 0, the image's position in the sorted folder).
        image: ``(H, W, 3)`` uint8 RGB.
        camera: its :class:`~paz6d.backend.camera.Camera` (no distortion: the image is undistorted).
        depth: ``(H, W)`` metres to refine the poses against (ICP), ``None``: no refinement.
        truth: ground-truth boxes ``((obj_id, (x_min, y_min, x_max, y_max) pixels), ...)``, ``None`` without.
        name: the image file's name (an image folder's frames), else ``None``.
        timestamp_s: seconds from the first frame (an image folder: ``index / fps``, as ``paz6d run``).
    """

    scene_id: int
    im_id: int
    image: np.ndarray
    camera: Camera
    depth: np.ndarray | None = None
    truth: tuple[tuple[int, tuple[float, float, float, float]], ...] | None = None
    name: str | None = None
    timestamp_s: float = 0.0


class SplitFrames:
    """The RGB images of a BOP split as frames, each with its camera from ``scene_camera.json``.

    Args:
        dataset: BOP data set folder.
        split: split folder name.
        object_ids: the objects estimated.
        box: with ground truth, the box of each instance (``"obj"`` or ``"visib"``,
            :func:`~paz6d.datasets.bop.fields.box_field`): frames only of images with an instance of
            ``object_ids`` whose visible fraction is at least ``min_visible``, each with those instances'
            boxes. ``None``: every image, no ground truth read.
        min_visible: with ``box``, the least visible fraction of an instance estimated.
        depth: read each frame's depth image (:func:`checked_depth`).
    Attributes:
        skipped: images without an RGB file (of those that would be frames).
        targets: with ``box``, the BOP'19 targets of the frames read so far.
        count: frames to come when known (without ground truth: the split's images), else ``None``.
    Raises:
        ValueError: a malformed data set, an image of another size than its camera, a missing box field or
            depth file (naming the file).
    """

    def __init__(self, dataset: Path, split: str, object_ids, box: str | None = None,
                 min_visible: float = TARGET_MIN_VISIBLE_FRACTION, depth: bool = False):
        from paz6d.datasets.bop.reader import BOPDataset  # here: OpenCV, which `paz6d estimate --help` does not need

        self.dataset, self.split, self.object_ids = Path(dataset), split, set(object_ids)
        self.field = None if box is None else box_field(box)
        self.min_visible, self.depth = min_visible, depth
        self.data = BOPDataset(dataset, split=split, ground_truth=box is not None)
        self.skipped, self.targets = 0, []
        self.count = None if box is not None else len(self.data)

    def _truth(self, sample, instances) -> tuple[tuple[int, tuple[float, float, float, float]], ...]:
        boxes = []
        for instance in instances:
            if not instance.info or self.field not in instance.info:
                raise ValueError(f"{self.dataset}: scene {sample.scene_id} image {sample.im_id} has no {self.field} "
                                 f"in scene_gt_info.json (needed for the ground-truth box)")
            x, y, width, height = instance.info[self.field]
            boxes.append((instance.obj_id, (float(x), float(y), float(x + width), float(y + height))))
        return tuple(boxes)

    def __iter__(self):
        for sample in self.data:
            instances = None
            if self.field is not None:
                instances = [instance for instance in sample.objects if instance.obj_id in self.object_ids
                             and (instance.info or {}).get("visib_fract", 1.0) >= self.min_visible]
                if not instances:
                    continue
            if sample.image is None:
                self.skipped += 1
                continue
            image, camera = sample.image, sample.camera
            if (image.shape[1], image.shape[0]) != (camera.width, camera.height):
                raise ValueError(f"{self.dataset}/{self.split}/{sample.scene_id:06d}/rgb: image {sample.im_id} is "
                                 f"{image.shape[1]}x{image.shape[0]} pixels, but {self.dataset}/camera.json says "
                                 f"{camera.width}x{camera.height}")
            if instances is not None:
                counts: dict[int, int] = {}
                for instance in instances:
                    counts[instance.obj_id] = counts.get(instance.obj_id, 0) + 1
                self.targets += [Target(sample.scene_id, sample.im_id, obj_id, count)
                                 for obj_id, count in sorted(counts.items())]
            depth = checked_depth(sample, self.dataset, self.split) if self.depth else None
            yield EstimationFrame(sample.scene_id, sample.im_id, image, camera, depth,
                                  None if instances is None else self._truth(sample, instances))


class FolderFrames:
    """The images of a folder (``.png``, ``.jpg``, ``.jpeg`` sorted by name,
    :func:`~paz6d.video.frames.open_frames`) as frames of scene 0, ``im_id`` their position, all with one
    camera. The folder is opened, and its first image read and checked, at construction; a camera with
    distortion undistorts every image first (``cv2.undistort``, as ``paz6d run``), and the frames get its
    ``K`` without distortion.

    Attributes:
        skipped: always 0 (every file of the folder is an image).
        count: the number of images.
        undistorted: whether the camera's distortion is removed from the images.
    Raises:
        ValueError: a missing or empty folder, an image that does not decode or whose size is not the
            camera's (naming the file; a later image when it is read).
    """

    def __init__(self, folder: Path, camera: Camera):
        from paz6d.video.frames import device_index, open_frames

        spec = f"./{folder}" if device_index(str(folder)) is not None else folder  # a folder named 0 is no device
        self.source = open_frames(spec, size=(camera.width, camera.height))
        self.camera = Camera(camera.K, camera.width, camera.height)
        self.distortion = camera.distortion
        self.skipped, self.count, self.undistorted = 0, self.source.count, camera.distortion is not None

    def __iter__(self):
        import cv2

        for frame in self.source:
            image = frame.image if self.distortion is None else cv2.undistort(frame.image, self.camera.K,
                                                                              self.distortion)
            yield EstimationFrame(0, frame.index, image, self.camera, name=frame.name, timestamp_s=frame.timestamp_s)


# ------------------------------------------------------------------------------------------ boxes
@dataclass
class FramePoses:
    """What a box source found in one frame: ``results`` ``[(Box2D, Pose6D)]`` (the boxes with a pose; the
    box's score is the estimate's), ``failed`` (the object id of each box its pose model failed on),
    ``seconds`` (the image's time), ``detections`` (every detection, for the COCO results) and
    ``without_model`` (the detections of classes without a pose model)."""

    results: list[tuple[Box2D, Pose6D]]
    failed: list[int]
    seconds: float
    detections: list[Box2D] = field(default_factory=list)
    without_model: list[Box2D] = field(default_factory=list)


class GroundTruthBoxes:
    """Poses from each frame's ground-truth boxes (score 1); the time of an image is that of its poses. The pose
    models load at the first frame (``options`` as :func:`load_estimators`'s). A pose model that fails on a box
    (e.g. PnP with too few keypoints, a ``ValueError``) counts it as failed (BOP scores a missing estimate as a
    miss)."""

    description = "estimate (ground-truth boxes)"

    def __init__(self, runs: dict[int, tuple[Path, str]], **options):
        self.runs, self.options = runs, options
        self.estimators: dict[int, object] | None = None
        self.unusable: dict[int, str] = {}

    def __call__(self, frame: EstimationFrame) -> FramePoses:
        if self.estimators is None:
            self.estimators, self.unusable = load_estimators(self.runs, **self.options)
        extra = {} if frame.depth is None else {"depth": frame.depth}
        results, failed, seconds = [], [], 0.0
        for obj_id, coordinates in frame.truth:
            if obj_id in self.unusable:
                continue
            started = time.perf_counter()
            try:
                box = Box2D(*coordinates, 1.0, object_class(obj_id))
                pose = self.estimators[obj_id](frame.image, box, camera=frame.camera, **extra)
            except ValueError:
                pose = None
            seconds += time.perf_counter() - started
            if pose is None:
                failed.append(obj_id)
            else:
                results.append((box, pose))
        return FramePoses(results, failed, seconds)


class DetectorBoxes:
    """Poses from a detector's boxes: :class:`~paz6d.detect_and_estimate.DetectAndEstimatePose6D` of the
    detector and the pose models, loaded at construction; the time of an image is the whole pipeline's.

    Args:
        runs: ``{obj_id: (run_dir, method)}``.
        detector_dir: the detector's run directory.
        score_threshold: detections below it are dropped.
        flip: the detector also sees the mirror image (``DetectSingleShot``).
        verify: scores of the detections with a pose model times their pose's score (``VerifyBoxes``).
        poses_per_class: poses only for each class's best detections (``KeepTopPerClass``).
        box_search: the AAE runs choose among the default :class:`~paz6d.processors.crops.BoxVariants` of each box.
        vote_iou: the detector's box voting (``DetectSingleShot``'s ``vote_iou``; ``None``: off).
        options: ``keypoint_crops``, ``viewpoints`` of :func:`load_estimators`.
    """

    description = "detect + estimate"

    def __init__(self, runs: dict[int, tuple[Path, str]], detector_dir: Path,
                 score_threshold: float = DEFAULT_SCORE_THRESHOLD, flip: bool = False, verify: bool = False,
                 poses_per_class: int | None = None, box_search: bool = False, vote_iou: float | None = None,
                 **options):
        from paz6d.detect_and_estimate import DetectAndEstimatePose6D, load_detector

        detector = load_detector(detector_dir, score_threshold, flip, vote_iou)
        self.estimators, self.unusable = load_estimators(runs, box_variants=BoxVariants() if box_search else None,
                                                         **options)
        self.pipeline = DetectAndEstimatePose6D(detector, self.estimators, verify=verify,
                                                poses_per_class=poses_per_class)

    def __call__(self, frame: EstimationFrame) -> FramePoses:
        from paz6d.detect_and_estimate import MissingPoseModelWarning, bop_object_id

        started = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", MissingPoseModelWarning)
            values = self.pipeline.run(frame.image, frame.camera, frame.depth)
        seconds = time.perf_counter() - started
        without = [box for box in values["detections"] if box.class_name not in self.pipeline.estimators]
        results = [(box, pose) for box, pose in zip(values["boxes"], values["poses"]) if pose is not None]
        failed = [bop_object_id(box.class_name) for box, pose in zip(values["boxes"], values["poses"]) if pose is None]
        # the boxes with a pose (values["boxes"]) carry the verified scores
        return FramePoses(results, failed, seconds, values["boxes"] + values.get("left_out", []) + without, without)


# ------------------------------------------------------------------------------------------ the loop
def estimate_frames(frames, boxes, object_ids, progress: bool = True) -> dict:
    """Every frame of ``frames`` (a frame source) through ``boxes`` (a box source).

    Returns:
        ``{"estimates": Estimates, "detections": [COCO result dicts], "images": [(scene_id, im_id)],
        "records": [FrameRecord] (one per frame, :mod:`paz6d.video.records`), "failed": {obj_id: count},
        "without_model": {class: count}, "unusable": {obj_id: reason}, "estimators": {obj_id: estimator},
        "seconds_per_image"}`` (``None`` without frames).
    Raises:
        ValueError: a detection of a class that is not a BOP object (``obj_XXXXXX``), or what the frame source
            raises.
    """
    from tqdm.auto import tqdm

    from paz6d.datasets.bop.coco_ground_truth import coco_image_id
    from paz6d.detect_and_estimate import bop_object_id

    estimates, detections, images, records = Estimates(), [], [], []
    failed, without_model, total = {obj_id: 0 for obj_id in object_ids}, {}, 0.0
    for index, frame in enumerate(tqdm(frames, total=frames.count, desc=boxes.description, unit="image",
                                       disable=not progress, dynamic_ncols=True)):
        found = boxes(frame)
        images.append((frame.scene_id, frame.im_id))
        total += found.seconds
        for box in found.detections:
            obj_id = bop_object_id(box.class_name)
            if obj_id is None:
                raise ValueError(f"--detector: class {box.class_name!r} is not a BOP object (obj_XXXXXX)")
            detections.append({"image_id": coco_image_id(frame.scene_id, frame.im_id), "category_id": obj_id,
                               "bbox": [round(float(v), 2) for v in (box.x_min, box.y_min, box.width, box.height)],
                               "score": round(float(box.score), 5)})
        for box in found.without_model:
            without_model[box.class_name] = without_model.get(box.class_name, 0) + 1
        for obj_id in found.failed:
            failed[obj_id] += 1
        estimates.add_image(frame.scene_id, frame.im_id, [(bop_object_id(box.class_name), float(box.score),
                                                           pose.to_matrix()) for box, pose in found.results],
                            found.seconds)
        records.append(FrameRecord(index, round(frame.timestamp_s, 6), round(found.seconds * 1000.0, 3),
                                   result_entries(found.results), frame.name))
    return {"estimates": estimates, "detections": detections, "images": images, "records": records,
            "failed": failed, "without_model": without_model, "unusable": boxes.unusable,
            "estimators": boxes.estimators or {}, "seconds_per_image": total / len(images) if images else None}


def detector_targets(dataset: Path, images: list[tuple[int, int]], object_ids) -> list[Target]:
    """The entries of ``<dataset>/test_targets_bop19.json`` for the estimated images and objects (the BOP
    protocol's list of what to score; empty when the file is absent)."""
    path = Path(dataset) / "test_targets_bop19.json"
    if not path.is_file():
        return []
    wanted = set(images)
    return [target for target in read_targets(path)
            if (target.scene_id, target.im_id) in wanted and target.obj_id in object_ids]


# ------------------------------------------------------------------------------------------ depth (--depth)
def _depth_file(dataset: Path, split: str, scene_id: int, im_id: int) -> Path:
    """``<dataset>/<split>/<scene>/depth/<im_id>.png`` (or ``.tif``/``.tiff``) of one image.

    Raises:
        ValueError: no depth file, naming the one expected.
    """
    from paz6d.datasets.bop.scene import DEPTH_SUFFIXES, find_image

    folder = Path(dataset) / split / f"{scene_id:06d}" / "depth"
    path = find_image(folder, im_id, DEPTH_SUFFIXES)
    if path is None:
        raise ValueError(f"{folder / f'{im_id:06d}.png'}: depth image not found (--depth needs one per image)")
    return path


def checked_depth(sample, dataset: Path, split: str) -> np.ndarray:
    """The depth ``(H, W)`` metres of a :class:`~paz6d.datasets.bop.reader.BOPSample`, checked to exist, be
    finite and have its RGB image's size (errors name the depth file)."""
    path = _depth_file(dataset, split, sample.scene_id, sample.im_id)
    return check_depth(sample.depth, str(path), sample.image.shape[:2])


def refinement_statistics(estimators) -> dict:
    """Counts and mean process time of the depth refinements the estimators' ``refine_with_depth`` steps ran."""
    steps = [estimator["refine_with_depth"].processor.statistics for estimator in estimators.values()
             if "refine_with_depth" in getattr(estimator, "names", ())]
    count = sum(step["refinements"] for step in steps)
    rejected: dict[str, int] = {}
    for step in steps:
        for check, number in step["rejected"].items():
            rejected[check] = rejected.get(check, 0) + number
    return {"refinements": count, "accepted": sum(step["accepted"] for step in steps), "rejected": rejected,
            "mean_cpu_seconds": sum(step["seconds"] for step in steps) / count if count else None}
