"""``paz6d run``: a pipeline over a video file, an image folder or a camera device.

The pipeline is chosen by flags: ``--detector RUN`` alone detects objects (a trained SSD); with
``--run OBJ_ID=RUN`` (repeatable) each detected object of those ids also gets its 6D pose
(:class:`~paz6d.detect_and_estimate.DetectAndEstimatePose6D`); ``--faces haar|emotion|head-pose``
runs a face pipeline (:mod:`paz6d.faces`)::

    paz6d run --input clip.mp4 --camera camera.json --detector runs/ssd --run 1=runs/aae_1 --out out/
    paz6d run --input photos/ --fps 5 --faces emotion --out out/
    paz6d run --input 0 --camera camera.json --faces head-pose --max-frames 300 --out out/

``--out`` receives ``annotated.mp4`` (the frames with the pipeline's drawing), ``frames.jsonl`` (one
line per frame, :mod:`paz6d.video.records`) and ``summary.json`` (frames per second, per-frame latency).
Detections of classes without a ``--run`` (and boxes a pose model fails on) are skipped and counted in
the summary's ``skipped_boxes``. ``--camera`` is a camera JSON file (:mod:`paz6d.backend.camera_file`);
every frame must have its size, and a camera with distortion undistorts every frame first
(``--no-undistort`` keeps them). ``--smooth WEIGHT`` smooths the poses over time
(:mod:`paz6d.video.smoothing`). ``--stream`` also writes each frame's JSON line to standard output as
soon as the frame is done, for a process reading the pipe. ``--bop-scene-id ID`` also writes the poses
as a BOP'19 results CSV (``results.csv``, :mod:`paz6d.video.bop_results`) for ``paz6d evaluate bop``.
Every flag, the camera file, the run directories and the first frame are checked before a model loads.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
import warnings
from pathlib import Path

from paz6d.backend.files import write_json_atomically
from paz6d.backend.paths import check_outputs
from paz6d.video.bop_results import write_bop_results
from paz6d.video.records import read_records
from paz6d.video.smoothing import PoseSmoother

FACES = ("haar", "emotion", "head-pose")
#: The files written in ``--out``.
VIDEO_FILE, RECORDS_FILE, SUMMARY_FILE, BOP_FILE = "annotated.mp4", "frames.jsonl", "summary.json", "results.csv"
DEFAULT_SCORE_THRESHOLD = 0.3


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--input", required=True, metavar="VIDEO|DIR|DEVICE",
                        help="a video file, a folder of images (png/jpg, sorted by name) or a camera device index")
    parser.add_argument("--out", type=Path, required=True, help="output folder (annotated video, JSON lines, summary)")
    parser.add_argument("--camera", type=Path, default=None,
                        help="camera JSON (BOP camera.json fields, optional distortion 'dist'); needed for poses")
    parser.add_argument("--detector", type=Path, default=None, help="SSD run directory (paz6d train ssd)")
    parser.add_argument("--run", action="append", default=[], metavar="OBJ_ID=RUN_DIR",
                        help="pose run directory of a BOP object the detector finds (repeatable; needs --detector)")
    parser.add_argument("--faces", choices=FACES, default=None,
                        help="a face pipeline: haar (face boxes), emotion (mini-Xception), head-pose (6D head poses)")
    parser.add_argument("--score-threshold", type=float, default=DEFAULT_SCORE_THRESHOLD,
                        help="detector score threshold in [0, 1]")
    parser.add_argument("--fps", type=float, default=None,
                        help="frames per second of an image folder (default 30) or of a device that reports none")
    parser.add_argument("--max-frames", type=int, default=None, metavar="N", help="stop after N frames")
    parser.add_argument("--smooth", type=float, default=None, metavar="WEIGHT",
                        help="smooth poses over time (alpha-beta filter, paz6d.video.smoothing) with this weight in "
                             "(0, 1] of each new pose (default: no smoothing)")
    parser.add_argument("--bop-scene-id", type=int, default=None, metavar="ID",
                        help="also write the poses as a BOP'19 results CSV (results.csv) of this scene for paz6d "
                             "evaluate bop; image ids from a folder's file names (000012.png -> 12), else frame "
                             "indices")
    parser.add_argument("--undistort", action=argparse.BooleanOptionalAction, default=True,
                        help="undistort the frames with the camera's distortion before the pipeline (default: yes)")
    parser.add_argument("--stream", action="store_true",
                        help="also write each frame's JSON line to standard output as soon as it is done (for a "
                             "process reading the pipe); the closing line then goes to standard error")
    parser.add_argument("--show", action="store_true", help="show the annotated frames in a window (needs a display)")
    parser.add_argument("--progress", action=argparse.BooleanOptionalAction, default=True,
                        help="progress bar (default: --progress)")


def parse_pose_runs(values: list[str]) -> dict[int, Path]:
    """``["1=runs/aae_1", ...]`` -> ``{1: Path("runs/aae_1")}``, each a directory.

    Raises:
        ValueError: not ``OBJ_ID=RUN_DIR`` with a positive id, an id given twice, or a run that is not a directory.
    """
    runs: dict[int, Path] = {}
    for value in values:
        match = re.fullmatch(r"(\d+)=(.+)", value)
        if match is None or int(match.group(1)) < 1:
            raise ValueError(f"--run {value}: expected OBJ_ID=RUN_DIR with a positive BOP object id")
        obj_id, run_dir = int(match.group(1)), Path(match.group(2))
        if obj_id in runs:
            raise ValueError(f"--run: object {obj_id} given twice ({runs[obj_id]} and {run_dir})")
        if not run_dir.is_dir():
            raise ValueError(f"--run: {run_dir} is not a directory")
        runs[obj_id] = run_dir
    return runs


def check_flags(args: argparse.Namespace) -> dict[int, Path]:
    """Checks the flags' values and combinations (nothing read yet); returns the ``--run`` directories."""
    if (args.detector is None) == (args.faces is None):
        raise ValueError("--detector or --faces: give exactly one pipeline (--detector RUN [--run ID=RUN ...] "
                         "or --faces " + "|".join(FACES) + ")")
    if args.run and args.detector is None:
        raise ValueError("--run: pose models need --detector (the boxes they estimate poses in)")
    needs_camera = "--run" if args.run else ("--faces head-pose" if args.faces == "head-pose" else None)
    if needs_camera and args.camera is None:
        raise ValueError(f"--camera: {needs_camera} needs the camera's intrinsics (a camera JSON file)")
    if not (math.isfinite(args.score_threshold) and 0.0 <= args.score_threshold <= 1.0):
        raise ValueError(f"--score-threshold: expected a number in [0, 1], got {args.score_threshold}")
    if args.fps is not None and not (math.isfinite(args.fps) and args.fps > 0):
        raise ValueError(f"--fps: expected a positive number of frames per second, got {args.fps}")
    if args.smooth is not None and not (math.isfinite(args.smooth) and 0.0 < args.smooth <= 1.0):
        raise ValueError(f"--smooth: expected a weight in (0, 1], got {args.smooth}")
    if args.smooth is not None and not (args.run or args.faces == "head-pose"):
        raise ValueError("--smooth: smooths poses; give pose models (--run) or --faces head-pose")
    if args.bop_scene_id is not None and (args.bop_scene_id < 0 or not args.run):
        raise ValueError(f"--bop-scene-id: expected a scene id >= 0 and pose models (--run), got {args.bop_scene_id}"
                         + ("" if args.run else " without --run"))
    if args.max_frames is not None and args.max_frames < 1:
        raise ValueError(f"--max-frames: expected a whole number >= 1, got {args.max_frames}")
    if args.show:
        from paz6d.video.player import has_display

        if not has_display():
            raise ValueError("--show: no display (DISPLAY/WAYLAND_DISPLAY unset); run without --show")
    if args.detector is not None and not args.detector.is_dir():
        raise ValueError(f"--detector: {args.detector} is not a directory")
    return parse_pose_runs(args.run)


def check_runs(detector: Path, runs: dict[int, Path]) -> None:
    """``detector`` is an SSD run that detects every object of ``runs``; each run is a pose model.

    Raises:
        ValueError: naming the flag and the run directory.
    """
    from paz6d import methods as registry

    found = registry.method_of(detector)
    if found.task != "detection":
        raise ValueError(f"--detector: {detector} is a {found.name} run directory, not a detector (paz6d train ssd)")
    class_names = list(found.run_dir.class_names(detector))
    for obj_id, run_dir in runs.items():
        method = registry.method_of(run_dir)
        if method.task != "pose":
            pose = ", ".join(known.name for known in registry.methods("pose"))
            raise ValueError(f"--run: {run_dir} is a {method.name} run directory, not a pose model ({pose})")
        if f"obj_{obj_id:06d}" not in class_names:
            raise ValueError(f"--run {obj_id}={run_dir}: the detector {detector} does not detect obj_{obj_id:06d} "
                             f"(its classes: {class_names})")


class CountSkippedBoxes:
    """A detect-and-estimate pipeline whose skipped boxes (a detected class without a pose model, a pose model
    failing on a box: :class:`~paz6d.detect_and_estimate.MissingPoseModelWarning`) are counted in ``skipped``
    instead of warned about once per box and frame; other warnings pass."""

    def __init__(self, pipeline):
        self.pipeline, self.draw, self.skipped = pipeline, pipeline.draw, 0

    def __call__(self, image):
        from paz6d.detect_and_estimate import MissingPoseModelWarning

        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            output = self.pipeline(image)
        for warning in caught:
            if issubclass(warning.category, MissingPoseModelWarning):
                self.skipped += 1
            else:
                warnings.warn_explicit(warning.message, warning.category, warning.filename, warning.lineno)
        return output


def build_pipeline(args: argparse.Namespace, runs: dict[int, Path], camera):
    """``(pipeline, draw, description)`` of the flags; ``camera`` is the pipeline's (distortion removed) or None."""
    if args.faces == "haar":
        from paz6d.faces.haar import HaarCascadeDetector
        from paz6d.ssd.pipeline import draw_detections

        detector = HaarCascadeDetector()
        return detector, lambda image, output: draw_detections(image, output, (detector.class_name,)), "faces haar"
    if args.faces == "emotion":
        from paz6d.faces.emotion import DetectEmotion, draw_emotions

        return DetectEmotion(), draw_emotions, "faces emotion"
    if args.faces == "head-pose":
        from paz6d.faces.head_pose import HeadPose6D
        from paz6d.video.drawing import draw_heads

        heads = HeadPose6D(camera)
        return heads.detect, lambda image, output: draw_heads(image, output, camera), "faces head-pose"
    if runs:
        from paz6d.detect_and_estimate import DetectAndEstimatePose6D

        pipeline = CountSkippedBoxes(DetectAndEstimatePose6D.from_run_dirs(args.detector, runs, camera,
                                                                           score_threshold=args.score_threshold))
        return pipeline, pipeline.draw, f"detector {args.detector} + poses of objects {sorted(runs)}"
    from paz6d.ssd.pipeline import DetectSingleShot, draw_detections

    detector = DetectSingleShot(args.detector, score_threshold=args.score_threshold)
    names = tuple(detector.class_names)
    return detector, lambda image, output: draw_detections(image, output, names), f"detector {args.detector}"


def run(args: argparse.Namespace) -> int:
    from paz6d.backend.camera import Camera
    from paz6d.backend.camera_file import read_camera_json
    from paz6d.video.frames import device_index, open_frames
    from paz6d.run_dirs import prepare_run_output
    from paz6d.video.player import VideoPlayer

    runs = check_flags(args)
    device = device_index(args.input)
    inputs = {"--input": None if device is not None else args.input, "--camera": args.camera,
              "--detector": args.detector, **{f"--run {obj_id}": path for obj_id, path in runs.items()}}
    outputs = {f"--out {name}": args.out / name for name in (VIDEO_FILE, RECORDS_FILE, SUMMARY_FILE, BOP_FILE)}
    check_outputs(outputs, inputs, {"--out": args.out})
    camera = read_camera_json(args.camera) if args.camera is not None else None
    if args.detector is not None:
        check_runs(args.detector, runs)
    size = None if camera is None else (camera.width, camera.height)
    with open_frames(args.input, fps=args.fps, size=size) as source:
        undistort = camera if args.undistort and camera is not None and camera.distortion is not None else None
        pipeline_camera = None if camera is None else Camera(camera.K, camera.width, camera.height)
        pipeline, draw, description = build_pipeline(args, runs, pipeline_camera)
        out = prepare_run_output(args.out, "run", inputs)
        smoother = None if args.smooth is None else PoseSmoother(args.smooth)
        player = VideoPlayer(pipeline, source, draw, undistort=undistort, camera=pipeline_camera, transform=smoother)
        summary = player.run(out / VIDEO_FILE, out / RECORDS_FILE, args.max_frames, args.progress, args.show,
                             sys.stdout if args.stream else None)
        report = {"input": {"kind": source.kind, "name": source.name, "fps": source.fps,
                            "size": list(source.size), "undistorted": undistort is not None},
                  "camera": None if args.camera is None else str(args.camera), "pipeline": description,
                  "smooth": args.smooth,
                  "skipped_boxes": getattr(pipeline, "skipped", None),
                  "video": VIDEO_FILE, "records": RECORDS_FILE, **summary}
    if args.bop_scene_id is not None:
        rows = write_bop_results(read_records(out / RECORDS_FILE), out / BOP_FILE, args.bop_scene_id)
        report.update(bop_results=BOP_FILE, bop_rows=rows)
    write_json_atomically(out / SUMMARY_FILE, report, indent=2)
    latency = summary["latency_ms"]
    print(f"{summary['frames']} frames, {summary['fps']} frames/s ({summary['pipeline_fps']} in the pipeline), "
          f"latency median {latency['median']} ms, p95 {latency['p95']} ms -> {out}",
          file=sys.stderr if args.stream else sys.stdout)
    return 0
