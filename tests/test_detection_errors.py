"""The per-class error breakdown of ``evaluation.detection_errors`` and ``paz6d evaluate coco --errors``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from evaluation.coco import CocoDetections, CocoGroundTruth
from evaluation.detection_errors import ERROR_KINDS, detection_errors
from paz6d.cli import main


def _truth() -> dict:
    boxes = [(1, 1, [0, 0, 10, 10], 0), (2, 1, [20, 0, 10, 10], 0), (3, 2, [0, 0, 10, 10], 0),
             (4, 2, [50, 50, 20, 20], 1)] + [(4 + i, 2 + i, [0, 0, 10, 10], 0) for i in range(1, 5)]
    categories = {1: 1, 2: 2}
    annotations = [{"id": aid, "image_id": image, "category_id": 2 if aid == 2 else 1, "bbox": box,
                    "area": box[2] * box[3], "iscrowd": crowd} for aid, image, box, crowd in boxes]
    return {"images": [{"id": i, "width": 100, "height": 100} for i in range(1, 7)], "annotations": annotations,
            "categories": [{"id": c, "name": f"class_{c}"} for c in categories]}


#: (score, image, box, expected kind) for class 1, whose 6 objects are in images 1, 2 (and a crowd region), 3-6
DETECTIONS = [(0.9, 1, [0, 0, 10, 10], "correct"),
              (0.8, 1, [1, 0, 10, 10], "duplicate"),       # IoU 0.82 with the object already taken
              (0.7, 2, [5, 0, 10, 10], "localization"),    # IoU 0.33 with the object of image 2
              (0.6, 1, [21, 0, 10, 10], "other_class"),    # on the class-2 object
              (0.5, 2, [55, 55, 5, 5], None),              # inside the crowd region: left out
              (0.4, 2, [80, 80, 5, 5], "background"),
              (0.3, 2, [0, 0, 10, 10], "correct"),
              (0.2, 3, [60, 60, 10, 10], "background")]    # beyond the top 6


def _iou(a, b) -> float:
    """Brute-force IoU of two ``[x, y, w, h]`` boxes."""
    w = max(0.0, min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0]))
    h = max(0.0, min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1]))
    return w * h / (a[2] * a[3] + b[2] * b[3] - w * h)


def test_breakdown_of_hand_made_detections():
    truth = CocoGroundTruth.from_dict(_truth())
    results = [{"image_id": image, "category_id": 1, "bbox": box, "score": score} for score, image, box,
               _ in DETECTIONS]
    errors = detection_errors(truth, CocoDetections.from_list(results, truth))
    assert errors.category_names == ("class_1", "class_2")
    np.testing.assert_array_equal(errors.objects, [6, 1])
    np.testing.assert_allclose(errors.recall, [2 / 6, 0.0])
    expected = [kind for *_, kind in DETECTIONS if kind is not None][:6]
    np.testing.assert_array_equal(errors.top[0], [expected.count(kind) for kind in ERROR_KINDS])
    np.testing.assert_array_equal(errors.top[1], np.zeros(len(ERROR_KINDS)))
    assert errors.to_dict()["class_1"] == {"objects": 6, "recall": 2 / 6, "correct": 2, "duplicate": 1,
                                           "localization": 1, "other_class": 1, "background": 1,
                                           "called": {"class_1": 2, "none": 4}}
    # the class-2 object is found only by a class-1 detection (IoU 0.82): the detector calls it class 1
    assert errors.called_names == ("class_1", "class_2", "none")
    np.testing.assert_array_equal(errors.confusion, [[2, 0, 4], [1, 0, 0]])
    assert "class_2                  class_1 1" in errors.table()
    masks_only = CocoDetections.from_list([{"image_id": 1, "category_id": 1, "score": 1.0,
                                            "segmentation": {"size": [100, 100], "counts": "PPYo1"}}], truth)
    with pytest.raises(ValueError, match="needs boxes"):
        detection_errors(truth, masks_only)


def test_recall_matches_a_brute_force_count():
    rng = np.random.default_rng(0)
    truth_dict = {"images": [{"id": i} for i in range(5)], "categories": [{"id": 1, "name": "a"}],
                  "annotations": []}
    for index in range(12):
        x, y = rng.uniform(0, 80, 2)
        truth_dict["annotations"].append({"id": index + 1, "image_id": int(index % 5), "category_id": 1,
                                          "bbox": [x, y, 15, 15], "area": 225, "iscrowd": 0})
    results = []
    for _ in range(40):
        x, y = rng.uniform(0, 80, 2)
        results.append({"image_id": int(rng.integers(5)), "category_id": 1, "bbox": [x, y, 15, 15],
                        "score": float(rng.random())})
    truth = CocoGroundTruth.from_dict(truth_dict)
    errors = detection_errors(truth, CocoDetections.from_list(results, truth))

    taken = set()
    for result in sorted(results, key=lambda r: -r["score"]):
        free = [(_iou(result["bbox"], a["bbox"]), a["id"]) for a in truth_dict["annotations"]
                if a["image_id"] == result["image_id"] and a["id"] not in taken]
        best = max(free, default=(0.0, None))
        if best[0] >= 0.5:
            taken.add(best[1])
    assert errors.recall[0] == pytest.approx(len(taken) / 12)
    assert errors.top[0].sum() == 12 and errors.top[0][0] <= len(taken)


def test_evaluate_coco_errors_flag_writes_the_breakdown(tmp_path, capsys):
    truth, results = tmp_path / "truth.json", tmp_path / "results.json"
    truth.write_text(json.dumps(_truth()))
    results.write_text(json.dumps([{"image_id": image, "category_id": 1, "bbox": box, "score": score}
                                   for score, image, box, _ in DETECTIONS]))
    assert main(["evaluate", "coco", "--gt", str(truth), "--results", str(results), "--out", str(tmp_path / "o.json"),
                 "--errors"]) == 0
    report = json.loads((tmp_path / "o.json").read_text())
    assert report["errors"]["class_1"]["duplicate"] == 1 and report["errors"]["class_2"]["objects"] == 1
    assert "background" in capsys.readouterr().out
    assert report["errors"]["class_2"]["called"] == {"class_1": 1}
    assert main(["evaluate", "coco", "--gt", str(truth), "--results", str(results), "--out", str(tmp_path / "q.json"),
                 "--errors", "--plots", str(tmp_path / "plots")]) == 0
    confusion = tmp_path / "plots" / "coco_bbox_confusion.png"
    assert confusion.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["evaluate", "coco", "--gt", str(truth), "--results", str(results), "--out",
                 str(tmp_path / "p.json")]) == 0
    assert "errors" not in json.loads((tmp_path / "p.json").read_text())


def test_confusion_matches_a_brute_force_loop():
    rng = np.random.default_rng(3)
    names = {1: "a", 2: "b", 5: "c"}
    truth_dict = {"images": [{"id": i} for i in range(6)], "annotations": [],
                  "categories": [{"id": c, "name": n} for c, n in names.items()]}
    for index in range(30):
        x, y = rng.uniform(0, 60, 2)
        truth_dict["annotations"].append({"id": index + 1, "image_id": int(index % 6),
                                          "category_id": int(rng.choice([1, 2, 5])),
                                          "bbox": [x, y, 20, 20], "area": 400, "iscrowd": int(index == 7)})
    results = []
    for ann in truth_dict["annotations"] * 2:
        x, y, w, h = ann["bbox"]
        results.append({"image_id": ann["image_id"], "category_id": int(rng.choice([1, 2, 5, 9])),
                        "score": float(rng.random()),
                        "bbox": [x + rng.normal(0, 4), y + rng.normal(0, 4), w, h]})
    truth = CocoGroundTruth.from_dict(truth_dict)
    errors = detection_errors(truth, CocoDetections.from_list(results, truth))

    expected = {name: {} for name in names.values()}
    for ann in truth_dict["annotations"]:
        if ann["iscrowd"]:
            continue
        hits = [r for r in results if r["image_id"] == ann["image_id"] and r["category_id"] in names
                and _iou(r["bbox"], ann["bbox"]) >= 0.5]
        called = names[max(hits, key=lambda r: r["score"])["category_id"]] if hits else "none"
        row = expected[names[ann["category_id"]]]
        row[called] = row.get(called, 0) + 1
    report = errors.to_dict()
    assert {name: report[name]["called"] for name in report} == {name: row for name, row in expected.items() if row}
    np.testing.assert_array_equal(errors.confusion.sum(axis=1), errors.objects)
