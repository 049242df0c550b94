"""Times paz6d COCO evaluation against pycocotools on the same files, in the same process.

Both sides do the full job: load the ground-truth and results JSON, evaluate, accumulate and
summarize. Reports the median of several repeats and the speed ratio, and checks that the 12
summary numbers agree.

Usage:
    .venv/bin/python benchmarks/evaluate_detection.py [--coco-dir ../shared/data/coco] [--repeats 5]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from evaluation import coco  # noqa: E402

RESULT_FILES = {"bbox": "instances_val2014_fakebbox100_results.json",
                "segm": "instances_val2014_fakesegm100_results.json"}
GROUND_TRUTH_FILE = "instances_val2014_100.json"


def run_pycocotools(ground_truth: Path, results: Path, iou_type: str) -> np.ndarray:
    """pycocotools load + evaluate + accumulate + summarize; returns the 12 stats."""
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    with contextlib.redirect_stdout(io.StringIO()):
        truth = COCO(str(ground_truth))
        detections = truth.loadRes(str(results))
        evaluator = COCOeval(truth, detections, iou_type)
        evaluator.evaluate()
        evaluator.accumulate()
        evaluator.summarize()
    return np.asarray(evaluator.stats)


def run_paz6d(ground_truth: Path, results: Path, iou_type: str) -> np.ndarray:
    """paz6d load + evaluate + accumulate + summarize; returns the 12 stats."""
    return coco.evaluate_files(ground_truth, results, iou_type).stats


def median_seconds(function, repeats: int, *args) -> tuple[float, np.ndarray]:
    times, output = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        output = function(*args)
        times.append(time.perf_counter() - start)
    return statistics.median(times), output


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--coco-dir", type=Path,
                        default=Path(__file__).resolve().parents[2] / "shared" / "data" / "coco")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    ground_truth = args.coco_dir / GROUND_TRUTH_FILE
    if not ground_truth.exists():
        print(f"missing {ground_truth}; pass --coco-dir", file=sys.stderr)
        return 1
    print(f"{'iou type':8s} {'pycocotools [s]':>16s} {'paz6d [s]':>10s} {'speed-up':>9s} {'max |stats diff|':>17s}")
    for iou_type, name in RESULT_FILES.items():
        results = args.coco_dir / name
        run_paz6d(ground_truth, results, iou_type)  # warm-up (imports, caches) for both sides
        run_pycocotools(ground_truth, results, iou_type)
        reference_time, reference = median_seconds(run_pycocotools, args.repeats, ground_truth, results, iou_type)
        our_time, ours = median_seconds(run_paz6d, args.repeats, ground_truth, results, iou_type)
        difference = float(np.max(np.abs(ours - reference)))
        print(f"{iou_type:8s} {reference_time:16.3f} {our_time:10.3f} {reference_time / our_time:8.2f}x "
              f"{difference:17.2e}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
