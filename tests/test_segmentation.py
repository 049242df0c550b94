"""The instance-segmentation mask head: model shapes and save/load, pasting masks back into the image,
a tiny training run, the SegmentInstances / DetectAndSegment pipelines, COCO segm scoring and run-directory
errors."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from paz6d.abstract import Box2D
from paz6d.cli import main
from paz6d.datasets.coco import mask_from_counts
from paz6d.run_dirs import method_of
from paz6d.segmentation.config import QUICK, SegmentationTraining
from paz6d.segmentation.dataset import crop_batch, load_mask_set
from paz6d.segmentation.masks import blank_background, jitter_box, paste_mask, rle_from_mask
from paz6d.segmentation.run_dir import SegmentationRunDir

TINY = QUICK.replace(input_size=32, widths=(8, 16), batch_size=8, learning_rate=1e-2, checkpoint_every=20,
                     sample_every=40)


@pytest.fixture(scope="module")
def generated(two_object_scenes) -> Path:
    return two_object_scenes(5)


@pytest.fixture(scope="module")
def trained(generated, tmp_path_factory) -> Path:
    from paz6d.segmentation.train import train_segmentation

    out = tmp_path_factory.mktemp("segmentation_run") / "run"
    train_segmentation(SegmentationTraining(dataset=generated, out=out, steps=40, progress=False, settings=TINY))
    return out


def test_a_run_directory_resumes_only_its_own_network(generated, trained):
    from paz6d.segmentation.train import train_segmentation

    with pytest.raises(ValueError, match=r"holds a different run \(widths differ\)"):
        train_segmentation(SegmentationTraining(dataset=generated, out=trained, steps=40, progress=False,
                                                settings=TINY.replace(widths=(8, 8))))
    with pytest.raises(ValueError, match="input_size: expected a multiple of 4"):
        SegmentationTraining(dataset=generated, out=trained, settings=TINY.replace(input_size=30))


def test_model_maps_crops_to_one_logit_map_per_class():
    from paz6d.segmentation.model import build_segmenter, mask_iou, mask_loss, pick_class

    model = build_segmenter(3, 32, (4, 8))
    logits = np.asarray(model(np.zeros((2, 32, 32, 3), np.float32)))
    assert logits.shape == (2, 32, 32, 3)
    picked = np.asarray(pick_class(logits, np.array([2, 0])))
    np.testing.assert_array_equal(picked, np.stack([logits[0, ..., 2], logits[1, ..., 0]]))
    targets = np.zeros((2, 32, 32), np.float32)
    assert float(mask_loss(logits, targets, np.array([2, 0]))) > 0
    assert 0.0 <= float(mask_iou(logits, targets, np.array([2, 0]))) <= 1.0
    with pytest.raises(ValueError, match="input_size: expected a positive multiple of 4, got 30"):
        build_segmenter(3, 30, (4, 8))


def test_save_and_load_give_identical_outputs(tmp_path):
    from paz6d.segmentation.model import SegmentationModelError, build_segmenter, load_segmenter, save_segmenter

    model = build_segmenter(2, 32, (4, 8))
    crops = np.random.default_rng(0).uniform(0, 255, (3, 32, 32, 3)).astype(np.float32)
    path = save_segmenter(model, tmp_path / "model.keras")
    loaded = load_segmenter(path, 32, 2)
    np.testing.assert_array_equal(np.asarray(model(crops)), np.asarray(loaded(crops)))
    with pytest.raises(SegmentationModelError, match=r"model.keras: expected a model .*\(None, 32, 32, 3\)"):
        load_segmenter(path, 32, 3)


def test_paste_puts_the_crop_mask_inside_the_box_at_its_place():
    # window (2, 4, side 16) cut at size 16: crop pixel (u, v) is image pixel (u + 2, v + 4)
    crop = np.zeros((16, 16), np.float32)
    crop[:, :8] = 1.0  # the left half of the window: image columns 2..9
    pasted = paste_mask(crop, (2, 4, 16), (4.0, 6.0, 14.0, 16.0), (20, 24))
    expected = np.zeros((24, 20), bool)
    expected[6:16, 4:10] = True  # left half of the window, cut to the box's rows 6..15 and columns 4..13
    np.testing.assert_array_equal(pasted >= 0.5, expected)
    # a crop at half resolution (8 x 8 for a 16-pixel window) lands on the same pixels
    half = np.zeros((8, 8), np.float32)
    half[:, :4] = 1.0
    assert ((paste_mask(half, (2, 4, 16), (4.0, 6.0, 14.0, 16.0), (20, 24)) >= 0.5) == expected).mean() > 0.97
    with pytest.raises(ValueError, match=r"crop_values: expected a square \(S, S\) map"):
        paste_mask(np.zeros((4, 5)), (0, 0, 4), (0, 0, 2, 2), (8, 8))


def test_rle_jitter_and_background_blanking():
    mask = np.zeros((5, 7), bool)
    mask[1:4, 2:6] = True
    rle = rle_from_mask(mask)
    np.testing.assert_array_equal(mask_from_counts(rle["counts"], 5, 7), mask)
    box = jitter_box((10, 10, 30, 50), np.random.default_rng(0), 0.1)
    assert np.all(np.abs(box - [10, 10, 30, 50]) < [6, 10, 6, 10])
    image = np.full((5, 7, 3), 200, np.uint8)
    blanked = blank_background(image, mask)
    assert blanked[mask].min() == 200 and blanked[~mask].max() == 0 and image.min() == 200
    with pytest.raises(ValueError, match="mask: expected a bool array of the image's shape"):
        blank_background(image, mask.astype(np.uint8))


def test_training_crops_hold_the_visible_mask(generated):
    data = load_mask_set(generated, "train")
    assert data.class_names == ("obj_000005", "obj_000008") and len(data) >= 6
    batch = crop_batch(data, np.random.default_rng(0), 4, 32, 1.25, 0.0)
    assert batch["crops"].shape == (4, 32, 32, 3) and batch["masks"].shape == (4, 32, 32)
    assert set(np.unique(batch["masks"])) <= {0.0, 1.0} and 0.05 < batch["masks"].mean() < 0.8
    with pytest.raises(ValueError, match="split folder not found"):
        load_mask_set(generated, "nope")


def test_tiny_training_lowers_the_loss(trained):
    with (trained / "log.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    losses = [float(row["loss"]) for row in rows]
    assert len(losses) == 4 and losses[-1] < 0.8 * losses[0]
    assert method_of(trained) == "segmentation"
    assert SegmentationRunDir.read_description(trained)["class_names"] == ["obj_000005", "obj_000008"]
    assert (trained / "samples" / "step_00000040.png").is_file()
    assert json.loads((trained / "metrics.json").read_text())["steps"] == 40


def test_pipelines_segment_inside_the_boxes_and_score(trained, generated, tmp_path):
    from paz6d.datasets.bop.reader import BOPDataset
    from paz6d.pipelines import DetectAndSegment, SegmentInstances
    from paz6d.segmentation.evaluate import evaluate_split

    segment = SegmentInstances(trained)
    assert segment.names == ["crop", "predict", "pick_class", "paste", "threshold"]
    sample = next(iter(BOPDataset(generated, "train")))
    boxes = [Box2D(x, y, x + w, y + h, class_name=f"obj_{obj.obj_id:06d}")
             for obj in sample.objects for x, y, w, h in [obj.info["bbox_visib"]]]
    masks = segment(sample.image, boxes)
    assert masks.shape == (len(boxes), 120, 160) and masks.dtype == bool
    for box, mask in zip(boxes, masks):
        outside = mask.copy()
        outside[int(box.y_min):int(np.ceil(box.y_max)), int(box.x_min):int(np.ceil(box.x_max))] = False
        assert not outside.any()
    assert segment(sample.image, []).shape == (0, 120, 160)
    with pytest.raises(ValueError, match="class_name: expected one of the run's classes"):
        segment(sample.image, [Box2D(10, 10, 50, 50, class_name="cat")])

    detections_and_masks = DetectAndSegment(lambda image: boxes, segment)
    assert detections_and_masks.names == ["detect", "segment"]
    detections, combined = detections_and_masks(sample.image)
    assert detections == boxes
    np.testing.assert_array_equal(combined, masks)

    report = evaluate_split(segment, generated, "train", tmp_path / "eval")
    assert report["instances"] >= 6 and 0.0 <= report["segm"]["AP"] <= 1.0 and 0.0 <= report["mean_iou"] <= 1.0
    assert (tmp_path / "eval" / "masks.png").is_file()
    assert main(["evaluate", "coco", "--gt", report["ground_truth"], "--results", report["results"], "--iou-type",
                 "segm", "--out", str(tmp_path / "coco.json")]) == 0
    assert json.loads((tmp_path / "coco.json").read_text())["stats"][0] == pytest.approx(report["segm"]["AP"], abs=1e-4)
    detected = evaluate_split(segment, generated, "train", tmp_path / "detected",
                              detector=lambda image: [Box2D(10, 10, 60, 60, score=0.5, class_name="obj_000005")])
    assert detected["instances"] == 6 and detected["mean_iou"] is None
    assert {result["score"] for result in json.loads(Path(detected["results"]).read_text())} == {0.5}


def test_training_refuses_a_folder_of_a_different_run(trained, generated):
    from paz6d.segmentation.train import train_segmentation

    before = (trained / SegmentationRunDir.CONFIG_FILE).read_text()
    for change, differ in (({"seed": 1}, "seed"), ({"settings": TINY.replace(input_size=48)}, "input_size")):
        job = SegmentationTraining(**{"dataset": generated, "out": trained, "steps": 40, "progress": False,
                                      "settings": TINY, **change})
        with pytest.raises(ValueError, match=rf"out: .* holds a different run \({differ} differ\); "
                                             r"choose another --out"):
            train_segmentation(job)
    assert (trained / SegmentationRunDir.CONFIG_FILE).read_text() == before


def test_corrupt_run_directories_are_named(trained, tmp_path):
    import shutil

    from paz6d.pipelines import SegmentInstances

    run = tmp_path / "run"
    shutil.copytree(trained, run)
    (run / "model.keras").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match=r"model.keras: not a readable .keras model archive"):
        SegmentInstances(run)
    (run / "model.keras").unlink()
    with pytest.raises(ValueError, match=r"model.keras: file not found \(is .* a segmentation run directory\?\)"):
        SegmentInstances(run)
    shutil.copy(trained / "model.keras", run / "model.keras")
    (run / "segmenter.json").write_text("{")
    with pytest.raises(ValueError, match="segmenter.json: corrupt segmenter description"):
        SegmentInstances(run)
    (run / "segmenter.json").write_text(json.dumps({"input_size": 32, "margin": 1.25, "class_names": ["a"]}))
    with pytest.raises(ValueError, match=r"segmenter.json: missing field\(s\) \['threshold'\]"):
        SegmentInstances(run)
    (run / "segmenter.json").write_text(json.dumps({"input_size": -3, "margin": 1.25, "class_names": ["a"],
                                                    "threshold": 0.5}))
    with pytest.raises(ValueError, match="segmenter.json: input_size: expected a positive integer"):
        SegmentInstances(run)
    (run / "segmenter.json").write_text(json.dumps({"input_size": 32, "margin": 1.25, "class_names": ["a", "b", "c"],
                                                    "threshold": 0.5}))
    with pytest.raises(ValueError, match=r"model.keras: expected a model .*\(None, 32, 32, 3\)"):
        SegmentInstances(run)
    with pytest.raises(ValueError, match="is not a directory"):
        SegmentInstances(tmp_path / "missing")


def test_command_reports_a_bad_data_set(tmp_path, capsys):
    assert main(["train", "segmentation", "--dataset", str(tmp_path / "none"), "--out", str(tmp_path / "run"),
                 "--no-progress"]) == 2
    assert "paz6d train segmentation: error:" in capsys.readouterr().err


def test_rendered_masks_match_the_generated_ones(generated, tmp_path):
    from paz6d.datasets.bop.reader import BOPDataset
    from paz6d.segmentation.real_masks import write_rendered_masks

    summary = write_rendered_masks(generated, "train", tmp_path / "copy", progress=False)
    assert summary["images"] == 6
    ious = []
    for original, rendered in zip(BOPDataset(generated, "train"), BOPDataset(tmp_path / "copy", "train")):
        assert rendered.image is not None and len(rendered.objects) == len(original.objects)
        for a, b in zip(original.objects, rendered.objects):
            ious.append((a.mask_visib & b.mask_visib).sum() / max((a.mask_visib | b.mask_visib).sum(), 1))
            assert b.info["bbox_visib"][2] > 0 or not b.mask_visib.any()
    # the generated masks also account for the unannotated distractor; the rendered ones cannot
    assert np.median(ious) > 0.9
    with pytest.raises(ValueError, match="lies inside the data set"):
        write_rendered_masks(generated, "train", generated / "copy", progress=False)
