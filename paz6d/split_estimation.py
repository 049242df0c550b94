"""Estimates of every image of a BOP split, the loops of ``paz6d estimate`` (:mod:`paz6d.estimate` handles
its arguments): poses from each annotated instance's ground-truth box (:func:`estimate_with_ground_truth`)
or from a detector's boxes (:func:`estimate_with_detector`), over one reader of the split
(:class:`~paz6d.datasets.bop.reader.BOPDataset`), with the per-image time BOP asks for, and optionally
refined against each image's depth (:func:`checked_depth`, :func:`refinement_statistics`).

Pose models load once per run directory (:func:`load_estimators`, each through its method in
:mod:`paz6d.methods`); each image's camera is given per call.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np

from paz6d.backend.checks import check_depth
from paz6d.backend.viewpoints import ViewpointRange
from paz6d.datasets.bop import Target
from paz6d.datasets.bop.fields import box_field
from paz6d.datasets.bop.targets import TARGET_MIN_VISIBLE_FRACTION, read_targets
from paz6d.processors.crops import BoxVariants

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


def _estimator(run_dir: Path, **options):
    """The pose pipeline of one run directory (its method found from its files), loaded once; each image's
    camera is given per call. ``options``: ``keypoint_crops``, ``box_variants``,
    ``viewpoints`` of :func:`~paz6d.detect_and_estimate.load_pose_estimator`."""
    from paz6d.detect_and_estimate import load_pose_estimator

    return load_pose_estimator(run_dir, **options)[1]


def load_estimators(runs: dict[int, tuple[Path, str]], **options) -> tuple[dict[int, object], dict[int, str]]:
    """``({obj_id: estimator}, {obj_id: reason})`` (``options`` as :func:`_estimator`'s): a run that loads but
    can never give a pose (a KeypointNet with fewer than 4 usable keypoints, a ``PnPError``) is left out with a
    warning, so its instances score as misses and the other objects are still estimated.

    Raises:
        ValueError: a corrupt run directory, or no run that can give a pose.
    """
    from paz6d.backend.pnp import PnPError

    estimators, unusable = {}, {}
    for obj_id, (run_dir, _) in runs.items():
        try:
            estimators[obj_id] = _estimator(run_dir, **options)
        except PnPError as error:
            unusable[obj_id] = str(error)
    if not estimators:
        raise ValueError("no pose model can estimate: " + "; ".join(unusable.values()))
    for obj_id, reason in unusable.items():
        warnings.warn(f"object {obj_id} is not estimated (its instances score as misses): {reason}", stacklevel=2)
    return estimators, unusable


def estimate_with_ground_truth(runs: dict[int, tuple[Path, str]], dataset: Path, split: str, box: str = "obj",
                               min_visible: float = TARGET_MIN_VISIBLE_FRACTION, progress: bool = True,
                               depth: bool = False, keypoint_crops: int = 1,
                               viewpoints: ViewpointRange | None = None) -> dict:
    """Every visible-enough instance of the runs' objects, from its ground-truth box (``viewpoints``: the
    AAE runs answer only with views in this range).

    Returns:
        ``{"estimates": Estimates, "targets": [Target], "skipped_images", "failed": {obj_id: count},
        "images": [(scene_id, im_id)], "unusable": {obj_id: reason}}`` (see :func:`load_estimators`); an
        estimate that fails (e.g. PnP with too few keypoints, a ``ValueError``) is counted and left out (BOP
        scores a missing estimate as a miss).
    """
    from tqdm.auto import tqdm

    from paz6d.datasets.bop.reader import BOPDataset  # here: OpenCV, which `paz6d estimate --help` does not need

    field = box_field(box)
    data = BOPDataset(dataset, split=split)
    estimators, unusable = None, {}  # loaded at the first instance to estimate
    estimates, targets = Estimates(), []
    skipped_images, images, failed = 0, [], {obj_id: 0 for obj_id in runs}
    for sample in tqdm(data, desc="estimate (ground-truth boxes)", unit="image", disable=not progress,
                       dynamic_ncols=True):
        instances = [instance for instance in sample.objects if instance.obj_id in runs
                     and (instance.info or {}).get("visib_fract", 1.0) >= min_visible]
        if not instances:
            continue
        if sample.image is None:
            skipped_images += 1
            continue
        counts: dict[int, int] = {}
        for instance in instances:
            counts[instance.obj_id] = counts.get(instance.obj_id, 0) + 1
        targets += [Target(sample.scene_id, sample.im_id, obj_id, count) for obj_id, count in sorted(counts.items())]
        if estimators is None:
            estimators, unusable = load_estimators(runs, keypoint_crops=keypoint_crops, viewpoints=viewpoints)
        images.append((sample.scene_id, sample.im_id))
        poses, seconds = [], 0.0
        extra = {"depth": checked_depth(sample, dataset, split)} if depth else {}
        for instance in instances:
            if instance.obj_id in unusable:
                continue
            if not instance.info or field not in instance.info:
                raise ValueError(f"{dataset}: scene {sample.scene_id} image {sample.im_id} has no {field} in "
                                 f"scene_gt_info.json (needed for the ground-truth box)")
            x, y, width, height = instance.info[field]
            started = time.perf_counter()
            try:
                pose = estimators[instance.obj_id](sample.image, (float(x), float(y), float(x + width),
                                                                   float(y + height)), camera=sample.camera,
                                                  **extra)
            except ValueError:
                pose = None
            seconds += time.perf_counter() - started
            if pose is None:
                failed[instance.obj_id] += 1
                continue
            poses.append((instance.obj_id, 1.0, pose.to_matrix()))
        estimates.add_image(sample.scene_id, sample.im_id, poses, seconds)
    return {"estimates": estimates, "targets": targets, "skipped_images": skipped_images, "failed": failed,
            "estimators": estimators or {},
            "images": images, "unusable": unusable}


def estimate_with_detector(runs: dict[int, tuple[Path, str]], detector_dir: Path, dataset: Path, split: str,
                           score_threshold: float = DEFAULT_SCORE_THRESHOLD, progress: bool = True,
                           depth: bool = False, keypoint_crops: int = 1, verify: bool = False,
                           flip: bool = False, box_search: bool = False, poses_per_class: int | None = None,
                           viewpoints: ViewpointRange | None = None) -> dict:
    """Detect every RGB image of the split, then estimate each detection of an object that has a run
    (``verify``: scores of the detections with a pose model times their pose's score, ``VerifyBoxes``;
    ``flip``: the detector also sees the mirror image, ``DetectSingleShot``; ``box_search``: the AAE runs
    choose among the default :class:`~paz6d.processors.crops.BoxVariants` of each box; ``poses_per_class``:
    poses only for each class's best detections, ``KeepTopPerClass``; ``viewpoints``: the AAE runs answer only
    with views in this range).

    Returns:
        ``{"estimates": Estimates, "detections": [COCO result dicts], "images": [(scene_id, im_id)],
        "skipped_images", "failed": {obj_id: count}, "without_model": {class: count}, "unusable": {obj_id: reason},
        "seconds_per_image"}``.
    """
    from tqdm.auto import tqdm

    from paz6d.datasets.bop.coco_ground_truth import coco_image_id
    from paz6d.datasets.bop.reader import BOPDataset
    from paz6d.detect_and_estimate import DetectAndEstimatePose6D, MissingPoseModelWarning, bop_object_id, load_detector

    detector = load_detector(detector_dir, score_threshold, flip)
    estimators, unusable = load_estimators(runs, keypoint_crops=keypoint_crops, viewpoints=viewpoints,
                                            box_variants=BoxVariants() if box_search else None)
    pipeline = DetectAndEstimatePose6D(detector, estimators, verify=verify, poses_per_class=poses_per_class)
    estimates, detections, images = Estimates(), [], []
    skipped_images, failed, without_model, total = 0, {obj_id: 0 for obj_id in runs}, {}, 0.0
    for sample in tqdm(BOPDataset(dataset, split, ground_truth=False), desc="detect + estimate", unit="image",
                       disable=not progress, dynamic_ncols=True):
        scene_id, im_id, image, camera = sample.scene_id, sample.im_id, sample.image, sample.camera
        if image is None:
            skipped_images += 1
            continue
        if (image.shape[1], image.shape[0]) != (camera.width, camera.height):
            raise ValueError(f"{dataset}/{split}/{scene_id:06d}/rgb: image {im_id} is {image.shape[1]}x"
                             f"{image.shape[0]} pixels, but {dataset}/camera.json says {camera.width}x{camera.height}")
        depth_image = checked_depth(sample, dataset, split) if depth else None
        started = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", MissingPoseModelWarning)
            values = pipeline.run(image, camera, depth_image)
        seconds = time.perf_counter() - started
        total += seconds
        images.append((scene_id, im_id))
        without = [box for box in values["detections"] if box.class_name not in pipeline.estimators]
        # the boxes with a pose (values["boxes"]) carry the verified scores
        for box in values["boxes"] + values.get("left_out", []) + without:
            obj_id = bop_object_id(box.class_name)
            if obj_id is None:
                raise ValueError(f"--detector: class {box.class_name!r} is not a BOP object (obj_XXXXXX)")
            detections.append({"image_id": coco_image_id(scene_id, im_id), "category_id": obj_id,
                               "bbox": [round(float(v), 2) for v in (box.x_min, box.y_min, box.width, box.height)],
                               "score": round(float(box.score), 5)})
            if obj_id not in estimators:
                without_model[box.class_name] = without_model.get(box.class_name, 0) + 1
        poses = []
        for box, pose in zip(values["boxes"], values["poses"]):
            obj_id = bop_object_id(box.class_name)
            if pose is None:
                failed[obj_id] += 1
            else:
                poses.append((obj_id, float(box.score), pose.to_matrix()))
        estimates.add_image(scene_id, im_id, poses, seconds)
    return {"estimates": estimates, "detections": detections, "images": images, "skipped_images": skipped_images,
            "estimators": estimators,
            "failed": failed, "without_model": without_model, "unusable": unusable,
            "seconds_per_image": total / len(images) if images else None}


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
