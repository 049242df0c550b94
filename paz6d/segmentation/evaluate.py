"""Mask quality on a held-out BOP split: COCO ``segm`` files and AP, mean IoU, a PNG of predicted masks.

The "detections" are the ground-truth visible boxes with score 1 (so the numbers measure the masks alone,
not a detector): :func:`write_coco_files` writes ``ground_truth.json`` (visible masks as RLE; instances
below ``visib_fract`` 0.1 become ignored ``iscrowd`` regions, as BOP's targets) and ``results.json`` (one
predicted mask per kept instance), which ``paz6d evaluate coco --iou-type segm`` scores;
:func:`evaluate_split` does all of it and writes ``segm_eval.json`` and ``masks.png``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from evaluation import coco

from paz6d.backend.draw import draw_box, draw_mask_outline, image_grid, keypoint_colors
from paz6d.backend.files import write_json_atomically
from paz6d.backend.image import resize, save_image
from paz6d.datasets.bop.coco_ground_truth import category_name, coco_image_id
from paz6d.datasets.bop.reader import BOPDataset
from paz6d.segmentation.dataset import MIN_VISIBLE_FRACTION
from paz6d.segmentation.masks import rle_from_mask

GROUND_TRUTH_FILE = "ground_truth.json"
RESULTS_FILE = "results.json"
EVALUATION_FILE = "segm_eval.json"
MASKS_PLOT = "masks.png"


def draw_masks(image: np.ndarray, masks: np.ndarray, boxes=None, truth: np.ndarray | None = None) -> np.ndarray:
    """``image`` with each predicted mask tinted in its own colour, its box, and the true masks' outlines in white."""
    canvas = image.astype(np.float32)
    colors = keypoint_colors(max(len(masks), 1))
    for mask, color in zip(masks, colors):
        canvas[mask] = 0.45 * canvas[mask] + 0.55 * np.asarray(color, np.float32)
    canvas = canvas.astype(np.uint8)
    for index, color in enumerate(colors[:len(masks)]):
        if boxes is not None:
            canvas = draw_box(canvas, np.asarray(boxes[index], np.float64), tuple(int(c) for c in color), thickness=1)
        if truth is not None:
            canvas = draw_mask_outline(canvas, truth[index], (255, 255, 255))
    return canvas


def write_coco_files(segment, root: str | Path, split: str, out: str | Path, progress: bool = False,
                     plot_images: int = 6, detector=None) -> dict:
    """Predicts a mask for every visible ground-truth box of ``root/split`` (or, with ``detector``, for every
    detected box) and writes the COCO files.

    Args:
        segment: a :class:`~paz6d.segmentation.pipeline.SegmentInstances`.
        out: folder for ``ground_truth.json``, ``results.json`` and ``masks.png``.
        detector: ``image -> list[Box2D]`` with ``obj_XXXXXX`` class names (e.g. ``DetectSingleShot``); its
            boxes and scores replace the ground-truth boxes (detection and masks scored together).
    Returns:
        ``{"images", "instances", "mean_iou", "ground_truth", "results"}`` (``mean_iou``: IoU of each kept
        instance's predicted and true visible mask, averaged; ``None`` with a detector).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    dataset = BOPDataset(root, split)
    images, annotations, results, ious, tiles, obj_ids = [], [], [], [], [], set()
    for sample in tqdm(dataset, total=len(dataset), desc=f"segmenting {split}", disable=not progress, unit="image"):
        if sample.image is None:
            raise ValueError(f"{Path(root) / split / f'{sample.scene_id:06d}'}: image {sample.im_id}: rgb image not "
                             f"found")
        height, width = sample.image.shape[:2]
        image_id = coco_image_id(sample.scene_id, sample.im_id)
        images.append({"id": image_id, "width": width, "height": height, "file_name": f"{sample.scene_id:06d}/"
                       f"{sample.im_id:06d}"})
        boxes, names, truths, kept = [], [], [], []
        for number, obj in enumerate(sample.objects):
            if obj.info is None or obj.mask_visib is None:
                raise ValueError(f"{Path(root) / split / f'{sample.scene_id:06d}'}: image {sample.im_id}, instance "
                                 f"{number}: scene_gt_info.json entry or mask_visib file missing")
            x, y, w, h = (int(value) for value in obj.info["bbox_visib"])
            obj_ids.add(obj.obj_id)
            if w <= 0 or h <= 0:
                continue
            ignored = float(obj.info.get("visib_fract", 1.0)) < MIN_VISIBLE_FRACTION
            annotations.append({"id": len(annotations) + 1, "image_id": image_id, "category_id": obj.obj_id,
                                "bbox": [x, y, w, h], "area": int(obj.mask_visib.sum()), "iscrowd": int(ignored),
                                "segmentation": rle_from_mask(obj.mask_visib)})
            if not ignored:
                boxes.append([x, y, x + w, y + h])
                names.append(category_name(obj.obj_id))
                truths.append(obj.mask_visib)
                kept.append(obj.obj_id)
        if detector is not None:
            detections = detector(sample.image)
            boxes = [detection.to_array().tolist() for detection in detections]
            names, scores = [d.class_name for d in detections], [float(d.score) for d in detections]
            kept = [int(name.removeprefix("obj_")) for name in names]
        else:
            scores = [1.0] * len(boxes)
        masks = segment(sample.image, np.asarray(boxes, np.float64).reshape(-1, 4), names)
        for obj_id, box, mask, score in zip(kept, boxes, masks, scores):
            results.append({"image_id": image_id, "category_id": obj_id, "score": score,
                            "bbox": [box[0], box[1], box[2] - box[0], box[3] - box[1]],
                            "segmentation": rle_from_mask(mask)})
        if detector is None:
            for mask, truth in zip(masks, truths):
                union = np.logical_or(mask, truth).sum()
                ious.append(float(np.logical_and(mask, truth).sum() / union) if union else 1.0)
        if len(tiles) < plot_images:
            tiles.append(draw_masks(sample.image, masks, boxes, None if detector is not None
                                    else np.asarray(truths).reshape(masks.shape)))
    categories = [{"id": obj_id, "name": category_name(obj_id)} for obj_id in sorted(obj_ids)]
    ground_truth = {"images": images, "annotations": annotations, "categories": categories}
    write_json_atomically(out / GROUND_TRUTH_FILE, ground_truth)
    write_json_atomically(out / RESULTS_FILE, results)
    if tiles:
        size = (tiles[0].shape[1], tiles[0].shape[0])
        save_image(out / MASKS_PLOT, image_grid([tile if tile.shape[:2] == size[::-1] else resize(tile, size)
                                                 for tile in tiles], columns=3))
    return {"images": len(images), "instances": len(results), "mean_iou": float(np.mean(ious)) if ious else None,
            "ground_truth": str(out / GROUND_TRUTH_FILE), "results": str(out / RESULTS_FILE)}


def evaluate_split(segment, root: str | Path, split: str, out: str | Path, progress: bool = False,
                   detector=None) -> dict:
    """:func:`write_coco_files`, then COCO segm AP (:func:`evaluation.coco.evaluate_files`); writes
    ``out/segm_eval.json`` and returns it (``AP``, ``AP50``, ``AP75``, ``mean_iou``, ...)."""
    summary = write_coco_files(segment, root, split, out, progress, detector=detector)
    evaluation = coco.evaluate_files(summary["ground_truth"], summary["results"], "segm")
    stats = {name: round(float(value), 4) for name, value in zip(coco.STAT_NAMES, evaluation.stats)}
    report = {"dataset": str(Path(root).resolve()), "split": split,
              "detections": ("ground-truth visible boxes, score 1 (mask quality only)" if detector is None
                             else f"detector {getattr(detector, 'run_dir', detector)} (detection and masks together)"),
              **summary,
              "segm": stats}
    write_json_atomically(Path(out) / EVALUATION_FILE, report, indent=2)
    return report


def main(argv: list[str] | None = None) -> int:
    """``python -m paz6d.segmentation.evaluate RUN_DIR DATASET SPLIT OUT``: the files and scores above."""
    from paz6d.segmentation.pipeline import SegmentInstances

    parser = argparse.ArgumentParser(description="mask quality of a segmentation run on a BOP split "
                                                 "(ground-truth boxes as the detections, score 1)")
    parser.add_argument("run_dir", type=Path, help="segmentation run directory")
    parser.add_argument("dataset", type=Path, help="BOP data set with mask_visib/ (e.g. a `paz6d generate` output)")
    parser.add_argument("split", help="split folder")
    parser.add_argument("out", type=Path, help="folder for ground_truth.json, results.json, segm_eval.json, masks.png")
    parser.add_argument("--detector", type=Path, help="SSD run directory: its detections (score >= 0.05) replace "
                                                      "the ground-truth boxes")
    parser.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar")
    args = parser.parse_args(argv)
    detector = None
    if args.detector is not None:
        from paz6d.ssd.pipeline import DetectSingleShot

        detector = DetectSingleShot(args.detector, score_threshold=0.05)
    report = evaluate_split(SegmentInstances(args.run_dir), args.dataset, args.split, args.out, args.progress,
                            detector)
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
