"""Whole-process COCO evaluation on a 5,000-image set: ``paz6d evaluate coco`` vs pycocotools.

The set is the 100-image val2014 sample of ``../shared/data/coco`` (and its cocoapi "fake" bbox and
segm results) replicated ``--copies`` times under new image and annotation ids (copy ``c`` adds
``c * 10**7`` to every image id and ``c * 10**8`` to every annotation id), written to a temporary
folder. Each side runs as its own process, start to finish, as a user would run it:

* paz6d: ``paz6d evaluate coco --gt GT --results RESULTS --iou-type TYPE --out OUT.json``;
* pycocotools: ``COCO(GT)``, ``loadRes(RESULTS)``, ``COCOeval(...).evaluate()``, ``accumulate()``,
  ``summarize()`` in ``python -c``.

Both report their 12 summary numbers, which must be identical. Best of ``--repeats`` alternating
runs; wall and CPU seconds (user + system of the child) are printed, the CPU ones being the steadier
on a shared machine. Run: ``.venv/bin/python benchmarks/coco_scale.py [--copies 50] [--repeats 3]
[--iou-types bbox segm]``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

from timing import run_process

SHARED_COCO = Path(__file__).resolve().parents[2] / "shared" / "data" / "coco"
GROUND_TRUTH = "instances_val2014_100.json"
RESULTS = {"bbox": "instances_val2014_fakebbox100_results.json", "segm": "instances_val2014_fakesegm100_results.json"}
IMAGE_ID_STEP, ANNOTATION_ID_STEP = 10**7, 10**8

PYCOCOTOOLS = """
import contextlib, io, json, sys
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval
with contextlib.redirect_stdout(io.StringIO()):
    truth = COCO(sys.argv[1])
    evaluator = COCOeval(truth, truth.loadRes(sys.argv[2]), sys.argv[3])
    evaluator.evaluate()
    evaluator.accumulate()
    evaluator.summarize()
print(json.dumps([float(value) for value in evaluator.stats]))
"""


def replicate(source: Path, folder: Path, copies: int) -> tuple[Path, dict[str, Path]]:
    """Writes the ground truth and both result files replicated ``copies`` times; returns their paths."""
    truth = json.loads((source / GROUND_TRUTH).read_text())
    images, annotations = [], []
    for copy in range(copies):
        images += [{**image, "id": image["id"] + copy * IMAGE_ID_STEP} for image in truth["images"]]
        annotations += [{**annotation, "id": annotation["id"] + copy * ANNOTATION_ID_STEP,
                         "image_id": annotation["image_id"] + copy * IMAGE_ID_STEP}
                        for annotation in truth["annotations"]]
    truth_path = folder / "ground_truth.json"
    truth_path.write_text(json.dumps({**truth, "images": images, "annotations": annotations}))
    result_paths = {}
    for iou_type, name in RESULTS.items():
        results = json.loads((source / name).read_text())
        result_paths[iou_type] = folder / f"{iou_type}_results.json"
        result_paths[iou_type].write_text(json.dumps(
            [{**result, "image_id": result["image_id"] + copy * IMAGE_ID_STEP}
             for copy in range(copies) for result in results]))
    return truth_path, result_paths


def paz6d_command() -> list[str]:
    script = Path(sys.executable).with_name("paz6d")
    return [str(script)] if script.exists() else [sys.executable, "-m", "paz6d"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--coco-dir", type=Path, default=SHARED_COCO, help="the coco folder of the shared data")
    parser.add_argument("--copies", type=int, default=50, help="replicas of the 100-image sample")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each side (best time is kept)")
    parser.add_argument("--iou-types", nargs="+", choices=tuple(RESULTS), default=list(RESULTS),
                        help="which jobs to time")
    args = parser.parse_args(argv)
    if not (args.coco_dir / GROUND_TRUTH).is_file():
        parser.error(f"--coco-dir: {args.coco_dir / GROUND_TRUTH} not found")
    if args.copies < 1 or args.repeats < 1:
        parser.error("--copies and --repeats: expected positive numbers")
    with tempfile.TemporaryDirectory(prefix="coco_scale_") as temporary:
        folder = Path(temporary)
        truth, results = replicate(args.coco_dir, folder, args.copies)
        print(f"load average {os.getloadavg()[0]:.2f}; {100 * args.copies} images; best of {args.repeats}")
        print(f"{'iou type':<9s} {'pycocotools wall/cpu [s]':>25s} {'paz6d wall/cpu [s]':>20s} "
              f"{'speed-up wall/cpu':>18s} {'stats identical':>16s}")
        failed = False
        for iou_type in args.iou_types:
            result_path = results[iou_type]
            out = folder / f"{iou_type}_paz6d.json"
            ours_command = [*paz6d_command(), "evaluate", "coco", "--gt", str(truth), "--results", str(result_path),
                            "--iou-type", iou_type, "--out", str(out)]
            theirs_command = [sys.executable, "-c", PYCOCOTOOLS, str(truth), str(result_path), iou_type]
            ours, theirs = [], []
            for _ in range(args.repeats):
                theirs.append(run_process(theirs_command))
                ours.append(run_process(ours_command))
            reference = json.loads(theirs[0][2].splitlines()[-1])
            stats = json.loads(out.read_text())["stats"]
            identical = stats == reference
            failed |= not identical
            base_wall, base_cpu = min(r[0] for r in theirs), min(r[1] for r in theirs)
            our_wall, our_cpu = min(r[0] for r in ours), min(r[1] for r in ours)
            print(f"{iou_type:<9s} {base_wall:12.2f} / {base_cpu:10.2f} {our_wall:9.2f} / {our_cpu:8.2f} "
                  f"{base_wall / our_wall:8.2f}x / {base_cpu / our_cpu:6.2f}x {str(identical):>16s}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
