"""``paz6d detect``: a trained SSD over a BOP split or an image folder -> COCO detections JSON.

With ``--dataset`` (a BOP data set: real, or one ``paz6d generate`` wrote) every RGB image of the
split is detected; image ids are :func:`paz6d.datasets.bop.coco_ground_truth.coco_image_id` and
category ids the BOP object ids (class names ``obj_XXXXXX``), so the file scores against the
split's ground truth, which ``--ground-truth PATH`` writes (visible boxes, instances with visible
fraction >= 0.1, :mod:`paz6d.datasets.bop.coco_ground_truth`)::

    paz6d detect --run-dir runs/ssd --dataset ../shared/data/bop_lmo --split test \\
        --out lmo_detections.json --ground-truth lmo_gt.json
    paz6d evaluate coco --gt lmo_gt.json --results lmo_detections.json --out lmo_coco.json

With ``--images DIR`` every image file of the folder (sorted by name) is detected; image ids are
positions in that order, category ids are class positions (1-based) in the detector's
``class_names``, and each entry also names its ``file_name`` and ``class_name``.

TensorFlow is imported inside :func:`run`.
"""

from __future__ import annotations

import argparse
import json
import re
import time
from dataclasses import dataclass
from pathlib import Path


from paz6d.backend.files import write_json_atomically
from paz6d.backend.image import load_image
from paz6d.backend.paths import check_outputs
from paz6d.cli_options import add_config_arguments, config_from_args, config_inputs, flags_in_errors, option
from paz6d.datasets.bop.coco_ground_truth import bop_split_to_coco

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
_BOP_NAME = re.compile(r"obj_(\d+)")


@dataclass
class Detection:
    """One ``paz6d detect`` run (each field is a flag)."""

    run_dir: Path = option(help="SSD run directory (`paz6d train ssd`)")
    out: Path = option(help="COCO results JSON to write (a list of detections, boxes [x, y, w, h] pixels)")
    dataset: Path | None = option(None, "BOP data set folder", one_of="source")
    images: Path | None = option(None, "folder of images", one_of="source")
    split: str = option("test", "with --dataset: the split folder")
    ground_truth: Path | None = option(None, "with --dataset: also write the split's COCO ground truth here "
                                             "(visible boxes; visible fraction < 0.1 ignored)")
    score_threshold: float = option(0.01, "detections scoring below it are dropped (low for mAP)")
    max_detections: int = option(100, "most detections per image")
    flip: bool = option(False, "also detect on each image's mirror image and average (test-time augmentation: "
                               "a second network pass; docs/ssd.md)")
    vote_iou: float | None = option(None, "each box is the score-weighted mean of the boxes of its class overlapping "
                                          "it by at least this IoU (box voting; default off; docs/ssd.md)")
    progress: bool = option(True, "progress bar")

    def __post_init__(self):
        if (self.dataset is None) == (self.images is None):
            raise ValueError("dataset: expected exactly one of dataset and images")
        if self.ground_truth is not None and self.dataset is None:
            raise ValueError("ground_truth: only with dataset (an image folder has no ground truth)")
        if not 0.0 <= self.score_threshold <= 1.0:
            raise ValueError(f"score_threshold: expected a value in [0, 1], got {self.score_threshold}")
        if self.max_detections < 1:
            raise ValueError(f"max_detections: expected a positive count, got {self.max_detections}")
        if self.vote_iou is not None and not 0.0 <= self.vote_iou <= 1.0:
            raise ValueError(f"vote_iou: expected a value in [0, 1], got {self.vote_iou}")


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``paz6d detect`` flags (the fields of :class:`Detection`)."""
    add_config_arguments(parser, Detection)


def bop_category_id(class_name: str) -> int:
    """The BOP object id of class ``obj_XXXXXX``.

    Raises:
        ValueError: any other name (the detector was not trained on BOP-named meshes).
    """
    match = _BOP_NAME.fullmatch(str(class_name))
    if match is None:
        raise ValueError(f"class_names: unknown class {class_name!r} for a BOP data set (expected obj_XXXXXX names)")
    return int(match.group(1))


def image_files(folder: Path) -> list[Path]:
    """The image files of ``folder`` sorted by name.

    Raises:
        ValueError: not a folder, or no image in it.
    """
    if not folder.is_dir():
        raise ValueError(f"images: {folder} is not a directory")
    files = sorted(path for path in folder.iterdir() if path.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise ValueError(f"images: no image file ({', '.join(IMAGE_SUFFIXES)}) in {folder}")
    return files


def detect_files(detector, files: list[tuple[int, Path]], category_ids: dict[str, int], progress: bool = True,
                 extra: bool = False) -> tuple[list[dict], float]:
    """COCO results of ``detector`` on ``(image_id, path)`` pairs and the mean seconds per image (detector
    call only). ``extra`` adds ``file_name`` and ``class_name`` to each entry."""
    from tqdm.auto import tqdm

    results, seconds = [], 0.0
    for image_id, path in tqdm(files, desc="detect", disable=not progress, dynamic_ncols=True):
        image = load_image(path)
        started = time.perf_counter()
        boxes = detector(image)
        seconds += time.perf_counter() - started
        for box in boxes:
            entry = {"image_id": int(image_id), "category_id": category_ids[box.class_name],
                     "bbox": [round(float(v), 2) for v in (box.x_min, box.y_min, box.width, box.height)],
                     "score": round(float(box.score), 5)}
            if extra:
                entry.update(file_name=path.name, class_name=box.class_name)
            results.append(entry)
    return results, seconds / max(len(files), 1)


def run(args: argparse.Namespace) -> int:
    """Entry point of ``paz6d detect``."""
    job = config_from_args(Detection, args)
    with flags_in_errors(Detection):
        summary = detect(job)
    print(json.dumps(summary, indent=2))
    return 0


def detect(job: Detection) -> dict:
    """Runs the detector and writes ``job.out`` (and ``job.ground_truth``); returns a summary.

    Raises:
        ValueError: an output that is an input (an image, a file of the data set or run directory) or
            the other output, or a symbolic link (:func:`paz6d.backend.paths.check_outputs`), before
            anything is read.
    """
    from paz6d.ssd.pipeline import DetectSingleShot

    check_outputs({"--out": job.out, "--ground-truth": job.ground_truth}, config_inputs(job, ("out", "ground_truth")))
    detector = DetectSingleShot(job.run_dir, score_threshold=job.score_threshold, max_detections=job.max_detections,
                                flip=job.flip, vote_iou=job.vote_iou)
    if job.dataset is not None:
        coco = bop_split_to_coco(job.dataset, job.split)
        category_ids = {name: bop_category_id(name) for name in detector.class_names}
        files = [(image["id"], Path(job.dataset) / image["file_name"]) for image in coco["images"]]
        if job.ground_truth is not None:
            write_json_atomically(job.ground_truth, coco)
    else:
        category_ids = {name: index + 1 for index, name in enumerate(detector.class_names)}
        files = list(enumerate(image_files(job.images)))
    results, seconds = detect_files(detector, files, category_ids, job.progress, extra=job.images is not None)
    write_json_atomically(job.out, results)
    return {"images": len(files), "detections": len(results), "out": str(job.out),
            "ground_truth": None if job.ground_truth is None else str(job.ground_truth),
            "milliseconds_per_image": round(1000 * seconds, 2),
            "score_threshold": job.score_threshold, "flip": job.flip, "vote_iou": job.vote_iou,
            "classes": list(detector.class_names)}
