"""paz6d.datasets.coco: the shared val2014 sample equals pycocotools (boxes, categories, crowd flags,
masks), a hand-made fixture with polygons, uncompressed and compressed RLE and keypoints, the round
trip through `paz6d generate`'s COCO file, and errors naming the file, the record and the field."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from pycocotools import mask as mask_utils
from pycocotools.coco import COCO

from paz6d.datasets import coco

FIXTURE = Path(__file__).parent / "data" / "datasets" / "coco"


@pytest.fixture(scope="module")
def val2014(shared_data):
    path = shared_data / "coco" / "instances_val2014_100.json"
    return path, COCO(str(path))


def _compare_with_pycocotools(samples, reference: COCO, indices, with_masks: bool) -> int:
    categories = sorted(reference.getCatIds())
    compared = 0
    for index in indices:
        sample, image_id = samples[index], reference.getImgIds()[index]
        annotations = reference.loadAnns(reference.getAnnIds(imgIds=[image_id]))
        assert sample.extras["image_id"] == image_id
        assert sample.extras["annotation_ids"] == [a["id"] for a in annotations]
        expected = np.array([a["bbox"] for a in annotations], dtype=np.float64).reshape(-1, 4)
        np.testing.assert_array_equal(sample.boxes,
                                      np.concatenate([expected[:, :2], expected[:, :2] + expected[:, 2:]], 1))
        assert sample.extras["category_ids"].tolist() == [a["category_id"] for a in annotations]
        assert [categories[i] for i in sample.class_ids] == [a["category_id"] for a in annotations]
        assert sample.class_names == [reference.cats[a["category_id"]]["name"] for a in annotations]
        assert sample.extras["iscrowd"].tolist() == [bool(a["iscrowd"]) for a in annotations]
        if with_masks:
            for annotation, mask in zip(annotations, sample.masks):
                np.testing.assert_array_equal(mask, reference.annToMask(annotation).astype(bool))
                compared += 1
    return compared


def test_shared_sample_equals_pycocotools(val2014):
    path, reference = val2014
    samples = coco.load(path)
    assert len(samples) == 100
    assert samples.class_names == [reference.cats[i]["name"] for i in sorted(reference.getCatIds())]
    assert Path(samples[0].image) == path.parent / reference.imgs[reference.getImgIds()[0]]["file_name"]
    boxes_only = coco.load(path, masks=False)
    assert _compare_with_pycocotools(boxes_only, reference, range(100), with_masks=False) == 0
    assert sum(len(s.boxes) for s in boxes_only) == 839 and boxes_only[0].masks is None
    # masks of the first 12 images (polygons, multi-part polygons and the first crowd RLEs)
    crowd_image = next(i for i, image_id in enumerate(reference.getImgIds())
                       if any(a["iscrowd"] for a in reference.imgToAnns[image_id]))
    assert _compare_with_pycocotools(samples, reference, range(12), with_masks=True) > 50
    assert _compare_with_pycocotools(samples, reference, [crowd_image], with_masks=True) > 0


@pytest.mark.slow
def test_shared_sample_masks_all_equal_annToMask(val2014):
    path, reference = val2014
    assert _compare_with_pycocotools(coco.load(path), reference, range(100), with_masks=True) == 839


def test_compressed_rle_strings_decode_as_pycocotools():
    generator = np.random.default_rng(0)
    for height, width, density in ((1, 1, 0.5), (7, 5, 0.5), (40, 31, 0.02), (64, 80, 0.98), (300, 200, 0.001)):
        mask = np.asfortranarray(generator.random((height, width)) < density)
        mask[height // 2:, : width // 3] = True  # long runs: multi-character, delta-coded values
        encoded = mask_utils.encode(mask.astype(np.uint8))
        decoded = coco.mask_from_segmentation(encoded, height, width)  # bytes counts
        np.testing.assert_array_equal(decoded, mask)
        encoded["counts"] = encoded["counts"].decode()
        np.testing.assert_array_equal(coco.mask_from_segmentation(encoded, height, width), mask)


def test_fixture_folder_layout_and_every_segmentation_kind():
    samples = coco.load(FIXTURE, "tiny2017")
    reference = COCO(str(FIXTURE / "annotations" / "instances_tiny2017.json"))
    assert samples.class_names == ["person", "dog", "potted plant"]  # category ids 1, 18, 64
    assert [s.extras["image_id"] for s in samples] == [7, 3, 9]
    first, second, empty = samples
    assert Path(first.image) == FIXTURE / "tiny2017" / "000007.jpg" and Path(first.image).is_file()
    np.testing.assert_array_equal(first.boxes, [[2.5, 3.0, 12.5, 11.5], [2.0, 4.0, 30.0, 20.0]])
    assert first.class_ids.tolist() == [1, 0] and first.class_names == ["dog", "person"]
    assert second.extras["iscrowd"].tolist() == [True, False] and second.masks.shape == (2, 16, 20)
    assert empty.boxes.shape == (0, 4) and empty.masks.shape == (0, 24, 32)
    for sample in (first, second):
        for annotation, mask in zip(reference.loadAnns(sample.extras["annotation_ids"]), sample.masks):
            np.testing.assert_array_equal(mask, reference.annToMask(annotation).astype(bool))
    assert first.keypoints.shape == (2, 2, 3) and first.keypoints[1, 0].tolist() == [20, 8, 2]
    assert first.keypoints[0].tolist() == [[0, 0, 0], [0, 0, 0]] and second.keypoints is None
    assert len(coco.load(FIXTURE, "tiny2017", skip_empty=True)) == 2
    no_crowd = coco.load(FIXTURE, "tiny2017", include_crowd=False)[1]
    assert no_crowd.class_names == ["potted plant"] and not no_crowd.extras["iscrowd"].any()
    by_file = coco.load(FIXTURE / "annotations" / "instances_tiny2017.json")
    assert by_file[0].image == first.image
    assert coco.is_coco_root(FIXTURE) and not coco.is_coco_root(FIXTURE / "tiny2017")


def test_round_trip_through_the_generated_coco_file(tmp_path, shared_data):
    from data_gen.config import GenerationConfig
    from data_gen.generator import generate
    from paz6d.backend.image import load_image

    models = shared_data / "bop_lmo" / "models"
    config = GenerationConfig(meshes=(models / "obj_000005.ply", models / "obj_000008.ply"), out=tmp_path, num_images=3,
                              width=64, height=48, mesh_scale=0.001, objects_per_image=(2, 2), distractors=0, seed=5)
    generate(config, workers=1, show_progress=False)
    path = tmp_path / "train" / "000000" / "scene_gt_coco.json"
    written = json.loads(path.read_text())
    samples = coco.load(path)
    assert samples.class_names == ["obj_000005", "obj_000008"] and len(samples) == 3
    annotations = iter(written["annotations"])
    for sample, image in zip(samples, written["images"]):
        assert load_image(sample.image).shape == (48, 64, 3)
        for box, mask, class_id in zip(sample.boxes, sample.masks, sample.class_ids):
            annotation = next(annotations)
            x, y, w, h = annotation["bbox"]
            np.testing.assert_array_equal(box, [x, y, x + w, y + h])
            assert samples.class_names[class_id] == f"obj_{annotation['category_id']:06d}"
            assert mask.sum() == annotation["area"]
            rows, columns = np.nonzero(mask)
            assert [columns.min(), rows.min(), columns.max() + 1, rows.max() + 1] == [x, y, x + w, y + h]
    assert next(annotations, None) is None


def _broken(tmp_path: Path, change) -> Path:
    data = json.loads((FIXTURE / "annotations" / "instances_tiny2017.json").read_text())
    change(data)
    path = tmp_path / "instances_broken.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize("change, message", [
    (lambda d: d["annotations"][1].pop("bbox"), r"annotations\[1\] \(id 12\), field 'bbox': missing"),
    (lambda d: d["annotations"][2].update(bbox=[1, 2, "3", 4]), r"annotations\[2\] \(id 13\), field 'bbox': expected"),
    (lambda d: d["annotations"][0].update(category_id=99),
     r"annotations\[0\] \(id 11\), field 'category_id': unknown category 99"),
    (lambda d: d["annotations"][0].update(image_id=5), r"annotations\[0\] \(id 11\), field 'image_id': 5 is not an id"),
    (lambda d: d["annotations"][3].update(iscrowd=2), r"annotations\[3\] \(id 14\), field 'iscrowd': expected 0 or 1"),
    (lambda d: d["images"][1].pop("height"), r"images\[1\] \(id 3\), field 'height': missing"),
    (lambda d: d["images"][0].update(width=-4), r"images\[0\] \(id 7\), field 'width'/'height'"),
    (lambda d: d.update(categories={}), r"field 'categories': expected a list"),
])
def test_malformed_records_name_file_record_and_field(tmp_path, change, message):
    path = _broken(tmp_path, change)
    with pytest.raises(ValueError, match=r"instances_broken\.json: " + message):
        coco.load(path)


@pytest.mark.parametrize("change, index, message", [
    (lambda d: d["annotations"][1]["segmentation"].update(counts="0#"), 0,
     r"annotations\[1\] \(id 12\), field 'segmentation', field 'counts': character '#'"),
    (lambda d: d["annotations"][2]["segmentation"].update(size=[3, 3]), 1,
     r"annotations\[2\] \(id 13\), field 'segmentation', field 'size': expected the image size \[16, 20\]"),
    (lambda d: d["annotations"][2]["segmentation"]["counts"].append(5), 1,
     r"annotations\[2\] \(id 13\), field 'segmentation', field 'counts': RLE counts must .* sum to"),
    (lambda d: d["annotations"][0].update(segmentation=[[1, 2, 3]]), 0,
     r"annotations\[0\] \(id 11\), field 'segmentation': a polygon needs an even number"),
])
def test_bad_segmentations_are_reported_when_read(tmp_path, change, index, message):
    samples = coco.load(_broken(tmp_path, change))
    with pytest.raises(ValueError, match=message):
        samples[index]
    assert coco.load(_broken(tmp_path, change), masks=False)[index].masks is None


def test_missing_files_and_splits(tmp_path):
    with pytest.raises(ValueError, match=r"split: .* is a COCO folder; name a split \(one of \['tiny2017'\]\)"):
        coco.load(FIXTURE)
    with pytest.raises(ValueError, match=r"instances_val2017\.json not found"):
        coco.load(FIXTURE, "val2017")
    (tmp_path / "bad.json").write_text("[1, 2]")
    with pytest.raises(ValueError, match=r"bad\.json: expected a JSON object"):
        coco.load(tmp_path / "bad.json")
