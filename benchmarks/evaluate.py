"""Evaluation speed against the obvious alternatives, in one run and one process.

* COCO bbox and segm mAP: paz6d ``evaluation.coco.evaluate_files`` vs pycocotools on the same files
  (``../shared/data/coco``: val2014 100-image ground truth, 734 cocoapi "fake" results). Both sides do
  the full job: load the ground-truth and results JSON, evaluate, accumulate, summarize; the 12
  summary numbers are checked to agree.
* ADD-S (ADI) and MSSD of each of the 1427 estimates of ``../shared/data/bop_lmo`` against its
  ground-truth instance on the ``models_eval`` meshes (mm):

  - baseline, the straightforward per-estimate implementation (as ``bop_toolkit_lib.pose_error``):
    ADI builds a ``cKDTree`` on the estimated posed points and queries the ground-truth posed
    points; MSSD loops over the symmetries and takes ``np.linalg.norm(...).max()`` over all points;
  - paz6d (``evaluation.pose_errors``): all estimates of an object in one call, one
    ``evaluation.point_tree.PointTree`` per object (queries mapped into the model frame), MSSD in a
    numba kernel over all points with the symmetries as one ``(S, 4, 4)`` array. Object setup (trees)
    is included in the timing.

Best of ``--repeats`` runs; wall and CPU (process) seconds are printed: on a shared machine the CPU
time is the steadier one. Run: ``.venv/bin/python benchmarks/evaluate.py [--repeats 3] [--workers 1]``
(``--workers -1``: paz6d's ADI on all cores; the baselines are single-threaded).
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from evaluation import coco, pose_errors  # noqa: E402
from paz6d.backend.mesh import load_mesh  # noqa: E402

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
COCO_RESULT_FILES = {"bbox": "instances_val2014_fakebbox100_results.json",
                     "segm": "instances_val2014_fakesegm100_results.json"}
COCO_GROUND_TRUTH_FILE = "instances_val2014_100.json"


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


def load(data: Path) -> dict[int, dict]:
    """Per object: points (N, 3) mm, symmetries (S, 4, 4), diameter, T_est and T_gt (E, 4, 4)."""
    scene = data / "test" / "000002"
    gt = json.loads((scene / "scene_gt.json").read_text())
    info = json.loads((data / "models_eval" / "models_info.json").read_text())
    objects: dict[int, dict] = {}
    with open(data / "results" / "results_lmo-test.csv", newline="") as file:
        for row in csv.DictReader(file):
            obj_id = int(row["obj_id"])
            if obj_id not in objects:
                entry = info[str(obj_id)]
                discrete = np.array(entry.get("symmetries_discrete", [])).reshape(-1, 4, 4)
                objects[obj_id] = {
                    "points": np.asarray(load_mesh(data / "models_eval" / f"obj_{obj_id:06d}.ply").vertices, float),
                    "symmetries": pose_errors.symmetry_transformations(discrete), "diameter": entry["diameter"],
                    "T_est": [], "T_gt": []}
            (instance,) = [g for g in gt[row["im_id"]] if g["obj_id"] == obj_id]
            for key, R, t in (("T_est", row["R"].split(), row["t"].split()),
                              ("T_gt", instance["cam_R_m2c"], instance["cam_t_m2c"])):
                T = np.eye(4)
                T[:3, :3] = np.asarray(R, dtype=np.float64).reshape(3, 3)
                T[:3, 3] = np.asarray(t, dtype=np.float64)
                objects[obj_id][key].append(T)
    for entry in objects.values():
        entry["T_est"], entry["T_gt"] = np.array(entry["T_est"]), np.array(entry["T_gt"])
    return objects


def baseline_adi(objects) -> dict[int, np.ndarray]:
    result = {}
    for obj_id, entry in objects.items():
        points, values = entry["points"], []
        for T_est, T_gt in zip(entry["T_est"], entry["T_gt"]):
            posed_est = points @ T_est[:3, :3].T + T_est[:3, 3]
            posed_gt = points @ T_gt[:3, :3].T + T_gt[:3, 3]
            values.append(cKDTree(posed_est).query(posed_gt, k=1)[0].mean())
        result[obj_id] = np.array(values)
    return result


def baseline_mssd(objects) -> dict[int, np.ndarray]:
    result = {}
    for obj_id, entry in objects.items():
        points, values = entry["points"], []
        for T_est, T_gt in zip(entry["T_est"], entry["T_gt"]):
            posed_est = points @ T_est[:3, :3].T + T_est[:3, 3]
            distances = []
            for symmetry in entry["symmetries"]:
                T_sym = T_gt @ symmetry
                distances.append(np.linalg.norm(posed_est - (points @ T_sym[:3, :3].T + T_sym[:3, 3]), axis=1).max())
            values.append(min(distances))
        result[obj_id] = np.array(values)
    return result


def ours_adi(objects, workers: int) -> dict[int, np.ndarray]:
    result = {}
    for obj_id, entry in objects.items():
        model = pose_errors.ObjectModel(entry["points"], entry["diameter"], entry["symmetries"])
        result[obj_id] = pose_errors.adi_error(entry["T_est"], entry["T_gt"], model.points, tree=model.tree,
                                               workers=workers)
    return result


def ours_mssd(objects) -> dict[int, np.ndarray]:
    result = {}
    for obj_id, entry in objects.items():
        model = pose_errors.ObjectModel(entry["points"], entry["diameter"], entry["symmetries"])
        result[obj_id] = pose_errors.mssd_error(entry["T_est"], entry["T_gt"], model.points, model.symmetries)
    return result


def timed(function, repeats: int):
    """(best wall seconds, best CPU seconds, result) over ``repeats`` calls."""
    walls, cpus, result = [], [], None
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        result = function()
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return min(walls), min(cpus), result


def max_difference(a: dict, b: dict) -> float:
    return max(float(np.max(np.abs(a[key] - b[key]))) for key in a)


def print_row(name: str, base_wall: float, base_cpu: float, our_wall: float, our_cpu: float, difference: float):
    print(f"{name:<14s} {base_wall:9.3f} / {base_cpu:8.3f} {our_wall:9.3f} / {our_cpu:8.3f} "
          f"{base_wall / our_wall:7.2f}x / {base_cpu / our_cpu:6.2f}x {difference:16.2e}")


def benchmark_coco(coco_dir: Path, repeats: int) -> None:
    ground_truth = coco_dir / COCO_GROUND_TRUTH_FILE
    print(f"\nCOCO: {ground_truth}; best of {repeats}")
    print(f"{'iou type':<14s} {'pycocotools wall/cpu [s]':>20s} {'paz6d wall/cpu [s]':>20s} "
          f"{'speed-up wall/cpu':>18s} {'max |stats diff|':>16s}")
    for iou_type, name in COCO_RESULT_FILES.items():
        results = coco_dir / name
        run_paz6d(ground_truth, results, iou_type)  # warm-up (imports, caches) for both sides
        run_pycocotools(ground_truth, results, iou_type)
        base_wall, base_cpu, reference = timed(lambda: run_pycocotools(ground_truth, results, iou_type), repeats)
        our_wall, our_cpu, ours = timed(lambda: run_paz6d(ground_truth, results, iou_type), repeats)
        print_row(iou_type, base_wall, base_cpu, our_wall, our_cpu, float(np.max(np.abs(ours - reference))))


def benchmark_pose(data: Path, repeats: int, workers: int) -> None:
    objects = load(data)
    count = sum(len(entry["T_est"]) for entry in objects.values())
    print(f"\nLM-O: {count} estimates, {len(objects)} objects, models_eval points per object "
          f"{min(len(e['points']) for e in objects.values())}-{max(len(e['points']) for e in objects.values())}; "
          f"paz6d workers={workers}, best of {repeats}")
    ours_adi(objects, workers)  # warm-up: loads (or compiles) the numba kernels
    print(f"{'error':<14s} {'scipy wall/cpu [s]':>20s} {'paz6d wall/cpu [s]':>20s} {'speed-up wall/cpu':>18s} "
          f"{'max |diff| [mm]':>16s}")
    rows = []
    for name, baseline, ours in (("ADD-S (ADI)", baseline_adi, lambda o: ours_adi(o, workers)),
                                 ("MSSD", baseline_mssd, ours_mssd)):
        base_wall, base_cpu, base_result = timed(lambda: baseline(objects), repeats)
        our_wall, our_cpu, our_result = timed(lambda: ours(objects), repeats)
        rows.append((name, base_wall, base_cpu, our_wall, our_cpu, max_difference(base_result, our_result)))
    rows.append(("ADD-S + MSSD", *(sum(row[column] for row in rows) for column in range(1, 5)),
                 max(row[5] for row in rows)))
    for row in rows:
        print_row(*row)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--coco-dir", type=Path, default=SHARED_DATA / "coco",
                        help="the coco folder of the shared data")
    parser.add_argument("--data", type=Path, default=SHARED_DATA / "bop_lmo",
                        help="the bop_lmo folder of the shared data")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each side (best time is kept)")
    parser.add_argument("--workers", type=int, default=1, help="threads of paz6d's ADI (-1 = all cores)")
    args = parser.parse_args()
    for folder in (args.coco_dir, args.data):
        if not folder.is_dir():
            parser.error(f"{folder}: shared data not found")
    benchmark_coco(args.coco_dir, args.repeats)
    benchmark_pose(args.data, args.repeats, args.workers)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
