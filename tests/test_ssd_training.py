"""`paz6d train ssd` on a few generated images, the DetectSingleShot pipeline, `paz6d detect`, the data
set reader's errors and the BOP -> COCO ground-truth converter."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from paz6d.abstract import Box2D
from paz6d.cli import build_parser, main
from paz6d.datasets.bop.coco_ground_truth import bop_split_to_coco, coco_image_id
from paz6d.run_dirs import method_of
from paz6d.ssd.run_dir import SSDRunDir
from paz6d.ssd.dataset import load_detection_set
from paz6d.ssd.config import FULL, QUICK, SSDTraining
from paz6d.ssd.train import augmentation_factory, image_scale, train_ssd

TINY = QUICK.replace(input_size=128, width=0.25, learning_rate=5e-3, warmup_steps=0, expand_probability=0.0,
                     checkpoint_every=30, sample_every=30)


@pytest.fixture(scope="module")
def generated(two_object_scenes) -> Path:
    return two_object_scenes(3)


@pytest.fixture(scope="module")
def trained(generated, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ssd_run") / "run"
    train_ssd(SSDTraining(dataset=generated, out=out, steps=60, batch_size=4, progress=False, settings=TINY))
    return out


def test_optional_augmentations_follow_the_run_settings():
    assert augmentation_factory(QUICK)().names == ["photometric", "expand", "crop", "flip"]
    chain = augmentation_factory(QUICK.replace(white_balance=0.3, grayscale=0.2))()
    assert chain.names == ["photometric", "white_balance", "grayscale", "expand", "crop", "flip"]
    assert chain["grayscale"].probability == 0.2 and chain["white_balance"].strength == 0.3
    assert chain["expand"].max_ratio == QUICK.expand_ratio
    with pytest.raises(ValueError, match="grayscale: expected at most 1.0"):
        QUICK.replace(grayscale=1.5)


def test_scale_crops_train_on_windows_and_detect_on_whole_images(generated, tmp_path):
    from paz6d.backend.image import load_image
    from paz6d.pipelines import DetectSingleShot
    from paz6d.synthesis.box_augment import RandomScaleCrop

    settings = TINY.replace(scale_crops=(0.5, 2.0))
    chain = augmentation_factory(settings)()
    assert chain.names == ["photometric", "flip", "crop"]
    assert isinstance(chain["crop"], RandomScaleCrop) and chain["crop"].size == 128
    assert image_scale(settings) == pytest.approx(1.0) and image_scale(QUICK) is None
    flagged = build_parser().parse_args(["train", "ssd", "--dataset", "d", "--out", "o", "--scale-crops", "0.7", "1.4"])
    assert tuple(flagged.scale_crops) == (0.7, 1.4)
    assert SSDTraining(dataset="d", out="o", scale_crops=(0.7, 1.4)).model_config.scale_crops == (0.7, 1.4)
    with pytest.raises(ValueError, match="scale_crops: expected values that do not decrease"):
        SSDTraining(dataset="d", out="o", scale_crops=(2.0, 1.0))
    with pytest.raises(ValueError, match="scale_crops: only the light network"):
        SSDTraining(dataset="d", out="o", config="full", scale_crops=(0.7, 1.4))
    out = tmp_path / "run"
    train_ssd(SSDTraining(dataset=generated, out=out, steps=20, batch_size=4, progress=False,
                          settings=settings.replace(checkpoint_every=20, sample_every=20)))
    assert SSDRunDir.read_description(out)["image_scale"] == pytest.approx(1.0)
    detect = DetectSingleShot(out, score_threshold=0.0, max_detections=5)
    assert detect.names == ["check", "resize", "normalize", "predict", "decode", "nms", "to_pixels", "to_boxes2d"]
    image = load_image(next((generated / "train" / "000000" / "rgb").iterdir()))  # 160 x 120
    values = detect.run_steps({"image": image})
    assert values["canvas_size"] == (192, 128) and values["resized"].shape == (128, 192, 3)
    boxes = values["detections"]
    assert 1 <= len(boxes) <= 5
    assert all(0 <= box.x_min <= box.x_max <= 160 and 0 <= box.y_min <= box.y_max <= 120 for box in boxes)


def test_canvas_decoding_maps_zero_offsets_to_the_priors_in_image_pixels():
    from paz6d.ssd.model import paper_priors, priors_for
    from paz6d.ssd.pipeline import CanvasToPixels, DecodeCanvasBoxes, ScaleAndPad

    spec = paper_priors("light", 128)
    image = np.zeros((120, 160, 3), np.uint8)
    canvas, canvas_size = ScaleAndPad(0.5)(image)  # 80 x 60 scaled, padded to the smallest input, 128 x 128
    assert canvas_size == (128, 128) and canvas.shape == (128, 128, 3)
    np.testing.assert_array_equal(ScaleAndPad(2.0)(image)[1], (320, 256))
    priors = priors_for(spec, (128, 128))
    outputs = np.zeros((len(priors), 4 + 3))
    boxes, _ = DecodeCanvasBoxes(spec)(outputs, canvas_size)
    pixels = CanvasToPixels(0.5)(boxes[:1], canvas_size, (160, 120))
    side = spec.min_sizes[0] / 0.5  # first prior: a min_size square around canvas pixel (4, 4)
    np.testing.assert_allclose(pixels[0], np.clip([8 - side / 2, 8 - side / 2, 8 + side / 2, 8 + side / 2], 0, None))


def test_training_lowers_the_loss_and_writes_the_run_directory(trained):
    with (trained / "log.csv").open() as handle:
        losses = [float(row["loss"]) for row in csv.DictReader(handle)]
    assert len(losses) == 6
    assert np.mean(losses[-2:]) < 0.7 * losses[0]
    detector = SSDRunDir.read_description(trained)
    assert detector["class_names"] == ["obj_000005", "obj_000008"]
    assert detector["architecture"] == "light"
    assert sorted(path.name for path in (trained / "samples").iterdir()) == ["step_00000030.png", "step_00000060.png"]
    assert json.loads((trained / "metrics.json").read_text())["steps"] == 60
    assert method_of(trained) == "ssd"


def test_pipeline_returns_named_boxes_from_named_steps(trained, generated):
    from paz6d.backend.image import load_image
    from paz6d.pipelines import DetectSingleShot

    detect = DetectSingleShot(trained, score_threshold=0.0, max_detections=5)
    assert detect.names == ["check", "resize", "normalize", "predict", "decode", "nms", "to_pixels", "to_boxes2d"]
    image = load_image(next((generated / "train" / "000000" / "rgb").iterdir()))
    boxes = detect(image)
    assert 1 <= len(boxes) <= 5 and all(isinstance(box, Box2D) for box in boxes)
    assert {box.class_name for box in boxes} <= {"obj_000005", "obj_000008"}
    assert all(0 <= box.x_min <= box.x_max <= 160 and 0 <= box.y_min <= box.y_max <= 120 for box in boxes)
    assert [box.score for box in boxes] == sorted((box.score for box in boxes), reverse=True)
    with pytest.raises(ValueError, match=r"image: expected an RGB image of shape \(H, W, 3\), got shape \(120, 160\)"):
        detect(image[..., 0])


def test_detect_command_writes_detections_that_evaluate_scores(trained, generated, tmp_path, capsys):
    detections, truth = tmp_path / "detections.json", tmp_path / "truth.json"
    assert main(["detect", "--run-dir", str(trained), "--dataset", str(generated), "--split", "train",
                 "--out", str(detections), "--ground-truth", str(truth), "--no-progress"]) == 0
    results = json.loads(detections.read_text())
    ground_truth = json.loads(truth.read_text())
    assert {r["image_id"] for r in results} <= {image["id"] for image in ground_truth["images"]}
    assert {r["category_id"] for r in results} <= {5, 8}
    assert main(["evaluate", "coco", "--gt", str(truth), "--results", str(detections),
                 "--out", str(tmp_path / "coco.json")]) == 0
    folder = tmp_path / "images"
    folder.mkdir()
    for path in sorted((generated / "train" / "000000" / "rgb").iterdir())[:2]:
        shutil.copy(path, folder / path.name)
    assert main(["detect", "--run-dir", str(trained), "--images", str(folder), "--out", str(tmp_path / "f.json"),
                 "--no-progress"]) == 0
    entries = json.loads((tmp_path / "f.json").read_text())
    assert {entry["image_id"] for entry in entries} <= {0, 1} and "file_name" in entries[0]
    capsys.readouterr()
    assert main(["detect", "--run-dir", str(trained), "--images", str(folder), "--out", str(tmp_path / "m.json"),
                 "--flip", "--no-progress"]) == 0
    assert json.loads(capsys.readouterr().out)["flip"] is True
    mirrored = json.loads((tmp_path / "m.json").read_text())
    assert {entry["image_id"] for entry in mirrored} <= {0, 1}
    assert sorted(entry["bbox"] for entry in mirrored) != sorted(entry["bbox"] for entry in entries)


def test_corrupt_run_directory_is_refused(trained, tmp_path):
    from paz6d.ssd.pipeline import DetectSingleShot

    broken = tmp_path / "broken"
    shutil.copytree(trained, broken)
    (broken / "detector.json").write_text("{not json")
    with pytest.raises(ValueError, match="detector.json: corrupt"):
        DetectSingleShot(broken)
    (broken / "detector.json").write_text(json.dumps({"architecture": "light", "class_names": [], "priors": {},
                                                      "variances": [0.1, 0.1, 0.2, 0.2]}))
    with pytest.raises(ValueError, match="class_names: expected a non-empty list"):
        DetectSingleShot(broken)
    detector = json.loads((trained / "detector.json").read_text())
    (broken / "detector.json").write_text(json.dumps({**detector, "image_scale": -1}))
    with pytest.raises(ValueError, match=r"detector.json: image_scale: expected a factor from 0.0625 to 16 or null"):
        DetectSingleShot(broken)
    (broken / "detector.json").write_text((trained / "detector.json").read_text())
    (broken / "model.keras").unlink()
    with pytest.raises(ValueError, match="model.keras: file not found"):
        DetectSingleShot(broken)
    with pytest.raises(ValueError, match="is not a directory"):
        DetectSingleShot(tmp_path / "missing")


def test_data_set_errors_name_the_problem(generated, tmp_path):
    with pytest.raises(ValueError, match="unknown class"):
        load_detection_set(generated, class_names=("obj_000005",))
    empty = tmp_path / "empty" / "train" / "000000"
    empty.mkdir(parents=True)
    (empty / "scene_gt_coco.json").write_text(json.dumps({"images": [{"id": 0, "file_name": "rgb/000000.png"}],
                                                          "annotations": [], "categories": []}))
    with pytest.raises(ValueError, match="empty data set"):
        load_detection_set(tmp_path / "empty")
    with pytest.raises(ValueError, match=r"dataset: no scene_gt_coco.json"):
        load_detection_set(tmp_path / "empty", split="val")
    assert main(["train", "ssd", "--dataset", str(tmp_path / "empty"), "--out", str(tmp_path / "run")]) == 2


def test_resuming_continues_and_other_settings_are_refused(trained, generated):
    with pytest.raises(ValueError, match="holds a different run"):
        train_ssd(SSDTraining(dataset=generated, out=trained, steps=60, batch_size=4, seed=9, progress=False,
                              settings=TINY))
    with pytest.raises(ValueError, match="holds a different run"):  # --input-size is part of the run
        train_ssd(SSDTraining(dataset=generated, out=trained, steps=60, batch_size=4, input_size=192,
                              progress=False, settings=TINY))
    summary = train_ssd(SSDTraining(dataset=generated, out=trained, steps=70, batch_size=4, progress=False,
                                    settings=TINY))
    assert summary["steps"] == 70
    with (trained / "log.csv").open() as handle:
        assert [int(row["step"]) for row in csv.DictReader(handle)] == list(range(10, 71, 10))


def test_input_size_flag_sets_the_light_network_input_and_is_checked():
    assert SSDTraining(dataset="d", out="o").model_config.input_size == 448  # the quick config
    assert SSDTraining(dataset="d", out="o", input_size=320).model_config.input_size == 320
    assert SSDTraining(dataset="d", out="o", input_size=192, settings=TINY).model_config == TINY.replace(input_size=192)
    for size, message in ((100, "multiple of 64"), (64, "at least 128"), (0, "at least 128"), (-64, "at least 128")):
        with pytest.raises(ValueError, match=message):
            SSDTraining(dataset="d", out="o", input_size=size)
    with pytest.raises(ValueError, match="only the light network"):
        SSDTraining(dataset="d", out="o", config="full", input_size=512)
    assert SSDTraining(dataset="d", out="o", config="full", input_size=300).model_config == FULL
    with pytest.raises(ValueError, match="input_size: expected a multiple of 64"):  # settings pass the same check
        TINY.replace(input_size=100)
    with pytest.raises(ValueError, match="input_size: expected a whole number, got 128.0"):
        TINY.replace(input_size=128.0)


def test_input_size_has_one_default_and_one_check_for_settings_and_the_model():
    from paz6d.ssd.model import SSDModelError, paper_priors

    assert paper_priors("light").input_size == SSDTraining(dataset="d", out="o").model_config.input_size == 448
    assert paper_priors("ssd512").input_size == 512
    for size, message in ((4096, "at most 2048"), (100, "multiple of 64")):
        with pytest.raises(SSDModelError, match=message):
            paper_priors("light", size)
        with pytest.raises(ValueError, match=message):
            SSDTraining(dataset="d", out="o", input_size=size)


def test_bop_to_coco_boxes_equal_bbox_visib_on_lmo(shared_data):
    root = shared_data / "bop_lmo"
    coco = bop_split_to_coco(root, "test")
    assert len(coco["images"]) == len(list((root / "test" / "000002" / "rgb").glob("*.png"))) == 105
    infos = json.loads((root / "test" / "000002" / "scene_gt_info.json").read_text())
    truth = json.loads((root / "test" / "000002" / "scene_gt.json").read_text())
    annotations = {}
    for annotation in coco["annotations"]:
        annotations.setdefault(annotation["image_id"], []).append(annotation)
    for image in coco["images"]:
        im_id = image["im_id"]
        assert image["id"] == coco_image_id(2, im_id) and (image["width"], image["height"]) == (640, 480)
        expected = [(entry["obj_id"], info["bbox_visib"], info["visib_fract"] < 0.1)
                    for entry, info in zip(truth[str(im_id)], infos[str(im_id)]) if info["bbox_visib"][2] > 0]
        got = [(a["category_id"], a["bbox"], bool(a["iscrowd"])) for a in annotations.get(image["id"], [])]
        assert got == [(obj, [float(v) for v in box], ignored) for obj, box, ignored in expected]
    assert [c["name"] for c in coco["categories"]] == [f"obj_{i:06d}" for i in (1, 5, 6, 8, 9, 10, 11, 12)]
    with pytest.raises(ValueError, match="split folder not found"):
        bop_split_to_coco(root, "train")
