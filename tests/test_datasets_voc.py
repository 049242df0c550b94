"""paz6d.datasets.voc: devkit folders and bare XML folders, the 1-based -> pixel box rule, difficult
and truncated flags, and errors naming the file, the object and the field."""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree
from pathlib import Path

import numpy as np
import pytest

from paz6d.backend.image import load_image
from paz6d.datasets import voc

FIXTURE = Path(__file__).parent / "data" / "datasets" / "voc" / "VOC2007"


def plain_parse(path: Path) -> list[tuple[str, list[float], bool, bool]]:
    root = ElementTree.parse(path).getroot()
    return [(obj.find("name").text,
             [float(obj.find("bndbox").find(tag).text) for tag in ("xmin", "ymin", "xmax", "ymax")],
             obj.find("difficult").text == "1", obj.find("truncated").text == "1") for obj in root.iter("object")]


@pytest.mark.parametrize("folder", ["toyexample/gts_vocpascal_format", "database/gts_pascalvoc_format"])
def test_shared_voc_sample_equals_a_plain_xml_parse(shared_data, folder):
    root = shared_data / "voc" / folder
    samples = voc.load(root)
    paths = sorted(root.glob("*.xml"))
    assert len(samples) == len(paths) and samples.class_names == list(voc.VOC_CLASSES)
    raw = voc.load(root, voc_coordinates=True)
    for sample, raw_sample, path in zip(samples, raw, paths):
        expected = plain_parse(path)
        assert sample.class_names == [name for name, *_ in expected]
        assert [voc.VOC_CLASSES[i] for i in sample.class_ids] == sample.class_names
        boxes = np.array([box for _, box, *_ in expected]).reshape(-1, 4)
        np.testing.assert_array_equal(raw_sample.boxes, boxes)
        np.testing.assert_array_equal(sample.boxes, boxes - [1, 1, 0, 0])  # 1-based inclusive -> [i, i+1) pixels
        assert sample.extras["difficult"].tolist() == [hard for *_, hard, _ in expected]
        assert sample.extras["truncated"].tolist() == [cut for *_, cut in expected]
        assert sample.extras["image_id"] == path.stem
        assert Path(sample.image) == root / ElementTree.parse(path).getroot().findtext("filename")


def test_shared_voc_sample_drops_difficult_boxes(shared_data):
    root = shared_data / "voc" / "database" / "gts_pascalvoc_format"
    objects = [obj for path in sorted(root.glob("*.xml")) for obj in plain_parse(path)]
    difficult = sum(hard for _, _, hard, _ in objects)
    assert len(objects) == 247 and difficult > 0
    easy = voc.load(root, drop_difficult=True)
    assert sum(len(sample.boxes) for sample in easy) == 247 - difficult
    assert not any(sample.extras["difficult"].any() for sample in easy)


def test_devkit_folder_splits_images_and_pixel_boxes():
    train = voc.load(FIXTURE, "train")
    assert len(train) == 2 and [s.extras["image_id"] for s in train] == ["000001", "000003"]
    assert [s.extras["image_id"] for s in voc.load(FIXTURE, "val")] == ["000002"]
    assert [s.extras["image_id"] for s in voc.load(FIXTURE, "dog_train")] == ["000001", "000003"]
    assert len(voc.load(FIXTURE)) == 3
    first = train[0]
    assert Path(first.image) == FIXTURE / "JPEGImages" / "000001.jpg"
    assert first.class_names == ["dog", "person"] and first.class_ids.tolist() == [11, 14]
    np.testing.assert_array_equal(first.boxes, [[4, 3, 30, 25], [0, 0, 12, 30]])
    assert first.extras["difficult"].tolist() == [False, True]
    assert first.extras["truncated"].tolist() == [True, False]
    assert first.extras["image_size"] == (40, 30)
    image = load_image(first.image)
    assert image.shape == (30, 40, 3)
    # a drawn box fills exactly the pixels the converted box covers
    x_min, y_min, x_max, y_max = first.boxes[0].astype(int)
    assert image[y_min + 1:y_max - 1, x_min + 1:x_max - 1, 2].min() > 150 and image[y_max + 2, x_max + 2, 2] < 60
    easy = voc.load(FIXTURE, "train", drop_difficult=True)[1]
    assert easy.class_names == ["cat", "chair"] and easy.boxes.shape == (2, 4)
    assert train[-1].extras["image_id"] == "000003" and len(train[0:2]) == 2


def _write(folder: Path, body: str, name: str = "a.xml") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(body)
    return path


GOOD_OBJECT = "<object><name>dog</name><difficult>0</difficult><bndbox><xmin>1</xmin><ymin>2</ymin>" \
              "<xmax>5</xmax><ymax>6</ymax></bndbox></object>"


@pytest.mark.parametrize("body, message", [
    ("<annotation><object>", r"a\.xml: malformed XML"),
    ("<annotation>" + GOOD_OBJECT.replace("<xmax>5</xmax>", "<xmax>five</xmax>") + "</annotation>",
     r"a\.xml, <object> #1, field <bndbox>/<xmax>: expected a number, got 'five'"),
    ("<annotation>" + GOOD_OBJECT + GOOD_OBJECT.replace("<ymin>2</ymin>", "") + "</annotation>",
     r"a\.xml, <object> #2, field <bndbox>/<ymin>: missing"),
    ("<annotation>" + GOOD_OBJECT.replace("dog", "dragon") + "</annotation>",
     r"a\.xml, <object> #1, field <name>: unknown class 'dragon'"),
    ("<annotation>" + GOOD_OBJECT.replace("<difficult>0", "<difficult>yes") + "</annotation>",
     r"a\.xml, <object> #1, field <difficult>: expected 0 or 1, got 'yes'"),
    ("<annotation>" + GOOD_OBJECT.replace("<name>dog</name>", "") + "</annotation>",
     r"a\.xml, <object> #1, field <name>: missing"),
    ("<annotation>" + GOOD_OBJECT.replace("<xmax>5</xmax>", "<xmax>0</xmax>") + "</annotation>",
     r"a\.xml, <object> #1, field <bndbox>: xmax < xmin"),
    ("<root/>", r"a\.xml: root element <root>; expected a VOC <annotation>"),
])
def test_malformed_xml_names_file_object_and_field(tmp_path, body, message):
    _write(tmp_path, body)
    samples = voc.load(tmp_path)
    with pytest.raises(ValueError, match=message):
        samples[0]


def test_missing_folders_and_splits_are_reported(tmp_path):
    with pytest.raises(ValueError, match="does not exist"):
        voc.load(tmp_path / "nowhere")
    with pytest.raises(ValueError, match="holds no VOC XML"):
        voc.load(tmp_path)
    with pytest.raises(ValueError,
                       match=r"split: .*test\.txt not found; the image sets of .* are \['dog_train', 'train', 'val'\]"):
        voc.load(FIXTURE, "test")
    _write(tmp_path, "<annotation/>")
    with pytest.raises(ValueError, match="bare folder of XML files"):
        voc.load(tmp_path, "train")
    assert voc.is_voc_root(tmp_path) and voc.is_voc_root(FIXTURE) and not voc.is_voc_root(tmp_path / "x")
    assert len(voc.load(tmp_path)[0].boxes) == 0
