"""COCO evaluation against pycocotools (the oracle) and the published numbers in shared/data/coco."""

from __future__ import annotations

import contextlib
import copy
import gc
import io
import json
from pathlib import Path

import numpy as np
import pytest

from evaluation import coco

pycocotools = pytest.importorskip("pycocotools")
from pycocotools import mask as mask_utils  # noqa: E402
from pycocotools.coco import COCO  # noqa: E402
from pycocotools.cocoeval import COCOeval  # noqa: E402

TOLERANCE = 1e-9
RESULT_FILES = {"bbox": "instances_val2014_fakebbox100_results.json",
                "segm": "instances_val2014_fakesegm100_results.json"}


def pycocotools_eval(gt: dict, results: list, iou_type: str) -> COCOeval:
    """Runs pycocotools on deep copies (it edits its inputs) with its printing silenced."""
    with contextlib.redirect_stdout(io.StringIO()):
        truth = COCO()
        truth.dataset = copy.deepcopy(gt)
        truth.createIndex()
        detections = truth.loadRes(copy.deepcopy(results))
        evaluator = COCOeval(truth, detections, iou_type)
        evaluator.evaluate()
        evaluator.accumulate()
        evaluator.summarize()
    return evaluator


def ours(gt: dict, results: list, iou_type: str) -> coco.CocoEvaluation:
    truth = coco.CocoGroundTruth.from_dict(copy.deepcopy(gt))
    return coco.evaluate(truth, coco.CocoDetections.from_list(copy.deepcopy(results), truth), iou_type)


def assert_same_as_pycocotools(gt: dict, results: list, iou_type: str) -> coco.CocoEvaluation:
    reference = pycocotools_eval(gt, results, iou_type)
    result = ours(gt, results, iou_type)
    np.testing.assert_allclose(result.stats, reference.stats, rtol=0, atol=TOLERANCE)
    np.testing.assert_allclose(result.precision, reference.eval["precision"], rtol=0, atol=TOLERANCE)
    np.testing.assert_allclose(result.recall, reference.eval["recall"], rtol=0, atol=TOLERANCE)
    return result


@pytest.mark.parametrize("iou_type", ["bbox", "segm"])
def test_shared_coco_matches_published_stats_and_pycocotools(shared_data, iou_type):
    folder = shared_data / "coco"
    expected = json.loads((folder / "expected_stats.json").read_text())
    gt = json.loads((folder / "instances_val2014_100.json").read_text())
    results = json.loads((folder / RESULT_FILES[iou_type]).read_text())
    result = assert_same_as_pycocotools(gt, results, iou_type)
    np.testing.assert_allclose(result.stats, expected[iou_type], rtol=0, atol=TOLERANCE)
    from_files = coco.evaluate_files(folder / "instances_val2014_100.json", folder / RESULT_FILES[iou_type], iou_type)
    np.testing.assert_array_equal(from_files.stats, result.stats)
    assert result.stats_dict()["AP"] == pytest.approx({"bbox": 0.505, "segm": 0.320}[iou_type], abs=5e-4)


# ------------------------------------------------------------------------------------------------
# synthetic data sets covering crowd regions, area ranges, empty images, absent categories, maxDets
# ------------------------------------------------------------------------------------------------

def column_major_counts(mask: np.ndarray) -> list[int]:
    """Uncompressed COCO RLE counts of a boolean mask, written independently of the library."""
    flat = mask.T.ravel().astype(np.int8)
    changes = np.flatnonzero(np.diff(np.concatenate([[0], flat, [1 - flat[-1]]])))
    return np.diff(np.concatenate([[0], changes])).tolist() if flat[0] == 0 else \
        [0] + np.diff(np.concatenate([[0], changes])).tolist()[1:]


def polygon_around(rng: np.random.Generator, box: list[float], vertices: int = 9) -> list[float]:
    x, y, w, h = box
    angles = np.sort(rng.uniform(0, 2 * np.pi, vertices))
    radius = rng.uniform(0.6, 1.0, vertices)
    xs = x + w / 2 + radius * np.cos(angles) * w / 2
    ys = y + h / 2 + radius * np.sin(angles) * h / 2
    return np.round(np.stack([xs, ys], axis=1).ravel(), 2).tolist()


def synthetic_dataset(seed: int, with_masks: bool) -> tuple[dict, list]:
    """Ground truth with crowd regions, empty images, categories without GT or detections."""
    rng = np.random.default_rng(seed)
    size = 160
    images = [{"id": int(i), "height": size, "width": size + 20} for i in rng.choice(1000, 16, replace=False)]
    categories = [{"id": c, "name": f"class{c}"} for c in (1, 3, 4, 7, 9)]  # 9: detections only, 7: GT only
    annotations, results = [], []
    next_id = 1
    for image in images[2:]:  # the first two images stay empty
        for _ in range(rng.integers(0, 6)):
            category = int(rng.choice([1, 3, 4, 7]))
            side = float(rng.choice([8.0, 20.0, 45.0, 110.0])) * rng.uniform(0.7, 1.3)
            w, h = min(side * rng.uniform(0.7, 1.3), 0.9 * size), min(side * rng.uniform(0.7, 1.3), 0.9 * size)
            x, y = rng.uniform(0, size + 20 - w), rng.uniform(0, size - h)
            box = [round(x, 2), round(y, 2), round(w, 2), round(h, 2)]
            crowd = rng.random() < 0.12
            annotation = {"id": next_id, "image_id": image["id"], "category_id": category, "bbox": box,
                          "iscrowd": int(crowd), "area": round(w * h * rng.uniform(0.6, 1.0), 2)}
            if crowd:
                mask = np.zeros((size, size + 20), dtype=bool)
                mask[int(y):int(y + h), int(x):int(x + w)] = True
                annotation["segmentation"] = {"size": [size, size + 20], "counts": column_major_counts(mask)}
            else:
                annotation["segmentation"] = [polygon_around(rng, box)]
                if rng.random() < 0.2:  # a second part
                    annotation["segmentation"].append(polygon_around(rng, [x + w / 3, y, w / 2, h / 2], 5))
            annotations.append(annotation)
            next_id += 1
            if rng.random() < 0.1:  # an identical twin: IoU ties between ground truths
                annotations.append(dict(copy.deepcopy(annotation), id=next_id))
                next_id += 1
            for _ in range(rng.integers(0, 3)):  # detections near this object
                jitter = rng.normal(0, 0.12 * side, 4)
                det_box = [box[0] + jitter[0], box[1] + jitter[1], max(1.0, box[2] + jitter[2]),
                           max(1.0, box[3] + jitter[3])]
                keep = category != 7 and rng.random() < 0.85
                det_category = category if keep else int(rng.choice([1, 3, 4, 9]))
                results.append(_detection(rng, image, det_category, det_box, with_masks))
        for _ in range(rng.integers(0, 4)):  # false positives anywhere
            w, h = rng.uniform(5, 90, 2)
            box = [rng.uniform(0, size + 20 - w), rng.uniform(0, size - h), w, h]
            results.append(_detection(rng, image, int(rng.choice([1, 3, 4, 9, 42])), box, with_masks))  # 42: unknown
    # one image/category with more than 100 detections exercises the maxDets cut
    crowded = images[5]
    for _ in range(105):
        w, h = rng.uniform(5, 60, 2)
        box = [rng.uniform(0, size + 20 - w), rng.uniform(0, size - h), w, h]
        results.append(_detection(rng, crowded, 3, box, with_masks))
    annotations.append({"id": next_id, "image_id": crowded["id"], "category_id": 3, "bbox": [10.0, 10.0, 40.0, 30.0],
                        "iscrowd": 0, "area": 1200.0, "segmentation": [[10, 10, 50, 10, 50, 40, 10, 40]]})
    crowd_mask = np.zeros((size, size + 20), dtype=bool)
    crowd_mask[60:140, 90:170] = True
    annotations.append({"id": next_id + 1, "image_id": crowded["id"], "category_id": 3, "iscrowd": 1,
                        "bbox": [90.0, 60.0, 80.0, 80.0], "area": 6400.0,
                        "segmentation": {"size": [size, size + 20], "counts": column_major_counts(crowd_mask)}})
    order = rng.permutation(len(results))
    gt = {"images": images, "annotations": annotations, "categories": categories}
    return gt, [results[i] for i in order]


def _detection(rng, image, category, box, with_masks: bool) -> dict:
    score = float(np.round(rng.uniform(0.05, 1.0), 1))  # coarse scores: many ties
    x, y, w, h = [float(v) for v in box]
    result = {"image_id": image["id"], "category_id": category, "score": score, "bbox": [x, y, w, h]}
    if with_masks:
        mask = np.zeros((image["height"], image["width"]), dtype=np.uint8, order="F")
        mask[int(max(y, 0)):int(y + h), int(max(x, 0)):int(x + w)] = 1
        mask[int(max(y, 0)):int(y + h / 3), int(max(x, 0)):int(x + w / 4)] = 0  # not a plain box
        rle = mask_utils.encode(mask)
        result = {"image_id": image["id"], "category_id": category, "score": score,
                  "segmentation": {"size": rle["size"], "counts": rle["counts"].decode("ascii")}}
    return result


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_synthetic_bbox_matches_pycocotools(seed):
    gt, results = synthetic_dataset(seed, with_masks=False)
    result = assert_same_as_pycocotools(gt, results, "bbox")
    category_7 = list(result.category_ids).index(7)
    assert np.all(result.precision[:, :, category_7, 0, :] <= 0)  # GT but no detections: zeros
    category_9 = list(result.category_ids).index(9)
    assert np.all(result.precision[:, :, category_9] == -1)  # detections but no GT: undefined


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_synthetic_segm_matches_pycocotools(seed):
    gt, results = synthetic_dataset(seed, with_masks=True)
    assert any(a["iscrowd"] for a in gt["annotations"])
    assert_same_as_pycocotools(gt, results, "segm")


def test_segm_results_with_boxes_use_box_areas_like_pycocotools():
    gt, results = synthetic_dataset(4, with_masks=True)
    for result in results:  # detectron-style output: mask plus a box whose area differs from the mask's
        rle = result["segmentation"]
        x, y, w, h = mask_utils.toBbox(rle).tolist()
        result["bbox"] = [x, y, w * 1.5, h * 1.5]
    assert_same_as_pycocotools(gt, results, "segm")


def test_bbox_evaluation_of_mask_only_results_derives_boxes_from_masks():
    gt, results = synthetic_dataset(5, with_masks=True)
    assert_same_as_pycocotools(gt, results, "bbox")


def test_empty_results_give_zero_recall_where_ground_truth_exists():
    gt, _ = synthetic_dataset(0, with_masks=False)
    result = ours(gt, [], "bbox")
    assert np.all(result.stats[[0, 1, 2, 6, 7, 8]] == 0.0)
    assert result.per_category_ap()["class9"] is None
    assert result.per_category_ap()["class1"] == 0.0


def test_per_category_ap_is_mean_over_thresholds_and_recalls():
    gt, results = synthetic_dataset(1, with_masks=False)
    reference = pycocotools_eval(gt, results, "bbox")
    result = ours(gt, results, "bbox")
    for k, (name, value) in enumerate(result.per_category_ap().items()):
        block = reference.eval["precision"][:, :, k, 0, -1]
        if np.all(block == -1):
            assert value is None
        else:
            assert value == pytest.approx(np.mean(block[block > -1]), abs=TOLERANCE)
    curve = result.precision_curve(0.5)
    assert curve.shape == (101,)
    with pytest.raises(ValueError, match="iou_threshold"):
        result.precision_curve(0.52)


# ------------------------------------------------------------------------------------------------
# bad input
# ------------------------------------------------------------------------------------------------

def test_malformed_json_names_the_file(tmp_path):
    path = tmp_path / "broken.json"
    path.write_text('{"images": [')
    with pytest.raises(ValueError, match="broken.json.*invalid JSON"):
        coco.CocoGroundTruth.from_file(path)
    with pytest.raises(ValueError, match="missing.json.*not found"):
        coco.CocoGroundTruth.from_file(tmp_path / "missing.json")


def test_bad_ground_truth_fields_name_the_entry(tmp_path):
    gt, _ = synthetic_dataset(0, with_masks=False)
    broken = copy.deepcopy(gt)
    broken["annotations"][3]["bbox"] = [1, 2, 3]
    with pytest.raises(ValueError, match=r"annotations\[3\]\.bbox must be \[x, y, w, h\]"):
        coco.CocoGroundTruth.from_dict(broken, "gt.json")
    broken = copy.deepcopy(gt)
    del broken["annotations"][0]["area"]
    with pytest.raises(ValueError, match=r"gt.json: annotations\[0\]\.area"):
        coco.CocoGroundTruth.from_dict(broken, "gt.json")
    with pytest.raises(ValueError, match="expected a list under 'images'"):
        coco.CocoGroundTruth.from_dict({"annotations": [], "categories": []}, "gt.json")


def test_bad_results_name_the_entry(tmp_path):
    gt, results = synthetic_dataset(0, with_masks=False)
    truth = coco.CocoGroundTruth.from_dict(gt, "gt.json")
    broken = copy.deepcopy(results)
    broken[2]["score"] = "high"
    with pytest.raises(ValueError, match=r"dt.json: entry \[2\]\.score"):
        coco.CocoDetections.from_list(broken, truth, "dt.json")
    broken = copy.deepcopy(results)
    broken[4]["image_id"] = 123456
    with pytest.raises(ValueError, match=r"entry \[4\] has image_id 123456"):
        coco.CocoDetections.from_list(broken, truth, "dt.json")
    path = tmp_path / "dt.json"
    path.write_text(json.dumps({"not": "a list"}))
    with pytest.raises(ValueError, match="dt.json: expected a COCO results list"):
        coco.CocoDetections.from_file(path, truth)


def test_bad_masks_and_iou_type_raise():
    gt, results = synthetic_dataset(0, with_masks=True)
    truth = coco.CocoGroundTruth.from_dict(gt, "gt.json")
    broken = copy.deepcopy(results)
    broken[0]["segmentation"]["counts"] = "not RLE!"
    with pytest.raises(ValueError, match="compressed RLE counts must use characters"):
        coco.evaluate(truth, coco.CocoDetections.from_list(broken, truth, "dt.json"), "segm")
    broken = copy.deepcopy(results)
    broken[1]["segmentation"]["size"] = [10, 10]
    with pytest.raises(ValueError, match="differs from the image size"):
        coco.evaluate(truth, coco.CocoDetections.from_list(broken, truth, "dt.json"), "segm")
    with pytest.raises(ValueError, match="iou_type"):
        coco.evaluate(truth, coco.CocoDetections.from_list(results, truth), "keypoints")


# ------------------------------------------------------------------------------------------------
# command line: paz6d evaluate coco
# ------------------------------------------------------------------------------------------------

def run_cli(argv: list[str]) -> int:
    import argparse

    from evaluation import cli

    parser = argparse.ArgumentParser(prog="paz6d evaluate")
    cli.configure(parser)
    return cli.run(parser.parse_args(argv))


@pytest.mark.parametrize("iou_type", ["bbox", "segm"])
def test_cli_writes_json_table_and_plots(tmp_path, capsys, iou_type):
    gt, results = synthetic_dataset(6, with_masks=iou_type == "segm")
    (tmp_path / "gt.json").write_text(json.dumps(gt))
    (tmp_path / "dt.json").write_text(json.dumps(results))
    out = tmp_path / "report" / "coco.json"
    code = run_cli(["coco", "--gt", str(tmp_path / "gt.json"), "--results", str(tmp_path / "dt.json"),
                    "--iou-type", iou_type, "--out", str(out), "--plots", str(tmp_path / "plots")])
    assert code == 0
    report = json.loads(out.read_text())
    reference = pycocotools_eval(gt, results, iou_type)
    np.testing.assert_allclose(report["stats"], reference.stats, rtol=0, atol=TOLERANCE)
    assert report["stat_names"] == list(coco.STAT_NAMES)
    assert report["per_class_ap"]["class9"] is None and set(report["per_class_ap"]) == {f"class{c}" for c in (1, 3, 4,
                                                                                                              7, 9)}
    printed = capsys.readouterr().out
    assert "AP50" in printed and "class3" in printed
    for name in (f"coco_{iou_type}_pr.png", f"coco_{iou_type}_ap_per_class.png"):
        data = (tmp_path / "plots" / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000
    assert not list(out.parent.glob(".*.tmp"))  # the temporary file was renamed away


def test_cli_reports_malformed_results_file(tmp_path):
    gt, _ = synthetic_dataset(0, with_masks=False)
    (tmp_path / "gt.json").write_text(json.dumps(gt))
    (tmp_path / "dt.json").write_text("[{'image_id': 1}]")
    with pytest.raises(ValueError, match="dt.json: invalid JSON"):
        run_cli(["coco", "--gt", str(tmp_path / "gt.json"), "--results", str(tmp_path / "dt.json"),
                 "--out", str(tmp_path / "out.json")])
    assert not (tmp_path / "out.json").exists()


def test_cli_dispatches_bop_to_bop_cli(monkeypatch):
    import argparse

    from evaluation import bop_cli, cli

    calls = []
    monkeypatch.setattr(bop_cli, "run", lambda args: calls.append(args.results) or 7)
    parser = argparse.ArgumentParser()
    cli.configure(parser)
    args = parser.parse_args(["bop", "--dataset", "d", "--results", "r.csv", "--out", "o.json"])
    assert cli.run(args) == 7 and calls == [Path("r.csv")]


@pytest.mark.parametrize("preset, expected", [(None, "1"), ("3", "3")])
def test_cli_asks_for_one_blas_thread_unless_the_user_chose(preset, expected):
    import os
    import subprocess
    import sys

    env = {key: value for key, value in os.environ.items() if key != "OPENBLAS_NUM_THREADS"}
    if preset is not None:
        env["OPENBLAS_NUM_THREADS"] = preset
    code = ("import sys, os; import evaluation.cli; "
            "print(os.environ['OPENBLAS_NUM_THREADS'], 'cv2' in sys.modules, 'evaluation.coco' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True,
                         cwd=Path(__file__).resolve().parents[1]).stdout.split()
    assert out == [expected, "False", "False"]  # and neither OpenCV nor the COCO scorer loads with the parser


def test_recall_thresholds_reached_equals_searchsorted():
    rng = np.random.default_rng(31)
    thresholds = coco.RECALL_THRESHOLDS
    recalls = np.concatenate([rng.integers(0, 400, 20000) / rng.integers(1, 400, 20000), thresholds,
                              np.nextafter(thresholds, 2.0), np.nextafter(thresholds, -1.0), np.arange(301) / 300,
                              [5.0]])
    recalls = recalls[(recalls >= 0) & np.isfinite(recalls)]
    np.testing.assert_array_equal(coco._recall_thresholds_reached(recalls),
                                  np.searchsorted(thresholds, recalls, side="right"))


def test_evaluate_files_restores_the_garbage_collector(shared_data):
    folder = shared_data / "coco"
    assert gc.isenabled()
    coco.evaluate_files(folder / "instances_val2014_100.json", folder / RESULT_FILES["bbox"], "bbox")
    assert gc.isenabled()
    gc.disable()
    try:
        coco.evaluate_files(folder / "instances_val2014_100.json", folder / RESULT_FILES["bbox"], "bbox")
        assert not gc.isenabled()
    finally:
        gc.enable()
