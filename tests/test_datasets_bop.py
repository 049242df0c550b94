"""BOP reader on real LM-O data (metres, missing parts) and its error messages."""

from __future__ import annotations

import json

import numpy as np
import pytest

from paz6d.backend.camera import transform_and_project
from paz6d.datasets.bop import (BOPDataset, BOPScene, load_model, load_models_info, load_scene_camera, load_scene_gt,
                                load_scene_gt_info)


@pytest.fixture(scope="module")
def lmo(shared_data):
    return shared_data / "bop_lmo"


def test_lmo_scene_reads_with_missing_depth_masks_and_most_frames(lmo):
    dataset = BOPDataset(lmo, split="test")
    samples = list(dataset)
    assert len(samples) == len(dataset) == 200
    with_images = [sample for sample in samples if sample.image is not None]
    assert len(with_images) == 20
    for sample in samples:
        assert sample.depth is None and sample.scene_id == 2
        assert (sample.camera.width, sample.camera.height) == (640, 480)
        assert all(obj.mask is None and obj.mask_visib is None for obj in sample.objects)
    first = with_images[0]
    assert first.image.shape == (480, 640, 3) and first.image.dtype == np.uint8
    np.testing.assert_allclose(first.K, [[572.4114, 0, 325.2611], [0, 573.57043, 242.04899], [0, 0, 1]])


def test_lmo_poses_are_metres_and_match_the_gt_boxes(lmo):
    scene = BOPScene(lmo / "test" / "000002")
    raw = json.loads((lmo / "test" / "000002" / "scene_gt.json").read_text())
    models = {}
    checked = 0
    for sample in list(scene)[:10]:
        for index, obj in enumerate(sample.objects):
            entry = raw[str(sample.im_id)][index]
            np.testing.assert_allclose(obj.T_model2cam[:3, 3], np.asarray(entry["cam_t_m2c"]) / 1000.0)
            # Not quite orthonormal in the file; the reader snaps it to the nearest rotation.
            np.testing.assert_allclose(obj.T_model2cam[:3, :3].ravel(), entry["cam_R_m2c"], atol=2e-3)
            R = obj.T_model2cam[:3, :3]
            np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
            assert 0.3 < obj.T_model2cam[2, 3] < 1.6  # LM-O distances: 346-1500 mm
            if obj.info["visib_fract"] < 0.5:
                continue
            # Independent check of units and frames: the projected model spans the BOP bbox_obj.
            if obj.obj_id not in models:
                models[obj.obj_id] = load_model(lmo / "models", obj.obj_id)
            pixels = transform_and_project(models[obj.obj_id].vertices, obj.T_model2cam, sample.K)
            x, y, width, height = obj.info["bbox_obj"]
            # BOP boxes come from renders: thin parts that miss pixel centres shift them ~2 px.
            np.testing.assert_allclose(pixels.min(axis=0), [x, y], atol=3.0)
            np.testing.assert_allclose(pixels.max(axis=0), [x + width - 1, y + height - 1], atol=3.0)
            checked += 1
    assert checked > 10


def test_stored_rotations_can_be_kept_unsnapped(lmo):
    path = lmo / "test" / "000002" / "scene_gt.json"
    raw = json.loads(path.read_text())
    stored = load_scene_gt(path, snap_rotations=False)
    snapped = load_scene_gt(path)
    for im_id, entries in list(raw.items())[:5]:
        for entry, kept, fixed in zip(entries, stored[int(im_id)], snapped[int(im_id)]):
            np.testing.assert_array_equal(kept.T_model2cam[:3, :3].ravel(), entry["cam_R_m2c"])
            np.testing.assert_allclose(fixed.T_model2cam[:3, :3], kept.T_model2cam[:3, :3], atol=2e-3)
            np.testing.assert_array_equal(fixed.T_model2cam[:3, 3], kept.T_model2cam[:3, 3])


def test_models_info_in_metres_with_symmetries(lmo):
    info = load_models_info(lmo / "models" / "models_info.json")
    assert sorted(info) == [1, 5, 6, 8, 9, 10, 11, 12]
    assert info[1].diameter == pytest.approx(0.102099)
    np.testing.assert_allclose(info[1].minimum, [-0.0379343, -0.0387996, -0.0458845])
    raw = json.loads((lmo / "models" / "models_info.json").read_text())
    symmetric = [obj_id for obj_id, entry in raw.items() if "symmetries_discrete" in entry]
    assert symmetric, "LM-O lists discrete symmetries for the eggbox and glue"
    for obj_id in symmetric:
        transforms = info[int(obj_id)].symmetries_discrete
        assert transforms.shape == (len(raw[obj_id]["symmetries_discrete"]), 4, 4)
        np.testing.assert_allclose(transforms[0][:3, 3] * 1000.0, np.reshape(raw[obj_id]["symmetries_discrete"][0],
                                                                              (4, 4))[:3, 3])
        rotation = transforms[0][:3, :3]
        np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-5)
    mesh = load_model(lmo / "models", 1)
    assert np.abs(mesh.vertices).max() < 0.06  # metres, not millimetres


def test_scene_camera_and_gt_info_parsers(lmo):
    cameras = load_scene_camera(lmo / "test" / "000002" / "scene_camera.json")
    assert len(cameras) == 200 and cameras[3].depth_scale == 1.0 and cameras[3].T_world2cam is None
    infos = load_scene_gt_info(lmo / "test" / "000002" / "scene_gt_info.json")
    assert set(infos) == set(cameras) and 0 <= infos[3][0]["visib_fract"] <= 1


@pytest.mark.parametrize("content, pattern", [
    ("{not json", "scene_gt.json: invalid JSON"),
    ('{"a": []}', "key 'a' is not an image id"),
    ('{"3": [{"cam_R_m2c": [1, 0, 0, 0, 1, 0, 0, 0, 1], "obj_id": 1}]}',
     "image 3, instance 0: missing field 'cam_t_m2c'"),
    ('{"3": [{"cam_R_m2c": [1, 0, 0], "cam_t_m2c": [0, 0, 1], "obj_id": 1}]}', "field 'cam_R_m2c' must hold 9"),
    ('{"3": [{"cam_R_m2c": [1, 0, 0, 0, 2, 0, 0, 0, 1], "cam_t_m2c": [0, 0, 1], "obj_id": 1}]}',
     "image 3, instance 0: not a rotation matrix"),
])
def test_malformed_files_name_file_and_field(tmp_path, content, pattern):
    path = tmp_path / "scene_gt.json"
    path.write_text(content)
    with pytest.raises(ValueError, match=pattern):
        load_scene_gt(path)


def test_missing_files_and_fields_are_named(tmp_path):
    with pytest.raises(ValueError, match="scene_gt.json: file not found"):
        load_scene_gt(tmp_path / "scene_gt.json")
    (tmp_path / "scene_camera.json").write_text('{"0": {"depth_scale": 1.0}}')
    with pytest.raises(ValueError, match="image 0: missing field 'cam_K'"):
        load_scene_camera(tmp_path / "scene_camera.json")
    (tmp_path / "models_info.json").write_text('{"1": {"min_x": 0}}')
    with pytest.raises(ValueError, match="object 1: missing field 'diameter'"):
        load_models_info(tmp_path / "models_info.json")
    (tmp_path / "info.json").write_text('{"0": [{"bbox_obj": [1, 2, 3, 4]}]}')
    with pytest.raises(ValueError, match="instance 0: missing field 'bbox_visib'"):
        load_scene_gt_info(tmp_path / "info.json")
    with pytest.raises(ValueError, match="split folder not found"):
        BOPDataset(tmp_path, split="test")
