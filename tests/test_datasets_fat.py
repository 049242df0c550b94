"""FAT (Falling Things) loader: the published NDDS files, centimetres to metres, the camera frame and
quaternion convention (pinned on a record written by NDDS itself), splits, and clear errors.

Fixture: ``tests/data/datasets/fat`` (``make_pose_fixtures.py``: boxes ray-cast at pixel centres)."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from paz6d.backend import quaternion
from paz6d.backend.camera import project_points, transform_and_project, unproject
from paz6d.backend.mesh import load_mesh
from paz6d.backend.transform import apply, invert
from paz6d.datasets import fat

ROOT = Path(__file__).parent / "data" / "datasets" / "fat"

#: One object record as NDDS writes it (the exporter FAT was made with; quoted in a public repository's
#: comments), 1280 x 720 camera. Its cuboid and projections pin the conventions: OpenCV camera frame in
#: centimetres, quaternion x, y, z, w, the corner order and (y, x) boxes.
NDDS_RECORD = {
    "class": "productobj", "instance_id": 14913080, "visibility": 0, "location": [20, -3, 50],
    "quaternion_xyzw": [0, 0.70709997415542603, -0.70709997415542603, 0],
    "pose_transform": [[0, -1, 0, 0], [-1, 0, 0, 0], [0, 0, 1, 0], [20, -3, 50, 1]],
    "cuboid_centroid": [20, -5.9998998641967773, 45.500099182128906],
    "projected_cuboid_centroid": [1046.275390625, 238.11830139160156],
    "bounding_box": {"top_left": [22.022800445556641, 824.39642333984375],
                     "bottom_right": [417.7655029296875, 1226.842041015625]},
    "cuboid": [[10.100099563598633, -14.849800109863281, 50], [29.899900436401367, -14.849800109863281, 50],
               [29.899900436401367, -14.849800109863281, 41.000099182128906],
               [10.100099563598633, -14.849800109863281, 41.000099182128906],
               [10.100099563598633, 2.8499000072479248, 50], [29.899900436401367, 2.8499000072479248, 50],
               [29.899900436401367, 2.8499000072479248, 41.000099182128906],
               [10.100099563598633, 2.8499000072479248, 41.000099182128906]],
    "projected_cuboid": [[826.70599365234375, 85.493202209472656], [1192.7159423828125, 85.493301391601563],
                         [1314.0419921875, 25.236499786376953], [867.6898193359375, 25.236499786376953],
                         [826.70599365234375, 412.681884765625], [1192.7159423828125, 412.681884765625],
                         [1314.0419921875, 424.24609375], [867.6898193359375, 424.24609375]],
}


@pytest.fixture
def copy(tmp_path):
    target = tmp_path / "fat"
    shutil.copytree(ROOT, target)
    return target


def _edit_json(path, change):
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))


def test_mixed_split_reads_every_field_in_metres():
    samples = fat.load(ROOT, "mixed")
    assert len(samples) == 2 and samples.class_names == ["003_cracker_box_16k", "006_mustard_bottle_16k"]
    sample = samples[0]
    assert sample.image == ROOT / "mixed/kitchen_0/000000.left.jpg"
    assert sample.class_names == ["003_cracker_box_16k", "006_mustard_bottle_16k"]
    np.testing.assert_array_equal(sample.class_ids, [0, 1])
    record = json.loads((ROOT / "mixed/kitchen_0/000000.left.json").read_text())["objects"][0]
    np.testing.assert_allclose(sample.keypoints[0], record["projected_cuboid"])
    (y_min, x_min), (y_max, x_max) = record["bounding_box"]["top_left"], record["bounding_box"]["bottom_right"]
    np.testing.assert_allclose(sample.boxes[0], [x_min, y_min, x_max, y_max])  # stored as (y, x)
    np.testing.assert_allclose(sample.extras["cuboid"][0], np.array(record["cuboid"]) / 100)  # cm -> m
    T = fat.load(ROOT, "mixed", model_frame="exported")[0].poses[0]
    np.testing.assert_allclose(T[:3, 3], np.array(record["location"]) / 100)
    assert sample.masks.shape == (2, 36, 64) and sample.masks.sum() > 300
    np.testing.assert_allclose(sample.camera_matrix, [[51.2107, 0, 32], [0, 51.2107, 18], [0, 0, 1]])
    assert sample.extras["frame"] == "mixed/kitchen_0/000000.left" and sample.extras["image_size"] == (64, 36)


def test_location_cuboid_and_model_poses_agree_with_projections_masks_and_depth():
    """``K @ location`` is the projected centroid, the cuboid projects to ``projected_cuboid``, and the
    pose of the YCB model (through ``fixed_model_transform``) puts the mesh where masks and depth are."""
    for split, camera in (("mixed", "left"), ("mixed", "right"), ("single", "left")):
        for sample, exported in zip(fat.load(ROOT, split, camera=camera, depth=True),
                                    fat.load(ROOT, split, camera=camera, masks=False, model_frame="exported")):
            K = sample.camera_matrix
            for index, (T, name, mask) in enumerate(zip(sample.poses, sample.class_names, sample.masks)):
                np.testing.assert_allclose(project_points(sample.extras["cuboid_centroid"][index][None], K)[0],
                                           sample.extras["projected_centroid"][index], atol=1e-3)
                np.testing.assert_allclose(project_points(sample.extras["cuboid"][index], K), sample.keypoints[index],
                                           atol=1e-3)
                np.testing.assert_allclose(project_points(exported.poses[index][:3, 3][None], K)[0],  # location
                                           sample.extras["projected_centroid"][index], atol=1e-3)
                mesh = load_mesh(ROOT / "ycb_models" / name.removesuffix("_16k") / "google_16k" / "textured.obj")
                vertices = np.asarray(mesh.vertices)
                uv = transform_and_project(vertices, T, K)
                np.testing.assert_allclose(np.sort(uv, axis=0), np.sort(sample.keypoints[index], axis=0), atol=2e-3)
                rows, columns = np.nonzero(mask)
                points = apply(invert(T), unproject(np.stack([columns, rows], 1).astype(float),
                                                    sample.extras["depth"][rows, columns], K))
                low, high = vertices.min(axis=0), vertices.max(axis=0)
                assert np.all(points >= low - 3e-4) and np.all(points <= high + 3e-4)


def test_conventions_on_a_record_written_by_ndds(tmp_path):
    """Rotating the corners of ``cuboid_dimensions`` (in :data:`fat.CUBOID_CORNER_SIGNS` order) by
    ``quaternion_xyzw`` about ``cuboid_centroid`` gives NDDS's ``cuboid``; K projects it to its
    ``projected_cuboid`` to 0.001 px, so both are in the OpenCV camera frame."""
    scene = tmp_path / "export"
    scene.mkdir()
    (scene / "_object_settings.json").write_text(json.dumps({"exported_object_classes": ["productobj"],
        "exported_objects": [{"class": "productobj", "segmentation_class_id": 1, "cuboid_dimensions": [19.8, 9.0, 17.7],
                              "fixed_model_transform": [[100, 0, 0, 0], [0, 100, 0, 0], [0, 0, 100, 0],
                                                        [0, 0, 0, 1]]}]}))
    (scene / "_camera_settings.json").write_text(json.dumps({"camera_settings": [{"name": "Viewpoint",
        "intrinsic_settings": {"fx": 924.2764, "fy": 924.2774, "cx": 640.0004, "cy": 359.9999, "s": 0},
        "captured_image_size": {"width": 1280, "height": 720}}]}))
    (scene / "000000.left.json").write_text(json.dumps({"camera_data": {}, "objects": [NDDS_RECORD]}))
    sample = fat.load(scene, ".", masks=False)[0]
    R = quaternion.to_rotation_matrix(np.array(NDDS_RECORD["quaternion_xyzw"]) / np.sqrt(2 * 0.70709997415542603 ** 2))
    np.testing.assert_allclose(sample.poses[0][:3, :3], R)
    np.testing.assert_allclose(sample.poses[0][:3, 3], [0.2, -0.03, 0.5])
    corners = fat.cuboid_corners([0.198, 0.09, 0.177]) @ R.T + sample.extras["cuboid_centroid"][0]
    np.testing.assert_allclose(corners, sample.extras["cuboid"][0], atol=1e-5)  # float32 centimetres
    np.testing.assert_allclose(project_points(sample.extras["cuboid"][0], sample.camera_matrix), sample.keypoints[0],
                               atol=1e-3)
    np.testing.assert_allclose(sample.boxes[0], [824.39642333984375, 22.022800445556641, 1226.842041015625,
                                                 417.7655029296875])


def test_splits_cameras_and_scene_folders():
    assert len(fat.load(ROOT, "single")) == 1 and len(fat.load(ROOT, "mixed/kitchen_0", camera="right")) == 2
    assert fat.load(ROOT, "single").class_names == ["003_cracker_box_16k"]
    assert [s.extras["frame"] for s in fat.load(ROOT, ".")] == [
        "mixed/kitchen_0/000000.left", "mixed/kitchen_0/000001.left",
        "single/003_cracker_box_16k/kitchen_0/000000.left"]
    with pytest.raises(ValueError, match=r"split: .*/fat/test is not a folder \(folders in .*\['mixed', 'single'"):
        fat.load(ROOT, "test")
    with pytest.raises(ValueError, match="split: expected a relative path inside"):
        fat.load(ROOT, "../fat")
    with pytest.raises(ValueError, match="camera: expected one of"):
        fat.load(ROOT, "mixed", camera="centre")
    with pytest.raises(ValueError, match="model_frame: expected one of"):
        fat.load(ROOT, "mixed", model_frame="world")


def test_malformed_files_name_the_file_the_object_and_the_field(copy):
    frame = copy / "mixed/kitchen_0/000001.left.json"
    samples = fat.load(copy, "mixed")
    (copy / "mixed/kitchen_0/000001.left.seg.png").unlink()
    with pytest.raises(ValueError, match=r"000001.left.seg.png: segmentation image not found"):
        samples[1]
    _edit_json(frame, lambda data: data["objects"][1].pop("quaternion_xyzw"))
    with pytest.raises(ValueError, match=r"000001.left.json, objects\[1\]: missing field 'quaternion_xyzw'"):
        samples[1]
    assert samples[0].poses.shape == (2, 4, 4)  # lazy: other frames still load
    _edit_json(frame, lambda data: data["objects"][1].update(quaternion_xyzw=[0, 0, 0, 2]))
    with pytest.raises(ValueError, match=r"objects\[1\]: field 'quaternion_xyzw' must be a unit quaternion"):
        samples[1]
    _edit_json(frame, lambda data: data["objects"][1].update(quaternion_xyzw=[0, 0, 0, 1], location=[1, "a", 2]))
    with pytest.raises(ValueError, match=r"objects\[1\]: field 'location' is not numeric"):
        samples[1]
    _edit_json(frame, lambda data: data["objects"][1].update(location=[1, 2, 3], **{"class": "999_unknown_16k"}))
    with pytest.raises(ValueError, match=r"objects\[1\]: field 'class' holds unknown class '999_unknown_16k'"):
        samples[1]
    _edit_json(frame, lambda data: data["objects"][1].update(bounding_box={"top_left": [1, 2]},
                                                              **{"class": "003_cracker_box_16k"}))
    with pytest.raises(ValueError, match=r"objects\[1\] bounding_box: missing field 'bottom_right'"):
        samples[1]
    frame.write_text("{not json")
    with pytest.raises(ValueError, match=r"000001.left.json: invalid JSON"):
        samples[1]
    settings = copy / "mixed/kitchen_0/_object_settings.json"
    _edit_json(settings, lambda data: data["exported_objects"][1].pop("fixed_model_transform"))
    with pytest.raises(ValueError, match=r"_object_settings.json, exported_objects\[1\]: missing field "
                                         r"'fixed_model_transform'"):
        fat.load(copy, "mixed")
    cameras = copy / "single/003_cracker_box_16k/kitchen_0/_camera_settings.json"
    _edit_json(cameras, lambda data: data["camera_settings"][1].update(name="centre"))
    with pytest.raises(ValueError, match=r"_camera_settings.json: no camera named 'right'"):
        fat.load(copy, "single", camera="right")
