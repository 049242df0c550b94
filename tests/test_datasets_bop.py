"""The BOP boundary (``paz6d.datasets.bop``): the reader on real LM-O data (metres, missing parts),
millimetre reads that keep the stored values, the camera, targets and writer, and error messages."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from paz6d.backend.camera import transform_and_project
from paz6d.datasets.bop import (MM_PER_M, BOPDataset, BOPScene, Target, load_camera, load_model, load_models_info,
                                load_scene_camera, load_scene_gt, load_scene_gt_info, read_targets, write_targets)
from paz6d.datasets.bop.scene import read_depth
from paz6d.datasets.bop.targets import targets_from_gt
from paz6d.datasets.bop.units import lengths_from_mm, mm_from_lengths
from paz6d.datasets.bop.writer import depth_png_from_lengths, gt_entry, write_models


@pytest.fixture(scope="module")
def lmo(shared_data):
    return shared_data / "bop_lmo"


def test_lmo_scene_reads_with_missing_depth_masks_and_most_frames(lmo):
    dataset = BOPDataset(lmo, split="test")
    samples = list(dataset)
    assert len(samples) == len(dataset) == 200
    with_images = [sample for sample in samples if sample.image is not None]
    frames_on_disk = sorted((lmo / "test" / "000002" / "rgb").glob("*.png"))
    assert len(with_images) == len(frames_on_disk) == 105
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
    ('{"3": {"obj_id": 1}}', "scene_gt.json: image 3: expected a list of instances"),
    ('{"3": [{"cam_R_m2c": [1, 0, 0, 0, 1, 0, 0, 0, 1], "obj_id": 1}]}',
     "image 3, instance 0: missing field 'cam_t_m2c'"),
    ('{"3": [{"cam_R_m2c": [1, 0, 0], "cam_t_m2c": [0, 0, 1], "obj_id": 1}]}', "field 'cam_R_m2c' must hold 9"),
    ('{"3": [{"cam_R_m2c": [1, 0, 0, 0, 2, 0, 0, 0, 1], "cam_t_m2c": [0, 0, 1], "obj_id": 1}]}',
     "image 3, instance 0, field 'cam_R_m2c': not a rotation matrix"),
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
    with pytest.raises(ValueError, match="info.json: image 0, instance 0: missing field 'bbox_visib'"):
        load_scene_gt_info(tmp_path / "info.json")
    (tmp_path / "info.json").write_text('{"0": [], "2": {"bbox_obj": [1, 2, 3, 4]}}')
    with pytest.raises(ValueError, match="info.json: image 2: expected a list of instances"):
        load_scene_gt_info(tmp_path / "info.json")
    with pytest.raises(ValueError, match="split folder not found"):
        BOPDataset(tmp_path, split="test")


def test_lmo_camera_json_gives_the_scene_intrinsics(lmo):
    camera = load_camera(lmo / "camera.json")
    assert (camera.width, camera.height) == (640, 480)
    np.testing.assert_allclose(camera.K, load_scene_camera(lmo / "test" / "000002" / "scene_camera.json")[3].K)
    np.testing.assert_allclose(camera.K, [[572.4114, 0, 325.2611], [0, 573.57043, 242.04899], [0, 0, 1]])


def test_camera_json_errors(tmp_path):
    with pytest.raises(ValueError, match="missing.json: camera file not found"):
        load_camera(tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(ValueError, match="invalid JSON"):
        load_camera(tmp_path / "bad.json")
    (tmp_path / "partial.json").write_text(json.dumps({"fx": 1.0, "fy": 1.0, "cx": 0.5}))
    with pytest.raises(ValueError, match="partial.json: missing field 'cy'"):
        load_camera(tmp_path / "partial.json")


def test_millimetres_are_read_as_stored_and_metres_converted_once(lmo):
    path = lmo / "test" / "000002" / "scene_gt.json"
    raw = json.loads(path.read_text())
    in_mm = load_scene_gt(path, snap_rotations=False, units="mm")
    in_m = load_scene_gt(path, snap_rotations=False)
    for im_id, entries in list(raw.items())[:20]:
        for entry, mm, m in zip(entries, in_mm[int(im_id)], in_m[int(im_id)]):
            np.testing.assert_array_equal(mm.T_model2cam[:3, 3], entry["cam_t_m2c"])  # bit for bit
            np.testing.assert_array_equal(m.T_model2cam[:3, 3], np.asarray(entry["cam_t_m2c"]) * 0.001)
    info_mm = load_models_info(lmo / "models" / "models_info.json", units="mm")
    raw_info = json.loads((lmo / "models" / "models_info.json").read_text())
    for obj_id, entry in raw_info.items():
        assert info_mm[int(obj_id)].diameter == entry["diameter"]
        assert info_mm[int(obj_id)].minimum.tolist() == [entry["min_x"], entry["min_y"], entry["min_z"]]
    mesh_mm = load_model(lmo / "models", 1, units="mm")
    np.testing.assert_allclose(load_model(lmo / "models", 1).vertices * MM_PER_M, mesh_mm.vertices, rtol=1e-12)
    with pytest.raises(ValueError, match="units: expected one of \\('m', 'mm'\\), got 'cm'"):
        load_scene_gt(path, units="cm")


def test_unit_converters_are_exact_inverses_of_the_old_literals():
    values = np.random.default_rng(3).normal(0, 500, 1000)
    np.testing.assert_array_equal(lengths_from_mm(values, "m"), values * 0.001)
    np.testing.assert_array_equal(mm_from_lengths(values, "m"), values * 1000.0)
    np.testing.assert_array_equal(lengths_from_mm(values, "mm"), values)
    np.testing.assert_array_equal(mm_from_lengths(values, "mm"), values)


def test_depth_written_in_metres_reads_back_in_both_units(tmp_path):
    import cv2

    depth_m = np.array([[0.0, 0.5], [1.2345, 70.0]], dtype=np.float32)
    stored = depth_png_from_lengths(depth_m, depth_scale=0.1)
    np.testing.assert_array_equal(stored, [[0, 5000], [12345, 65535]])  # 0.1 mm units, clipped at 16 bits
    cv2.imwrite(str(tmp_path / "000000.png"), stored)
    np.testing.assert_allclose(read_depth(tmp_path / "000000.png", 0.1, units="mm"), stored * 0.1)
    np.testing.assert_allclose(read_depth(tmp_path / "000000.png", 0.1), stored * 0.1 / 1000.0)


def test_written_ground_truth_and_models_read_back_in_metres(tmp_path):
    import trimesh

    T = np.eye(4)
    T[:3, :3] = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    T[:3, 3] = [0.01, -0.02, 0.75]
    entry = gt_entry(7, T)
    assert entry["obj_id"] == 7 and entry["cam_t_m2c"] == [10.0, -20.0, 750.0]
    (tmp_path / "scene_gt.json").write_text(json.dumps({"0": [entry]}))
    (read,) = load_scene_gt(tmp_path / "scene_gt.json")[0]
    assert read.obj_id == 7
    np.testing.assert_allclose(read.T_model2cam, T, atol=1e-15)
    box = trimesh.creation.box((0.02, 0.04, 0.06))
    paths = write_models(tmp_path / "models", [box], [7], [0.08], {7: {"symmetries_discrete": []}})
    assert [path.name for path in paths] == ["obj_000007.ply", "models_info.json"]
    info = load_models_info(tmp_path / "models" / "models_info.json")[7]
    assert info.diameter == pytest.approx(0.08)
    np.testing.assert_allclose(info.minimum, [-0.01, -0.02, -0.03])
    np.testing.assert_allclose(info.size, [0.02, 0.04, 0.06])
    assert json.loads(paths[1].read_text())["7"]["size_z"] == pytest.approx(60.0)
    np.testing.assert_allclose(load_model(tmp_path / "models", 7).bounds, box.bounds, atol=1e-7)


def test_targets_round_trip_and_come_from_visible_instances(tmp_path):
    targets = (targets_from_gt(1, 4, [5, 2, 5, 5], [0.9, 0.5, 0.05, 0.1])
               + targets_from_gt(1, 5, [3], [0.0]))
    assert targets == [Target(1, 4, 2, 1), Target(1, 4, 5, 2)]
    path = write_targets(tmp_path / "targets.json", targets)
    assert json.loads(path.read_text())[1] == {"scene_id": 1, "im_id": 4, "obj_id": 5, "inst_count": 2}
    assert read_targets(path) == targets


def test_duplicated_targets_are_rejected_naming_file_and_entry(tmp_path):
    path = tmp_path / "test_targets_bop19.json"
    entries = [{"scene_id": 2, "im_id": 3, "obj_id": 5, "inst_count": 1},
               {"scene_id": 2, "im_id": 3, "obj_id": 6, "inst_count": 1},
               {"scene_id": 2, "im_id": 3, "obj_id": 5, "inst_count": 1}]
    path.write_text(json.dumps(entries))
    with pytest.raises(ValueError, match=r"test_targets_bop19.json: target 2 repeats target 0: scene 2, image 3, "
                                         r"object 5"):
        read_targets(path)
    path.write_text(json.dumps([{"scene_id": 2, "im_id": 3, "obj_id": 5, "inst_count": 0}]))
    with pytest.raises(ValueError, match="target 0: field 'inst_count' must be positive"):
        read_targets(path)
    path.write_text(json.dumps([{"scene_id": 2, "im_id": "3", "obj_id": 5, "inst_count": 1}]))
    with pytest.raises(ValueError, match="target 0: field 'im_id' must be a non-negative integer, got '3'"):
        read_targets(path)


def test_a_split_without_annotations_reads_the_images_of_scene_camera_json(tmp_path):
    import cv2

    scene = tmp_path / "set" / "test" / "000003"
    (scene / "rgb").mkdir(parents=True)
    (scene / "depth").mkdir()
    K = [[300.0, 0, 15.5], [0, 300.0, 11.5], [0, 0, 1]]
    (scene / "scene_camera.json").write_text(json.dumps({str(im_id): {"cam_K": np.ravel(K).tolist(), "depth_scale": 0.1}
                                                         for im_id in (4, 9)}))
    cv2.imwrite(str(scene / "rgb" / "000004.png"), np.full((24, 32, 3), 7, np.uint8))
    cv2.imwrite(str(scene / "depth" / "000004.png"), np.full((24, 32), 5000, np.uint16))
    with pytest.raises(ValueError, match="scene_gt.json"):
        BOPDataset(tmp_path / "set", "test")
    first, second = BOPDataset(tmp_path / "set", "test", ground_truth=False)
    assert (first.scene_id, first.im_id, second.im_id) == (3, 4, 9)
    assert first.objects == [] and first.image.shape == (24, 32, 3) and second.image is None
    np.testing.assert_allclose(first.depth, 0.5)  # 5000 x 0.1 mm
    np.testing.assert_allclose(first.K, K)


def test_load_gives_the_lmo_split_as_the_shared_sample_interface(lmo):
    from paz6d.datasets.bop import load

    samples = load(lmo, "test")
    raw_gt = json.loads((lmo / "test" / "000002" / "scene_gt.json").read_text())
    raw_info = json.loads((lmo / "test" / "000002" / "scene_gt_info.json").read_text())
    assert len(samples) == len(raw_gt) == 200 and samples.class_names == [f"obj_{i:06d}" for i in (1, 5, 6, 8, 9,
                                                                                                      10, 11, 12)]
    scene = BOPDataset(lmo, "test").scenes[0]
    for sample in (samples[0], samples[57], samples[199]):
        reference = scene.sample(sample.extras["im_id"])
        gt, info = raw_gt[str(reference.im_id)], raw_info[str(reference.im_id)]
        assert sample.class_names == [f"obj_{entry['obj_id']:06d}" for entry in gt]
        assert [samples.class_names[i] for i in sample.class_ids] == sample.class_names
        for index, (entry, instance) in enumerate(zip(info, reference.objects)):
            x, y, width, height = entry["bbox_visib"]
            expected = (x, y, x + width, y + height) if width > 0 else (0, 0, 0, 0)
            np.testing.assert_array_equal(sample.boxes[index], expected)
            np.testing.assert_array_equal(sample.poses[index], instance.T_model2cam)  # metres, as BOPDataset's
            assert sample.extras["visibility"][index] == entry["visib_fract"]
        np.testing.assert_array_equal(sample.camera_matrix, reference.K)
        assert Path(sample.image).name == f"{reference.im_id:06d}.png" and sample.extras["image_size"] == (640, 480)
        assert sample.extras["depth"] is None and sample.extras["scene_id"] == 2


def test_load_names_an_unseen_instance_with_an_empty_box(tmp_path):
    from paz6d.datasets.bop import load

    scene = tmp_path / "set" / "test" / "000000"
    scene.mkdir(parents=True)
    K = [[300.0, 0, 15.5], [0, 300.0, 11.5], [0, 0, 1]]
    T = np.eye(4)
    T[:3, 3] = [0.0, 0.0, 0.5]
    (scene / "scene_camera.json").write_text(json.dumps({"0": {"cam_K": np.ravel(K).tolist(), "depth_scale": 1}}))
    (scene / "scene_gt.json").write_text(json.dumps({"0": [gt_entry(7, T), gt_entry(3, T)]}))
    info = {"bbox_obj": [1, 2, 3, 4], "bbox_visib": [-1, -1, -1, -1], "visib_fract": 0.0, "px_count_all": 12,
            "px_count_valid": 12, "px_count_visib": 0}
    (scene / "scene_gt_info.json").write_text(json.dumps({"0": [info, {**info, "bbox_visib": [2, 3, 4, 5],
                                                                         "visib_fract": 0.5}]}))
    samples = load(tmp_path / "set", "test")
    sample, = samples
    assert samples.class_names == ["obj_000003", "obj_000007"] and sample.class_ids.tolist() == [1, 0]
    np.testing.assert_array_equal(sample.boxes, [[0, 0, 0, 0], [2, 3, 6, 8]])
    np.testing.assert_array_equal(load(tmp_path / "set", "test", box="obj")[0].boxes, [[1, 2, 4, 6], [1, 2, 4, 6]])
    np.testing.assert_array_equal(sample.extras["visibility"], [0.0, 0.5])
    np.testing.assert_allclose(sample.poses[0], T)
    with pytest.raises(ValueError, match="box: expected 'visib' or 'obj'"):
        load(tmp_path / "set", "test", box="full")
