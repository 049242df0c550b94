"""VOC AP: published numbers (shared/data/voc/expected_ap.json) and a devkit-style reference loop."""

from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pytest

from evaluation import voc

METHOD_KEYS = {"11point": "eleven_point", "allpoint": "every_point"}


@pytest.mark.parametrize("method", ["11point", "allpoint"])
@pytest.mark.parametrize("iou", ["0.1", "0.3", "0.5", "0.75"])
def test_test_case_1_matches_published_ap(shared_data, method, iou):
    folder = shared_data / "voc"
    expected = json.loads((folder / "expected_ap.json").read_text())["test_case_1"]
    result = voc.evaluate_directories(folder / "test_case_1" / "gts", folder / "test_case_1" / "dets",
                                      float(iou), method, box_format="xywh")
    assert list(result.per_class) == ["object"]
    record = result.per_class["object"]
    assert (record.ground_truth_count, record.detection_count) == (expected["n_gt"], expected["n_det"])
    # published with 10 decimals (truncated), hence the 1e-10 tolerance
    assert record.average_precision == pytest.approx(expected[METHOD_KEYS[method]][iou], abs=1e-10)
    assert result.mean_average_precision == record.average_precision


@pytest.mark.parametrize("method", ["11point", "allpoint"])
@pytest.mark.parametrize("iou", ["0.5", "0.75"])
@pytest.mark.parametrize("folder_name, box_format", [("dets_classname_abs_xyx2y2", "xyxy"),
                                                     ("dets_classname_abs_xywh", "xywh")])
def test_toyexample_cat_matches_published_ap(shared_data, method, iou, folder_name, box_format):
    folder = shared_data / "voc"
    expected = json.loads((folder / "expected_ap.json").read_text())["toyexample"]
    result = voc.evaluate_directories(folder / "toyexample" / "gts_vocpascal_format",
                                      folder / "toyexample" / folder_name,
                                      float(iou), method, box_format=box_format)
    record = result.per_class["cat"]
    assert (record.ground_truth_count, record.detection_count) == (expected["n_gt"], expected["n_det"])
    percent = expected[METHOD_KEYS[method] + "_percent"][iou]
    assert 100 * record.average_precision == pytest.approx(percent, abs=0.005)  # published with 2 decimals


def test_tie_order_follows_file_order(shared_data, tmp_path):
    """Renaming files changes the order of equal scores, which changes AP@0.1 (PROVENANCE §6)."""
    source = shared_data / "voc" / "test_case_1"
    reference = voc.evaluate_directories(source / "gts", source / "dets", 0.1, "11point", "xywh")
    for kind in ("gts", "dets"):
        (tmp_path / kind).mkdir()
        files = sorted((source / kind).glob("*.txt"))
        for index, path in enumerate(reversed(files)):
            shutil.copy(path, tmp_path / kind / f"{index:05d}.txt")
    reordered = voc.evaluate_directories(tmp_path / "gts", tmp_path / "dets", 0.1, "11point", "xywh")
    assert reference.per_class["object"].average_precision == pytest.approx(1 / 3, abs=1e-12)
    assert reordered.per_class["object"].average_precision != pytest.approx(1 / 3, abs=1e-6)


def test_devkit_layout_and_class_name_mapping_give_the_same_results(shared_data, tmp_path):
    folder = shared_data / "voc" / "database"
    names = voc.read_class_names(folder / "voc.names")
    by_id = voc.evaluate_directories(folder / "gts_pascalvoc_format", folder / "dets_abs_xyx2y2", 0.5, "allpoint",
                                     class_names=names)
    # the same detections rewritten as devkit results, one comp4_det_test_<class>.txt per class
    lines: dict[str, list[str]] = {}
    for path in sorted((folder / "dets_abs_xyx2y2").glob("*.txt")):
        for line in path.read_text().splitlines():
            if line.strip():
                class_id, *rest = line.split()
                lines.setdefault(names[int(class_id)], []).append(" ".join([path.stem, *rest]))
    for name, rows in lines.items():
        (tmp_path / f"comp4_det_test_{name}.txt").write_text("\n".join(rows) + "\n")
    by_class_file = voc.evaluate_directories(folder / "gts_pascalvoc_format", tmp_path, 0.5, "allpoint")
    assert sorted(by_id.per_class) == sorted(by_class_file.per_class)
    assert len(by_id.per_class) == 20
    for name, record in by_id.per_class.items():
        assert record.average_precision == pytest.approx(by_class_file.per_class[name].average_precision, abs=1e-12)
    assert 0.0 < by_id.mean_average_precision < 1.0
    assert sum(r.ground_truth_count for r in by_id.per_class.values()) < 247  # difficult objects excluded


# ------------------------------------------------------------------------------------------------
# reference: the VOC devkit loop, written independently of the library
# ------------------------------------------------------------------------------------------------

def devkit_ap(gt, detections, threshold, method, plus_one):
    """gt: {image: [(box, difficult)]}; detections: [(image, score, box)] -> AP (VOC devkit loop)."""
    extra = 1.0 if plus_one else 0.0
    positives = sum(1 for objects in gt.values() for _, hard in objects if not hard)
    taken = {image: [False] * len(objects) for image, objects in gt.items()}
    ordered = sorted(detections, key=lambda d: -d[1])  # Python's sort is stable
    tp, fp = [], []
    for image, _, box in ordered:
        best, best_index = -math.inf, -1
        for index, (truth, _) in enumerate(gt.get(image, [])):
            iw = min(box[2], truth[2]) - max(box[0], truth[0]) + extra
            ih = min(box[3], truth[3]) - max(box[1], truth[1]) + extra
            inter = max(iw, 0.0) * max(ih, 0.0)
            union = ((box[2] - box[0] + extra) * (box[3] - box[1] + extra)
                     + (truth[2] - truth[0] + extra) * (truth[3] - truth[1] + extra) - inter)
            overlap = inter / union
            if overlap > best:
                best, best_index = overlap, index
        if best >= threshold:
            if gt[image][best_index][1]:
                tp.append(0), fp.append(0)
            elif not taken[image][best_index]:
                taken[image][best_index] = True
                tp.append(1), fp.append(0)
            else:
                tp.append(0), fp.append(1)
        else:
            tp.append(0), fp.append(1)
    tp, fp = np.cumsum(tp, dtype=float), np.cumsum(fp, dtype=float)
    recall = tp / positives
    precision = tp / np.maximum(tp + fp, np.finfo(float).eps)
    if method == "11point":
        return sum((max(precision[recall >= t]) if np.any(recall >= t) else 0.0) for t in np.linspace(0, 1, 11)) / 11
    mrec = [0.0, *recall, 1.0]
    mpre = [0.0, *precision, 0.0]
    for i in range(len(mpre) - 2, -1, -1):
        mpre[i] = max(mpre[i], mpre[i + 1])
    return sum((mrec[i] - mrec[i - 1]) * mpre[i] for i in range(1, len(mrec)) if mrec[i] != mrec[i - 1])


def write_random_case(rng, folder):
    """Per-image text files with two classes, difficult objects, score ties; returns the reference view."""
    (folder / "gt").mkdir()
    (folder / "det").mkdir()
    truth, found = {"a": {}, "b": {}}, {"a": [], "b": []}
    for image in range(12):
        name = f"img{image:02d}"
        gt_lines, det_lines = [], []
        for _ in range(rng.integers(0, 5)):
            cls = str(rng.choice(["a", "b"]))
            x, y = rng.integers(0, 80, 2)
            w, h = rng.integers(4, 40, 2)
            box = [float(x), float(y), float(x + w), float(y + h)]
            hard = bool(rng.random() < 0.25)
            gt_lines.append(f'<object><name>{cls}</name><difficult>{int(hard)}</difficult><bndbox><xmin>{box[0]:g}'
                            f'</xmin><ymin>{box[1]:g}</ymin><xmax>{box[2]:g}</xmax><ymax>{box[3]:g}</ymax></bndbox>'
                            '</object>')
            truth[cls].setdefault(name, []).append((box, hard))
            truth["b" if cls == "a" else "a"].setdefault(name, [])
            for _ in range(rng.integers(0, 3)):
                jitter = rng.integers(-6, 7, 4)
                det_box = [box[0] + jitter[0], box[1] + jitter[1], box[2] + abs(jitter[2]) + 1,
                           box[3] + abs(jitter[3]) + 1]
                score = float(rng.choice([0.3, 0.5, 0.7, 0.9]))
                det_lines.append(f"{cls} {score} {' '.join(f'{v:g}' for v in det_box)}")
                found[cls].append((name, score, det_box))
        for _ in range(rng.integers(0, 3)):
            cls = str(rng.choice(["a", "b"]))
            x, y = rng.integers(0, 80, 2)
            det_box = [float(x), float(y), float(x + 20), float(y + 15)]
            score = float(rng.choice([0.3, 0.5, 0.7, 0.9]))
            det_lines.append(f"{cls} {score} {' '.join(f'{v:g}' for v in det_box)}")
            found[cls].append((name, score, det_box))
        (folder / "gt" / f"{name}.xml").write_text(f"<annotation>{''.join(gt_lines)}</annotation>")
        (folder / "det" / f"{name}.txt").write_text("\n".join(det_lines) + "\n")
    return truth, found


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("method", ["11point", "allpoint"])
@pytest.mark.parametrize("plus_one", [True, False])
def test_random_cases_with_difficult_objects_match_the_devkit_loop(tmp_path, seed, method, plus_one):
    truth, found = write_random_case(np.random.default_rng(seed), tmp_path)
    result = voc.evaluate_directories(tmp_path / "gt", tmp_path / "det", 0.5, method, plus_one=plus_one)
    for cls in ("a", "b"):
        if cls not in result.per_class:
            continue
        expected = devkit_ap(truth[cls], found[cls], 0.5, method, plus_one)
        assert result.per_class[cls].average_precision == pytest.approx(expected, abs=1e-12)


def test_plus_one_changes_iou_as_documented():
    boxes = np.array([[0.0, 0.0, 9.0, 9.0]])
    shifted = np.array([[5.0, 0.0, 14.0, 9.0]])
    assert voc.box_iou(boxes, shifted, plus_one=True)[0] == pytest.approx(50 / 150)
    assert voc.box_iou(boxes, shifted, plus_one=False)[0] == pytest.approx(36 / 126)


def test_average_precision_methods_on_a_known_curve():
    recall = np.array([0.2, 0.4, 0.4, 0.8])
    precision = np.array([1.0, 0.5, 0.4, 0.6])
    # all-point: 0.2 * 1 + 0.6 * 0.6 ; 11-point: recall >= 0, .1, .2 -> 1; .3 ... .8 -> 0.6; .9, 1 -> 0
    assert voc.average_precision(recall, precision, "allpoint") == pytest.approx(0.2 + 0.36)
    assert voc.average_precision(recall, precision, "11point") == pytest.approx((3 * 1.0 + 6 * 0.6) / 11)
    with pytest.raises(ValueError, match="method"):
        voc.average_precision(recall, precision, "coco")


# ------------------------------------------------------------------------------------------------
# bad input
# ------------------------------------------------------------------------------------------------

def test_malformed_inputs_name_file_and_line(tmp_path):
    gt, det = tmp_path / "gt", tmp_path / "det"
    gt.mkdir()
    det.mkdir()
    (gt / "a.xml").write_text("<annotation><object><name>cat</name></object></annotation>")
    with pytest.raises(ValueError, match=r"a\.xml, <object> #1 \(cat\), field <bndbox>: missing"):
        voc.read_annotations(gt)
    (gt / "a.xml").write_text("<annotation><object>")
    with pytest.raises(ValueError, match=r"a\.xml: malformed XML"):
        voc.read_annotations(gt)
    (gt / "a.xml").write_text("<annotation><object><name>cat</name><bndbox><xmin>1</xmin><ymin>2</ymin>"
                              "<xmax>x</xmax><ymax>9</ymax></bndbox></object></annotation>")
    with pytest.raises(ValueError, match=r"a\.xml, <object> #1, field <bndbox>/<xmax>: expected a number, got 'x'"):
        voc.read_annotations(gt)
    (gt / "a.xml").unlink()
    (gt / "a.txt").write_text("cat 1 2 3 4\ncat 1 2 3\n")
    with pytest.raises(ValueError, match=r"a\.txt:2: expected '<class> <4 box numbers \(xyxy\)>', got 4 fields"):
        voc.read_annotations(gt)
    (gt / "a.txt").write_text("cat 1 2 3 4\n")
    (det / "a.txt").write_text("cat high 1 2 3 4\n")
    ground_truth = voc.read_annotations(gt)
    with pytest.raises(ValueError, match=r"a\.txt:1: expected '<class> <score>"):
        voc.read_detections(det, ground_truth)
    (det / "a.txt").write_text("cat 0.5 5 2 3 4\n")
    with pytest.raises(ValueError, match="negative size"):
        voc.read_detections(det, ground_truth)
    (det / "a.txt").write_text("cat 0.5 1 2 3 4\n")
    (det / "b.txt").write_text("cat 0.5 1 2 3 4\n")
    with pytest.raises(ValueError, match=r"b\.txt: image 'b' has no ground-truth annotation file"):
        voc.read_detections(det, ground_truth)
    (gt / "c.xml").write_text("<annotation/>")
    with pytest.raises(ValueError, match="both .xml and .txt"):
        voc.read_annotations(gt)
    with pytest.raises(ValueError, match="annotation directory not found"):
        voc.read_annotations(tmp_path / "nowhere")
    with pytest.raises(ValueError, match="class id 7"):
        (gt / "c.xml").unlink()
        (gt / "a.txt").write_text("7 1 2 3 4\n")
        voc.read_annotations(gt, class_names=["cat", "dog"])


def test_iou_equal_to_the_threshold_is_a_true_positive():
    truth = voc.VocGroundTruth(image_ids=("x",), image_index=np.array([0]), class_names=("cat",),
                               boxes=np.array([[0.0, 0.0, 10.0, 10.0]]), difficult=np.array([False]))
    found = voc.VocDetections(image_index=np.array([0]), class_names=("cat",),
                              boxes=np.array([[0.0, 0.0, 10.0, 5.0]]), scores=np.array([0.9]))
    exact = voc.evaluate(truth, found, iou_threshold=0.5, method="allpoint", plus_one=False)
    assert exact.per_class["cat"].true_positives == 1 and exact.mean_average_precision == 1.0
    stricter = voc.evaluate(truth, found, iou_threshold=0.51, method="allpoint", plus_one=False)
    assert stricter.per_class["cat"].false_positives == 1 and stricter.mean_average_precision == 0.0


# ------------------------------------------------------------------------------------------------
# command line: paz6d evaluate voc
# ------------------------------------------------------------------------------------------------

def run_cli(argv: list[str]) -> int:
    import argparse

    from evaluation import cli

    parser = argparse.ArgumentParser(prog="paz6d evaluate")
    cli.configure(parser)
    return cli.run(parser.parse_args(argv))


def test_cli_writes_json_table_and_plots(tmp_path, capsys):
    truth, found = write_random_case(np.random.default_rng(3), tmp_path)
    out = tmp_path / "voc.json"
    code = run_cli(["voc", "--annotations", str(tmp_path / "gt"), "--detections", str(tmp_path / "det"),
                    "--iou", "0.5", "--method", "11point", "--no-plus-one", "--out", str(out),
                    "--plots", str(tmp_path / "plots")])
    assert code == 0
    report = json.loads(out.read_text())
    assert (report["method"], report["iou_threshold"], report["plus_one"]) == ("11point", 0.5, False)
    for cls in ("a", "b"):
        expected = devkit_ap(truth[cls], found[cls], 0.5, "11point", plus_one=False)
        assert report["per_class"][cls]["ap"] == pytest.approx(expected, abs=1e-12)
    assert report["mAP"] == pytest.approx(np.mean([report["per_class"][c]["ap"] for c in ("a", "b")]))
    assert "mAP" in capsys.readouterr().out
    for name in ("voc_pr_a.png", "voc_pr_b.png", "voc_pr_all.png", "voc_ap_per_class.png"):
        assert (tmp_path / "plots" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_reproduces_test_case_1_and_rejects_bad_arguments(shared_data, tmp_path):
    folder = shared_data / "voc" / "test_case_1"
    out = tmp_path / "voc.json"
    assert run_cli(["voc", "--annotations", str(folder / "gts"), "--detections", str(folder / "dets"),
                    "--iou", "0.3", "--method", "allpoint", "--box-format", "xywh", "--out", str(out)]) == 0
    assert json.loads(out.read_text())["mAP"] == pytest.approx(0.2456866804, abs=1e-10)
    with pytest.raises(SystemExit):
        run_cli(["voc", "--annotations", str(folder / "gts"), "--detections", str(folder / "dets"),
                 "--iou", "1.5", "--out", str(out)])
    with pytest.raises(ValueError, match="detection directory not found"):
        run_cli(["voc", "--annotations", str(folder / "gts"), "--detections", str(tmp_path / "none"),
                 "--box-format", "xywh", "--out", str(out)])
    with pytest.raises(ValueError, match=r"00001\.txt:2: box .*negative size"):  # xywh read as xyxy
        run_cli(["voc", "--annotations", str(folder / "gts"), "--detections", str(folder / "dets"),
                 "--out", str(out)])


def test_paz6d_command_dispatches_to_the_evaluate_voc_subcommand(shared_data, tmp_path):
    """End to end through ``python -m paz6d.cli`` (skipped while the top-level CLI cannot start)."""
    import subprocess
    import sys

    probe = subprocess.run([sys.executable, "-m", "paz6d.cli", "evaluate", "--help"], capture_output=True, text=True)
    if probe.returncode != 0:
        pytest.skip("paz6d.cli cannot build its parser yet: " + probe.stderr.strip().splitlines()[-1])
    folder = shared_data / "voc" / "test_case_1"
    out = tmp_path / "voc.json"
    done = subprocess.run([sys.executable, "-m", "paz6d.cli", "evaluate", "voc", "--annotations", str(folder / "gts"),
                           "--detections", str(folder / "dets"), "--iou", "0.1", "--method", "11point",
                           "--box-format", "xywh", "--out", str(out)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert json.loads(out.read_text())["mAP"] == pytest.approx(1 / 3, abs=1e-10)
    failed = subprocess.run([sys.executable, "-m", "paz6d.cli", "evaluate", "voc", "--annotations", str(folder / "gts"),
                             "--detections", str(tmp_path / "none"), "--box-format", "xywh", "--out", str(out)],
                            capture_output=True, text=True)
    assert failed.returncode != 0 and "detection directory not found" in failed.stderr
