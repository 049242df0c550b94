"""``paz6d estimate``: run trained pose models on a BOP data set or a folder of images and write one BOP
results CSV.

One or more pose run directories (``--run OBJ_ID=RUN_DIR``, repeatable; the method of each, one of the pose
methods of :mod:`paz6d.methods`, is found from its files) get every image of a split, either with each annotated
instance's ground-truth 2D box (the setting of the AAE paper's evaluation) or, with ``--detector``, with
the boxes a trained SSD finds (:class:`paz6d.detect_and_estimate.DetectAndEstimatePose6D`; no ground
truth read). Estimates are written in the BOP'19 results format that ``paz6d evaluate bop`` scores, with
the per-image time (seconds, the same on every row of an image, as BOP asks)::

    paz6d estimate --run 5=runs/aae_5 --run 8=runs/kp_8 --dataset ../shared/data/bop_lmo --out gt.csv
    paz6d estimate --detector runs/ssd --run 5=runs/aae_5 --run 8=runs/kp_8 --dataset ../shared/data/bop_lmo \\
        --out det.csv             # also writes det_detections.json (COCO results of the detector)
    paz6d evaluate bop --dataset ../shared/data/bop_lmo --results det.csv --metrics mssd,mspd,add --out det.json

``--images DIR --camera camera.json`` (with ``--detector``) estimates the images of a plain folder instead
(sorted by name, as ``paz6d run`` reads a folder; scene 0, ``im_id`` each image's position): besides the CSV
and the detections it writes ``<out stem>_frames.jsonl`` (one line per image, the records of ``paz6d run``,
:mod:`paz6d.video.records`, with the image's file name) and ``<out stem>_summary.json``::

    paz6d estimate --images photos/ --camera camera.json --detector runs/ssd --run 5=runs/aae_5 --out photos.csv

With ``--depth`` every pose is refined by ICP against the image's depth image (BOP ``depth/`` files in
millimetres times ``depth_scale``, read in metres; :class:`paz6d.processors.refine.RefineWithDepth`), and
the summary counts the refinements accepted and rejected.

A bare ``--run RUN_DIR`` with ``--object-id`` (or a run whose mesh is named ``obj_XXXXXX``) keeps working.
Images without an RGB file are skipped (reported), as are, with ground-truth boxes, instances below
``--min-visible``. Nothing estimated is an error (exit 2).

This module handles the flags and checks every run directory, the detector and the outputs before any
image is read; the loop over the images is :mod:`paz6d.split_estimation`'s (a frame source for a split or
a folder, a box source for ground-truth boxes or a detector).
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import numpy as np

from paz6d.backend.files import write_bytes_atomically, write_json_atomically
from paz6d.backend.paths import check_outputs, check_outputs_apart, check_plain_name
from paz6d.keypointnet.config import CROP_JITTERS, check_crops
from paz6d.backend.viewpoints import ViewpointRange
from paz6d.datasets.bop import write_pose_results, write_targets
from paz6d.datasets.bop.targets import TARGET_MIN_VISIBLE_FRACTION
from paz6d.datasets.bop.fields import BOX_FIELDS
from paz6d.methods import get, method_of, methods
from paz6d.video.records import record_line
from paz6d.split_estimation import (DEFAULT_SCORE_THRESHOLD, DetectorBoxes, FolderFrames, GroundTruthBoxes,
                                    SplitFrames, detector_targets, estimate_frames, refinement_statistics)

_OBJECT_MESH = re.compile(r"^obj_(\d+)$")


def configure(parser: argparse.ArgumentParser) -> None:
    pose_methods = methods("pose")
    parser.add_argument("--run", action="append", required=True, metavar="[OBJ_ID=]RUN_DIR",
                        help=f"pose run directory of `paz6d train {'|'.join(method.name for method in pose_methods)}` "
                             f"for BOP object OBJ_ID; repeat for more objects. A bare RUN_DIR takes --object-id (or "
                             f"the obj_XXXXXX name of its mesh)")
    parser.add_argument("--method", choices=sorted({name for method in pose_methods
                                                    for name in (method.name, *method.aliases)}), default=None,
                        help="optional check: every --run must be of this method (found from the files anyway)")
    parser.add_argument("--dataset", type=Path, default=None, help="BOP data set folder (or --images)")
    parser.add_argument("--images", type=Path, default=None, metavar="DIR",
                        help="instead of --dataset, a folder of images (png/jpg, sorted by name; scene 0, im_id each "
                             "image's position) with --camera and --detector; also writes <out stem>_frames.jsonl "
                             "(one line per image, as `paz6d run`) and <out stem>_summary.json")
    parser.add_argument("--camera", type=Path, default=None,
                        help="with --images: the camera JSON file of the images (BOP camera.json fields, optional "
                             "distortion 'dist', as `paz6d calibrate` writes; with 'dist' the images are undistorted "
                             "first)")
    parser.add_argument("--split", default=None, help="split folder of --dataset (default: test)")
    parser.add_argument("--object-id", type=int, default=None, help="object of a bare --run RUN_DIR")
    parser.add_argument("--out", type=Path, required=True, help="results CSV to write (all objects)")
    parser.add_argument("--detector", type=Path, default=None,
                        help="SSD run directory (`paz6d train ssd`): boxes from its detections instead of the "
                             "ground truth (no ground truth is read)")
    parser.add_argument("--detections-out", type=Path, default=None,
                        help="with --detector: COCO results JSON of every detection (default: beside --out, "
                             "<out stem>_detections.json)")
    parser.add_argument("--score-threshold", type=float, default=DEFAULT_SCORE_THRESHOLD,
                        help=f"with --detector: detections scoring below it are dropped (default "
                             f"{DEFAULT_SCORE_THRESHOLD}); the BOP score of an estimate is its detection's")
    parser.add_argument("--verify", action="store_true",
                        help="with --detector: multiply each detection's score by its pose model's score (the AAE: "
                             "cosine similarity to its codebook match), in the detections JSON and the results")
    parser.add_argument("--flip", action="store_true",
                        help="with --detector: also detect on each image's mirror image and average (a second "
                             "network pass; see DetectSingleShot's flip)")
    parser.add_argument("--vote-iou", type=float, default=None, metavar="IOU",
                        help="with --detector: each detection's box is the score-weighted mean of the boxes of its "
                             "class overlapping it by at least this IoU (box voting; default: off, the NMS winner's "
                             "own box; see DetectSingleShot's vote_iou)")
    parser.add_argument("--box-search", action="store_true",
                        help="with --detector: each AAE run tries its detection's box shifted by 0, 5 and 10 %% of "
                             "its sides either way along x and y and scaled by 0.9/1/1.1 (75 crops), and keeps the "
                             "crop that matches its codebook best (a detector's boxes are loose; see BoxVariants)")
    parser.add_argument("--poses-per-class", type=int, default=None, metavar="N",
                        help="with --detector: estimate poses only for the N highest-scoring detections of each "
                             "class per image (BOP scores an object's best N estimates, N its instance count: 1 on "
                             "LM-O); the detections JSON still holds every detection (default: all)")
    parser.add_argument("--elevation-degrees", type=float, nargs=2, default=(-90.0, 90.0), metavar=("MIN", "MAX"),
                        help="AAE runs: answer only with views whose camera elevation above the model's xy plane "
                             "(z up) lies in MIN..MAX degrees, as `paz6d generate --rotation view-sphere` draws "
                             "them; e.g. your training scenes' range widened by a margin, for a camera that never "
                             "sees the objects from below (default: -90 90, every view)")
    parser.add_argument("--inplane-degrees", type=float, default=180.0, metavar="D",
                        help="AAE runs: answer only with views whose in-plane angle (the model's z axis in the "
                             "image against image-up) lies within ±D degrees, as `paz6d generate` draws it "
                             "(default: 180, every view)")
    parser.add_argument("--box", choices=sorted(BOX_FIELDS), default=None,
                        help="without --detector, the ground-truth box given to the model: of the whole projected "
                             "object (obj, the default) or of its visible part (visib, what a detector would see)")
    parser.add_argument("--targets-out", type=Path, default=None,
                        help="also write the BOP'19 targets of the images estimated (for `evaluate bop --targets` "
                             "when only some images of the split have RGB files); with --detector, the data "
                             "set's test_targets_bop19.json entries of those images")
    parser.add_argument("--min-visible", type=float, default=None,
                        help=f"without --detector, skip instances whose visible fraction is below this (default "
                             f"{TARGET_MIN_VISIBLE_FRACTION}, as BOP'19 targets)")
    parser.add_argument("--depth", action="store_true",
                        help="refine every pose by ICP (open3d) against the image's depth (depth/<im_id>.png of "
                             "the split, times depth_scale of scene_camera.json); a refinement that fails its "
                             "checks keeps the RGB pose")
    parser.add_argument("--keypoint-crops", type=int, default=1,
                        help=f"KeypointNet runs: crops per box, 1 to {len(CROP_JITTERS)} (more: more accurate, "
                             f"that many network inputs; see KeypointPose6D's crops; default 1)")
    parser.add_argument("--progress", action=argparse.BooleanOptionalAction, default=True,
                        help="progress bar (default: --progress)")


# ------------------------------------------------------------------------------------------ run directories
def run_object_id(run_dir: Path, method: str) -> int | None:
    """The BOP object id a run directory was trained on, from its mesh's ``obj_XXXXXX`` file name
    (``None`` when the mesh is named otherwise, e.g. a mesh given with ``--mesh``).

    Checks the run's files through its method's ``RunDir.validate``, so a corrupt or incomplete run
    directory fails here, naming the file, before any image is read.
    """
    found = get(method)
    if found.task != "pose":
        names = " or ".join(pose.name for pose in methods("pose"))
        raise ValueError(f"--run: {run_dir} is a {found.name} run directory, not a pose model ({names})")
    found.run_dir.validate(run_dir)
    mesh = found.run_dir.training_mesh(run_dir)
    match = _OBJECT_MESH.match(mesh[0].stem) if mesh else None
    return int(match.group(1)) if match else None


def parse_run(value: str) -> tuple[int | None, Path]:
    """``"5=runs/aae"`` -> ``(5, Path("runs/aae"))``; ``"runs/aae"`` -> ``(None, Path("runs/aae"))``.

    Raises:
        ValueError: an object id that is not a positive integer, or an empty run directory.
    """
    head, separator, tail = value.partition("=")
    if separator and re.fullmatch(r"[+-]?\d+", head.strip()):
        obj_id = int(head)
        if obj_id < 1:
            raise ValueError(f"--run {value}: expected a BOP object id (a positive integer) before '=', got {obj_id}")
        if not tail:
            raise ValueError(f"--run {value}: expected OBJ_ID=RUN_DIR, the run directory is empty")
        return obj_id, Path(tail)
    if not value:
        raise ValueError("--run: expected OBJ_ID=RUN_DIR or RUN_DIR, got an empty value")
    return None, Path(value)


def resolve_runs(values: list[str], object_id: int | None, method: str | None = None) -> dict[int, tuple[Path, str]]:
    """``{obj_id: (run_dir, method)}`` from the ``--run`` values, every run directory checked (its method,
    its files, the object it was trained on) before any image is read.

    Raises:
        ValueError: a missing/corrupt/non-pose run directory, an object given twice, a bare run without an
            object id, or a run trained on another object (naming the flag and the file).
    """
    if object_id is not None and object_id < 1:
        raise ValueError(f"--object-id: expected a BOP object id (a positive integer), got {object_id}")
    runs: dict[int, tuple[Path, str]] = {}
    for value in values:
        obj_id, run_dir = parse_run(value)
        if not run_dir.is_dir():
            raise ValueError(f"--run: {run_dir} is not a directory")
        record = method_of(run_dir)
        found = record.name
        if record.task == "detection":
            raise ValueError(f"--run: {run_dir} is {record.run_dir.KIND} detector run directory; give it as --detector")
        if method is not None and record is not get(method):
            raise ValueError(f"--method: {run_dir} is a {found} run directory; use --method {found} (or leave "
                             f"--method out: the method is found from the files)")
        trained_on = run_object_id(run_dir, found)
        if obj_id is None:
            obj_id = object_id if object_id is not None else trained_on
            if obj_id is None:
                raise ValueError(f"--run {value}: which object? give --run OBJ_ID={run_dir} (its mesh is not named "
                                 f"obj_XXXXXX)")
            if object_id is not None and trained_on is not None and trained_on != object_id:
                raise ValueError(f"--object-id: {run_dir} was trained on object {trained_on}, not {object_id}")
        elif trained_on is not None and trained_on != obj_id:
            raise ValueError(f"--run {value}: {run_dir} was trained on object {trained_on}, not {obj_id}")
        if obj_id in runs:
            raise ValueError(f"--run: object {obj_id} given twice ({runs[obj_id][0]} and {run_dir})")
        runs[obj_id] = (run_dir, found)
    if not runs:
        raise ValueError("--run: expected at least one pose run directory")
    return runs


def check_detector(detector: Path, object_ids) -> tuple[str, ...]:
    """The class names of an SSD run directory, checked to include ``obj_XXXXXX`` of every object.

    Raises:
        ValueError: not a (valid) SSD run directory, or an object the detector was not trained on.
    """
    if not detector.is_dir():
        raise ValueError(f"--detector: {detector} is not a directory")
    found = method_of(detector)
    if found.task != "detection":
        trainers = " or ".join(f"`paz6d train {method.name}`" for method in methods("detection"))
        raise ValueError(f"--detector: {detector} is a {found.name} run directory, not a detector ({trainers})")
    class_names = found.run_dir.class_names(detector)
    missing = [obj_id for obj_id in sorted(object_ids) if f"obj_{obj_id:06d}" not in class_names]
    if missing:
        raise ValueError(f"--detector: {detector} does not detect objects {missing} (its classes: {list(class_names)})")
    return class_names


def detections_path(args: argparse.Namespace) -> Path | None:
    """Where the detections JSON goes: ``--detections-out``, else ``<out stem>_detections.json`` beside ``--out``."""
    if args.detector is None:
        return None
    if args.detections_out is not None:
        return args.detections_out
    return args.out.with_name(f"{args.out.stem}_detections.json")


def folder_outputs(args: argparse.Namespace) -> dict[str, Path]:
    """With ``--images``, the files written beside ``--out``: ``{"records": <out stem>_frames.jsonl,
    "summary": <out stem>_summary.json}``; else ``{}``."""
    if args.images is None:
        return {}
    return {name: args.out.with_name(f"{args.out.stem}_{suffix}")
            for name, suffix in (("records", "frames.jsonl"), ("summary", "summary.json"))}


def check_source(args: argparse.Namespace) -> None:
    """Checks that the images come from one place, ``--dataset`` or ``--images`` (with ``--camera`` and
    ``--detector``, and none of the flags that need a data set's ground truth or depth)."""
    if args.images is None:
        if args.dataset is None:
            raise ValueError("--dataset or --images: give the images to estimate (a BOP data set folder, or a folder "
                             "of images with --camera and --detector)")
        if args.camera is not None:
            raise ValueError("--camera: only with --images (a BOP data set's images have their cameras in "
                             "scene_camera.json)")
        return
    if args.dataset is not None:
        raise ValueError("--images: not with --dataset (give a BOP data set or a folder of images, not both)")
    if args.detector is None:
        raise ValueError("--images: needs --detector (a folder of images has no ground-truth boxes)")
    if args.camera is None:
        raise ValueError("--camera: --images needs the camera's intrinsics (a camera JSON file, as `paz6d calibrate` "
                         "writes; a BOP camera.json is one)")
    for flag, given, reason in (("--targets-out", args.targets_out is not None, "no ground truth to score against"),
                                ("--depth", args.depth, "no depth images"),
                                ("--split", args.split is not None, "no splits")):
        if given:
            raise ValueError(f"{flag}: not with --images (a folder of images has {reason})")


def check_ground_truth_flags(args: argparse.Namespace) -> None:
    """Refuses the flags that choose ground-truth boxes (``--box``, ``--min-visible``) where boxes come from
    ``--detector``, then gives the unset ones their defaults (``--split`` test, ``--box`` obj, ``--min-visible``
    the BOP'19 targets' fraction)."""
    for flag, value in (("--box", args.box), ("--min-visible", args.min_visible)):
        if value is not None and args.detector is not None:
            raise ValueError(f"{flag}: only without --detector (it chooses the ground-truth boxes; with --detector "
                             f"the boxes are its detections)")
    args.split = "test" if args.split is None else args.split
    args.box = "obj" if args.box is None else args.box
    args.min_visible = TARGET_MIN_VISIBLE_FRACTION if args.min_visible is None else args.min_visible


# ------------------------------------------------------------------------------------------ command
def viewpoint_range(args: argparse.Namespace) -> ViewpointRange | None:
    """The AAE runs' :class:`~paz6d.backend.viewpoints.ViewpointRange` of ``--elevation-degrees`` and
    ``--inplane-degrees``, ``None`` for every view; ``ValueError`` naming the flag for a bad range."""
    for flag, settings in (("--elevation-degrees", {"elevation_degrees": tuple(args.elevation_degrees)}),
                           ("--inplane-degrees", {"inplane_degrees": args.inplane_degrees})):
        try:
            ViewpointRange(**settings)
        except ValueError as error:
            raise ValueError(f"{flag}: {error}") from None
    viewpoints = ViewpointRange(tuple(args.elevation_degrees), args.inplane_degrees)
    return None if viewpoints.is_everything else viewpoints


def check_arguments(args: argparse.Namespace) -> tuple[dict[int, tuple[Path, str]], ViewpointRange | None]:
    """Checks every flag, the run directories (method, files, object), the detector and the output paths
    before any image is read; returns ``({obj_id: (run_dir, method)}, viewpoint_range(args))``. Bad input
    raises ``ValueError`` naming the flag or file."""
    check_source(args)
    check_ground_truth_flags(args)
    check_plain_name(args.split, "--split")
    if not 0.0 <= args.min_visible <= 1.0:
        raise ValueError(f"--min-visible: expected a visible fraction in [0, 1], got {args.min_visible}")
    check_crops(args.keypoint_crops, "--keypoint-crops")
    if not 0.0 <= args.score_threshold <= 1.0:
        raise ValueError(f"--score-threshold: expected a score in [0, 1], got {args.score_threshold}")
    if args.detections_out is not None and args.detector is None:
        raise ValueError("--detections-out: only with --detector")
    if args.verify and args.detector is None:
        raise ValueError("--verify: only with --detector (ground-truth boxes have no detection score)")
    if args.flip and args.detector is None:
        raise ValueError("--flip: only with --detector (it is how the detector sees the image)")
    if args.vote_iou is not None and args.detector is None:
        raise ValueError("--vote-iou: only with --detector (it is how the detector's boxes are merged)")
    if args.vote_iou is not None and not 0.0 <= args.vote_iou <= 1.0:
        raise ValueError(f"--vote-iou: expected an IoU in [0, 1], got {args.vote_iou}")
    if args.box_search and args.detector is None:
        raise ValueError("--box-search: only with --detector (with exact ground-truth boxes it lowers the scores)")
    if args.poses_per_class is not None:
        if args.detector is None:
            raise ValueError("--poses-per-class: only with --detector (ground-truth boxes are one per instance)")
        if args.poses_per_class < 1:
            raise ValueError(f"--poses-per-class: expected a whole number >= 1, got {args.poses_per_class}")
        if args.verify:
            raise ValueError("--poses-per-class: not with --verify (it re-ranks every detection by its pose's score, "
                             "so every detection needs a pose)")
    viewpoints = viewpoint_range(args)
    detections = detections_path(args)
    outputs = {"--out": args.out, "--targets-out": args.targets_out, "--detections-out": detections,
               **{f"--out ({path.name})": path for path in folder_outputs(args).values()}}
    check_outputs(outputs, {"--dataset": args.dataset, "--images": args.images, "--camera": args.camera,
                            "--detector": args.detector})
    if args.dataset is not None and not args.dataset.is_dir():
        raise ValueError(f"--dataset: {args.dataset} is not a directory")
    if args.images is not None and not args.images.is_dir():
        raise ValueError(f"--images: {args.images} is not a folder (expected a folder of .png/.jpg images)")
    runs = resolve_runs(args.run, args.object_id, args.method)
    check_outputs_apart(outputs, {f"--run {obj_id}": run_dir for obj_id, (run_dir, _) in runs.items()})
    if viewpoints is not None and not any("viewpoints" in get(method).options for _, method in runs.values()):
        takers = " or ".join(method.label for method in methods("pose") if "viewpoints" in method.options)
        raise ValueError(f"--elevation-degrees/--inplane-degrees: only {takers} runs answer from a codebook of views; "
                         f"no --run is one")
    if args.detector is not None:
        check_detector(args.detector, runs)
    return runs, viewpoints


def frame_source(args: argparse.Namespace, runs) -> SplitFrames | FolderFrames:
    """The frames of ``--images`` (with ``--camera``) or of ``--split`` of ``--dataset`` (with ground-truth
    boxes unless ``--detector``); a folder is opened and its first image checked now."""
    if args.images is not None:
        from paz6d.backend.camera_file import read_camera_json

        return FolderFrames(args.images, read_camera_json(args.camera))
    return SplitFrames(args.dataset, args.split, runs, None if args.detector is not None else args.box,
                       args.min_visible, args.depth)


def box_source(args: argparse.Namespace, runs, viewpoints: ViewpointRange | None) -> GroundTruthBoxes | DetectorBoxes:
    """The boxes the pose models get: ``--detector``'s (its models loaded now), else the ground truth's."""
    options = {"keypoint_crops": args.keypoint_crops, "viewpoints": viewpoints}
    if args.detector is None:
        return GroundTruthBoxes(runs, **options)
    return DetectorBoxes(runs, args.detector, args.score_threshold, args.flip, args.verify, args.poses_per_class,
                         args.box_search, args.vote_iou, **options)


def write_folder_outputs(args: argparse.Namespace, frames: FolderFrames, found: dict, summary: dict) -> None:
    """With ``--images``: the JSON lines of every image and the summary JSON (:func:`folder_outputs`); adds
    their paths and the folder's description to ``summary``."""
    paths = folder_outputs(args)
    write_bytes_atomically(paths["records"], "".join(record_line(record) + "\n"
                                                     for record in found["records"]).encode())
    summary.update(images=str(args.images), camera=str(args.camera), undistorted=frames.undistorted,
                   frames=len(found["records"]), records_out=str(paths["records"]),
                   summary_out=str(paths["summary"]))
    write_json_atomically(paths["summary"], summary, indent=2)


def estimate(args: argparse.Namespace) -> dict:
    """Runs ``paz6d estimate`` (flags as parsed by :func:`configure`); returns its summary.

    Raises:
        ValueError: bad flags or files, or nothing estimated (no file is written then).
    """
    from paz6d.backend.tensorflow_guard import import_tensorflow

    runs, viewpoints = check_arguments(args)
    import_tensorflow()
    objects = sorted(runs)
    frames = frame_source(args, runs)
    found = estimate_frames(frames, box_source(args, runs, viewpoints), runs, args.progress)
    if not found["images"] and args.detector is None:
        raise ValueError(f"{args.dataset}: no instance of objects {objects} with an RGB image and visible "
                         f"fraction >= {args.min_visible} in split {args.split!r}")
    if not found["images"]:
        raise ValueError(f"{args.dataset}: no image of split {args.split!r} has an RGB file "
                         f"({frames.skipped} listed in scene_camera.json)")
    estimates = found["estimates"]
    failed = sum(found["failed"].values())
    if len(estimates) == 0:
        which = f"object {objects[0]}" if len(objects) == 1 else f"objects {objects}"
        reason = (f"every estimate failed ({failed} instances of {which})" if failed else
                  "the detector found none of the objects" if args.detector is not None else "no estimate")
        raise ValueError(f"nothing estimated for objects {objects}: {reason}; {args.out} not written")
    rows = estimates.arrays()
    write_pose_results(args.out, rows["scene_ids"], rows["im_ids"], rows["obj_ids"], rows["scores"], rows["rotations"],
                       rows["translations"], rows["times"], units="m")
    summary = {"out": str(args.out), "estimates": len(estimates),
               "per_object": {str(obj_id): int(np.sum(rows["obj_ids"] == obj_id)) for obj_id in objects},
               "failed": {str(key): value for key, value in found["failed"].items()},
               "images_without_rgb_skipped": frames.skipped,
               "unusable": {str(key): reason for key, reason in found["unusable"].items()},
               "methods": {str(obj_id): method for obj_id, (_, method) in runs.items()},
               "mean_seconds_per_image": found["seconds_per_image"]}
    if args.detector is not None:
        path = detections_path(args)
        write_json_atomically(path, found["detections"])
        summary.update(detections_out=str(path), detections=len(found["detections"]),
                       detections_without_pose_model=found["without_model"])
    if viewpoints is not None:
        summary["viewpoints"] = viewpoints.describe()
    if args.targets_out is not None:
        targets = frames.targets if args.detector is None else detector_targets(args.dataset, found["images"], runs)
        write_targets(args.targets_out, targets)
        summary["targets_out"] = str(args.targets_out)
    if args.depth:
        summary["depth_refinement"] = refinement_statistics(found["estimators"])
    if args.images is not None:
        write_folder_outputs(args, frames, found, summary)
    return summary


def run(args: argparse.Namespace) -> int:
    summary = estimate(args)
    failed = sum(int(value) for value in summary["failed"].values())
    extra = (f", {summary['detections']} detections -> {summary['detections_out']}"
             if "detections_out" in summary else "")
    if summary["unusable"]:
        extra += f"; objects {sorted(map(int, summary['unusable']))} not estimated (unusable pose model)"
    if "records_out" in summary:
        extra += f"; one line per image -> {summary['records_out']}, summary -> {summary['summary_out']}"
        images = f"{summary['frames']} images of {summary['images']}"
    else:
        images = f"{summary['images_without_rgb_skipped']} images without RGB skipped"
    print(f"wrote {args.out}: {summary['estimates']} estimates of objects {sorted(map(int, summary['per_object']))} "
          f"({failed} failed, {images}{extra}; {summary['mean_seconds_per_image']:.3f} s per image)")
    if "depth_refinement" in summary:
        refined = summary["depth_refinement"]
        seconds = "" if refined["mean_cpu_seconds"] is None else f", {refined['mean_cpu_seconds']:.3f} CPU s each"
        print(f"depth refinement (ICP): {refined['accepted']} of {refined['refinements']} accepted{seconds}; "
              f"rejected by check: {refined['rejected']}")
    return 0
