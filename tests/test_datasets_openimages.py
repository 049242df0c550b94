"""paz6d.datasets.openimages: box CSV + class descriptions (with and without header) + split folders,
normalised -> pixel boxes from image headers, flags, and errors naming file, line and field."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from paz6d.backend.image import encode_image, load_image
from paz6d.datasets import openimages

FIXTURE = Path(__file__).parent / "data" / "datasets" / "openimages"
HEADER = ",".join(openimages.BOX_COLUMNS)


def test_fixture_boxes_in_pixels_from_the_image_headers():
    samples = openimages.load(FIXTURE, "validation")
    assert samples.class_names == ["Tortoise", "Cat", "Dog", "Person"]
    assert [s.extras["image_id"] for s in samples] == ["0a1b2c3d4e5f6071", "1f2e3d4c5b6a7980", "b00000000000000c"]
    first, second, third = samples
    assert Path(first.image) == FIXTURE / "validation" / "0a1b2c3d4e5f6071.jpg"
    assert Path(second.image).suffix == ".png"
    for sample in samples:
        height, width = load_image(sample.image).shape[:2]
        assert sample.extras["image_size"] == (width, height)
    np.testing.assert_allclose(first.boxes, [[10, 7.5, 20, 15], [0, 3, 40, 27]])  # 40 x 30 image
    np.testing.assert_allclose(second.boxes, [[3, 18, 21, 36]])  # 24 x 36 PNG
    assert first.class_names == ["Cat", "Person"] and first.class_ids.tolist() == [1, 3]
    assert first.extras["label_names"] == ["/m/01yrx", "/m/01g317"]
    assert first.extras["is_group_of"].tolist() == [0, 1] and first.extras["is_inside"].tolist() == [0, -1]
    assert second.extras["is_depiction"].tolist() == [1] and second.extras["source"] == ["activemil"]
    assert third.extras["is_occluded"].tolist() == [0, -1]
    assert len(openimages.load(FIXTURE, "val", include_group_of=False)[0].boxes) == 1
    assert openimages.is_openimages_root(FIXTURE) and not openimages.is_openimages_root(FIXTURE / "validation")


def test_v7_header_and_the_downloader_layout(tmp_path):
    split = tmp_path / "validation"
    shutil.copytree(FIXTURE / "validation", split / "data")
    (split / "labels").mkdir()
    shutil.copy(FIXTURE / "validation-annotations-bbox.csv", split / "labels" / "detections.csv")
    (split / "metadata").mkdir()
    descriptions = (FIXTURE / "class-descriptions-boxable.csv").read_text()
    (split / "metadata" / "classes.csv").write_text("LabelName,DisplayName\n" + descriptions)
    samples = openimages.load(tmp_path, "validation")
    assert samples.class_names == ["Tortoise", "Cat", "Dog", "Person"]
    assert Path(samples[0].image) == split / "data" / "0a1b2c3d4e5f6071.jpg"
    np.testing.assert_allclose(samples[0].boxes, openimages.load(FIXTURE, "validation")[0].boxes)


def test_image_size_from_headers_of_every_kind(tmp_path):
    image = np.zeros((37, 53, 3), dtype=np.uint8)
    for suffix, parameters in ((".png", ()), (".jpg", ()), (".jpg", (cv2.IMWRITE_JPEG_PROGRESSIVE, 1)), (".bmp", ())):
        path = tmp_path / f"image{len(parameters)}{suffix}"
        path.write_bytes(encode_image(image, suffix, parameters))
        assert openimages.image_size_from_header(path) == (53, 37)
    (tmp_path / "cut.jpg").write_bytes(encode_image(image, ".jpg")[:20])
    with pytest.raises(ValueError, match=r"cut\.jpg: JPEG file without a frame header"):
        openimages.image_size_from_header(tmp_path / "cut.jpg")
    with pytest.raises(ValueError, match=r"missing\.jpg: image file not found"):
        openimages.image_size_from_header(tmp_path / "missing.jpg")


def _copy(tmp_path: Path, boxes: str | None = None, classes: str | None = None) -> Path:
    shutil.copytree(FIXTURE, tmp_path / "oi")
    if boxes is not None:
        (tmp_path / "oi" / "validation-annotations-bbox.csv").write_text(boxes)
    if classes is not None:
        (tmp_path / "oi" / "class-descriptions-boxable.csv").write_text(classes)
    return tmp_path / "oi"


GOOD = "0a1b2c3d4e5f6071,xclick,/m/01yrx,1,0.25,0.5,0.25,0.5,0,0,0,0,0"


@pytest.mark.parametrize("boxes, message", [
    (f"{HEADER}\n{GOOD}\n{GOOD.replace('/m/01yrx', '/m/0dragon')}\n",
     r"validation-annotations-bbox\.csv, line 3, field LabelName: unknown class '/m/0dragon'"),
    (f"{HEADER}\n{GOOD.replace(',0.5,0.25', ',abc,0.25')}\n",
     r"validation-annotations-bbox\.csv, line 2, field XMax: expected a fraction .* got 'abc'"),
    (f"{HEADER}\n{GOOD}\n{GOOD.replace(',0.25,0.5,0,', ',1.25,0.5,0,')}\n",
     r"line 3, field YMin: expected a fraction of the image size in \[0, 1\], got '1.25'"),
    (f"{HEADER}\n{GOOD[:-2]}\n", r"line 2: expected 13 fields, got 12"),
    (f"{HEADER}\n{GOOD[:-1]}7\n", r"line 2, field IsInside: expected 0, 1 or -1 \(unknown\), got '7'"),
    (f"{HEADER}\n{GOOD[:-1]}999999999999\n",  # beyond the flag's integer type (the fuzz run found it)
     r"line 2, field IsInside: expected 0, 1 or -1 \(unknown\), got '999999999999'"),
    (f"{HEADER.replace('XMin', 'Xmin')}\n{GOOD}\n", r"header lacks \['XMin'\]"),
    (f"{HEADER}\n{GOOD.replace('0.25,0.5,0.25', '0.75,0.5,0.25')}\n", r"line 2, field XMax/YMax: XMax < XMin"),
])
def test_malformed_box_csv_names_file_line_and_field(tmp_path, boxes, message):
    with pytest.raises(ValueError, match=message):
        openimages.load(_copy(tmp_path, boxes=boxes), "validation")


def test_class_descriptions_and_missing_files(tmp_path):
    with pytest.raises(ValueError, match=r"class-descriptions-boxable\.csv, line 2: expected 'LabelName,DisplayName'"):
        openimages.load(_copy(tmp_path, classes="/m/01yrx,Cat\n,Nothing\n"), "validation")
    with pytest.raises(ValueError, match=r"no Open Images box CSV for split 'train'"):
        openimages.load(FIXTURE, "train")
    with pytest.raises(ValueError, match=r"no Open Images class-description CSV"):
        openimages.load(tmp_path, "validation", boxes_csv=FIXTURE / "validation-annotations-bbox.csv")
    labels, names = openimages.read_class_descriptions(FIXTURE / "class-descriptions-boxable.csv")
    assert labels[0] == "/m/011k07" and names[-1] == "Person"
