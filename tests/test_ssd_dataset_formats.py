"""`paz6d train ssd --dataset` on VOC, COCO and Open Images folders: format detection, default splits,
the samples SSD trains on, and a few training steps on each fixture."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from paz6d.cli import main
from paz6d.datasets import voc
from paz6d.ssd.config import QUICK, SSDTraining
from paz6d.ssd.dataset import detect_format, load_detection_set

DATA = Path(__file__).parent / "data" / "datasets"
VOC = DATA / "voc" / "VOC2007"
COCO = DATA / "coco"
OPENIMAGES = DATA / "openimages"
TINY = QUICK.replace(input_size=128, width=0.25, learning_rate=1e-3, warmup_steps=0, expand_probability=0.0,
                     checkpoint_every=2, sample_every=100)


def test_formats_are_detected(tmp_path):
    assert detect_format(VOC) == "voc" and detect_format(VOC / "Annotations") == "voc"
    assert detect_format(COCO) == "coco" and detect_format(COCO / "annotations" / "instances_tiny2017.json") == "coco"
    assert detect_format(OPENIMAGES) == "openimages"
    with pytest.raises(ValueError, match=r"dataset: cannot tell the format of .*; .*--format"):
        detect_format(tmp_path)
    with pytest.raises(ValueError, match=r"format: expected one of"):
        load_detection_set(VOC, dataset_format="yolo")


def test_voc_training_samples_leave_out_difficult_boxes():
    data = load_detection_set(VOC)  # ImageSets/Main/train.txt (no trainval here)
    assert data.class_names == voc.VOC_CLASSES and len(data) == 2
    first = data.samples[0]
    assert first.path == VOC / "JPEGImages" / "000001.jpg"
    np.testing.assert_array_equal(first.boxes, [[4, 3, 30, 25]])  # the difficult person is left out
    assert first.class_ids.tolist() == [voc.VOC_CLASSES.index("dog") + 1]
    assert len(load_detection_set(VOC, "val")) == 1
    with pytest.raises(ValueError, match=r"unknown class\(es\) \['cat', 'chair'\]"):
        load_detection_set(VOC, class_names=("dog", "car"))


def test_coco_and_openimages_training_samples():
    data = load_detection_set(COCO)
    assert data.class_names == ("person", "dog", "potted plant")
    assert [sample.path.name for sample in data.samples] == ["000007.jpg", "000003.png"]  # empty image left out
    assert data.samples[1].class_ids.tolist() == [3]  # the crowd box is left out
    data = load_detection_set(OPENIMAGES, dataset_format="openimages")
    assert data.class_names == ("Tortoise", "Cat", "Dog", "Person") and len(data) == 3
    assert data.samples[0].class_ids.tolist() == [2]  # the group-of box is left out
    np.testing.assert_allclose(data.samples[0].boxes, [[10, 7.5, 20, 15]])


@pytest.mark.slow
@pytest.mark.parametrize("dataset, dataset_format", [(VOC, "voc"), (COCO, "auto"), (OPENIMAGES, "openimages")])
def test_a_few_training_steps_on_each_format(tmp_path, dataset, dataset_format):
    from paz6d.ssd.train import train_ssd

    summary = train_ssd(SSDTraining(dataset=dataset, out=tmp_path / "run", steps=4, batch_size=2, progress=False,
                                    format=dataset_format, settings=TINY))
    assert summary["steps"] == 4 and np.isfinite(summary["final_losses"]["loss"])
    detector = json.loads((tmp_path / "run" / "detector.json").read_text())
    assert detector["class_names"] == list(load_detection_set(dataset, dataset_format=dataset_format).class_names)


def test_the_command_takes_format_and_reports_bad_folders(tmp_path, capsys):
    assert main(["train", "ssd", "--dataset", str(tmp_path), "--out", str(tmp_path / "run")]) == 2
    assert "cannot tell the format" in capsys.readouterr().err
    assert main(["train", "ssd", "--dataset", str(VOC), "--format", "coco", "--out", str(tmp_path / "run")]) == 2
    assert "has no COCO annotations/instances_<split>.json" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["train", "ssd", "--dataset", str(VOC), "--format", "yolo", "--out", str(tmp_path / "run")])
