"""YCB-Video loader: the published per-frame files (``-meta.mat``, ``-box.txt``, ``-label.png``,
``-depth.png``), its pose and intrinsics conventions, and clear errors for malformed files.

Fixture: ``tests/data/datasets/ycb_video`` (``make_pose_fixtures.py``: boxes ray-cast at pixel centres)."""

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import scipy.io

from paz6d.backend.camera import transform_and_project, unproject
from paz6d.backend.transform import apply, invert
from paz6d.datasets import ycb_video
from paz6d.datasets.sample import Sample

ROOT = Path(__file__).parent / "data" / "datasets" / "ycb_video"


@pytest.fixture
def copy(tmp_path):
    target = tmp_path / "YCB_Video_Dataset"
    shutil.copytree(ROOT, target)
    return target


def _resave_meta(path, **changes):
    meta = {key: value for key, value in scipy.io.loadmat(str(path)).items() if not key.startswith("__")}
    for key, value in changes.items():
        if value is None:
            del meta[key]
        else:
            meta[key] = value
    scipy.io.savemat(str(path), meta)


def test_train_split_reads_every_field_of_the_published_layout():
    samples = ycb_video.load(ROOT, "train")
    assert len(samples) == 2 and samples.class_names == list(ycb_video.YCB_VIDEO_CLASSES)
    first, second = samples
    assert isinstance(first, Sample) and first.image == ROOT / "data/0048/000001-color.png"
    assert first.class_names == ["003_cracker_box", "006_mustard_bottle"]
    np.testing.assert_array_equal(first.class_ids, [1, 4])
    np.testing.assert_array_equal(first.extras["label_ids"], [2, 5])  # 1-based, as label pixels and BOP YCB-V ids
    assert first.poses.shape == (2, 4, 4) and first.masks.shape == (2, 48, 64) and first.masks.dtype == bool
    np.testing.assert_allclose(first.boxes[0], [16.55, 10.86, 37.01, 37.90])  # -box.txt, as stored
    np.testing.assert_allclose(first.camera_matrix[0], [106.6778, 0.0, 31.29869])
    assert first.extras["factor_depth"] == 10000.0 and first.extras["frame"] == "0048/000001"
    # a one-object frame: MATLAB stores poses as (3, 4), not (3, 4, 1)
    assert second.poses.shape == (1, 4, 4) and second.class_names == ["003_cracker_box"]
    assert ycb_video.load(ROOT, "keyframe")[0].extras["frame"] == "0051/000001"
    assert samples[-1].extras["frame"] == "0048/000002" and len(samples[0:2]) == 2


def test_pose_and_intrinsics_conventions_agree_with_boxes_centres_masks_and_depth():
    """poses map model points (points.xyz, metres) to the camera: projected with intrinsic_matrix they
    span the stored box; the projected model origin is meta's `center`; every masked depth pixel,
    lifted with K and mapped back with the inverse pose, lies on the object's model surface."""
    for split in ("train", "keyframe"):
        for sample in ycb_video.load(ROOT, split, depth=True):
            depth = sample.extras["depth"]
            assert depth.dtype == np.float32
            for T, name, box, mask, centre in zip(sample.poses, sample.class_names, sample.boxes, sample.masks,
                                                  sample.extras["centers"]):
                points = ycb_video.model_points(ROOT, name)
                uv = transform_and_project(points, T, sample.camera_matrix)
                extent = np.concatenate([uv.min(axis=0), uv.max(axis=0)]) + 0.5  # pixel centres -> box convention
                np.testing.assert_allclose(extent, box, atol=0.006)
                np.testing.assert_allclose(transform_and_project(np.zeros((1, 3)), T, sample.camera_matrix)[0], centre,
                                           atol=1e-6)
                rows, columns = np.nonzero(mask)
                cam = unproject(np.stack([columns, rows], axis=1).astype(float), depth[rows, columns],
                                sample.camera_matrix)
                model = apply(invert(T), cam)
                low, high = points.min(axis=0), points.max(axis=0)
                assert np.all(model >= low - 2e-4) and np.all(model <= high + 2e-4)  # 0.1 mm depth steps
                on_face = np.isclose(model, low, atol=2e-4) | np.isclose(model, high, atol=2e-4)
                assert np.all(on_face.any(axis=1))


def test_synthetic_frames_without_box_files_get_their_mask_boxes():
    samples = ycb_video.load(ROOT, "data_syn", masks=False)
    assert len(samples) == 1
    sample = samples[0]
    assert sample.masks is None and sample.class_names == ["006_mustard_bottle"]
    assert sample.image == ROOT / "data_syn/000000-color.png"
    label = ycb_video.load(ROOT, "data_syn")[0].masks[0]
    rows, columns = np.nonzero(label)
    np.testing.assert_array_equal(sample.boxes[0], [columns.min(), rows.min(), columns.max() + 1, rows.max() + 1])


def test_models_classes_and_meshes():
    assert ycb_video.read_classes(ROOT)[1] == "003_cracker_box"
    assert ycb_video.model_mesh_path(ROOT, "003_cracker_box").name == "textured.obj"
    assert ycb_video.model_points(ROOT, "006_mustard_bottle").shape[1] == 3
    with pytest.raises(ValueError, match="no model folder for class '002_master_chef_can'"):
        ycb_video.model_mesh_path(ROOT, "002_master_chef_can")


def test_bad_splits_and_folders_name_what_is_wrong(tmp_path):
    with pytest.raises(ValueError, match=r"split: .*test.txt does not exist .*\['keyframe', 'train'\]"):
        ycb_video.load(ROOT, "test")
    with pytest.raises(ValueError, match="expected a YCB-Video image set name"):
        ycb_video.load(ROOT, "../train")
    with pytest.raises(ValueError, match="not a YCB-Video folder"):
        ycb_video.load(tmp_path, "train")


def test_malformed_meta_files_name_the_file_the_object_and_the_field(copy):
    meta = copy / "data/0048/000001-meta.mat"
    _resave_meta(meta, poses=None)
    samples = ycb_video.load(copy, "train")  # lazy: the split loads, the bad frame fails when read
    with pytest.raises(ValueError, match=r"000001-meta.mat: missing field 'poses'"):
        samples[0]
    assert samples[1].poses.shape == (1, 4, 4)
    _resave_meta(meta, poses=np.zeros((3, 4, 5)))
    with pytest.raises(ValueError, match=r"field 'poses' must have shape \(3, 4, 2\) for 2 objects"):
        samples[0]
    good = scipy.io.loadmat(str(copy / "data/0051/000001-meta.mat"))["poses"]
    _resave_meta(meta, poses=good, cls_indexes=np.array([[2], [22]]))
    with pytest.raises(ValueError, match=r"000001-meta.mat, object 1: field 'cls_indexes' holds 22, expected a class "
                                         r"index in 1..21"):
        samples[0]
    bent = good.copy()
    bent[0, 0, 1] = 3.0
    _resave_meta(meta, poses=bent, cls_indexes=np.array([[2], [5]]))
    with pytest.raises(ValueError, match=r"object 1: field 'poses' rotation is not a rotation matrix"):
        samples[0]
    _resave_meta(meta, poses=good, intrinsic_matrix=np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"field 'intrinsic_matrix' must be"):
        samples[0]
    _resave_meta(meta, intrinsic_matrix=scipy.io.loadmat(str(copy / "data/0051/000001-meta.mat"))["intrinsic_matrix"])
    label = copy / "data/0048/000001-label.png"
    label.write_bytes((copy / "data/0048/000001-color.png").read_bytes())
    with pytest.raises(ValueError, match=r"000001-label.png: expected a single-channel 8- or 16-bit label image"):
        samples[0]
    label.unlink()
    with pytest.raises(ValueError, match=r"000001-label.png: label image not found"):
        samples[0]
    assert ycb_video.load(copy, "train", masks=False)[0].masks is None  # boxes from -box.txt: no label needed
    meta.write_bytes(b"not a mat file")
    with pytest.raises(ValueError, match=r"000001-meta.mat: not a readable MATLAB .mat file"):
        samples[0]


def test_malformed_box_files_name_the_line(copy):
    box = copy / "data/0048/000001-box.txt"
    lines = box.read_text().splitlines()
    samples = ycb_video.load(copy, "train")
    box.write_text(lines[0] + "\n999_unknown 1 2 3 4\n")
    with pytest.raises(ValueError, match=r"000001-box.txt, line 2: unknown class '999_unknown'"):
        samples[0]
    box.write_text(lines[0] + "\n006_mustard_bottle 1 2 x 4\n")
    with pytest.raises(ValueError, match=r"line 2: expected '<class name> x1 y1 x2 y2'"):
        samples[0]
    box.write_text(lines[0] + "\n")
    with pytest.raises(ValueError, match=r"000001-box.txt: no box for '006_mustard_bottle' \(object 1"):
        samples[0]
    (copy / "models/003_cracker_box/points.xyz").write_text("0 0 0\n1 2\n")
    with pytest.raises(ValueError, match=r"points.xyz, line 2: expected 'x y z'"):
        ycb_video.model_points(copy, "003_cracker_box")
    (copy / "image_sets/train.txt").write_text("0048/000001\n0048\n")
    with pytest.raises(ValueError, match=r"train.txt, line 2: expected <video>/<frame>"):
        ycb_video.load(copy, "train")


def test_the_fixture_generator_reproduces_the_committed_fixtures(tmp_path):
    """``make_pose_fixtures.py`` regenerates both fixtures (text files byte for byte, images pixel for
    pixel, ``.mat`` files array for array, floats to 1e-12: their headers carry the creation time)."""
    import importlib.util

    path = ROOT.parent / "make_pose_fixtures.py"
    spec = importlib.util.spec_from_file_location("make_pose_fixtures", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.make_ycb_video(tmp_path / "ycb_video")
    module.make_fat(tmp_path / "fat")
    for name in ("ycb_video", "fat"):
        committed = sorted(p.relative_to(ROOT.parent / name) for p in (ROOT.parent / name).rglob("*") if p.is_file())
        made = sorted(p.relative_to(tmp_path / name) for p in (tmp_path / name).rglob("*") if p.is_file())
        assert made == committed
        for relative in committed:
            new, old = tmp_path / name / relative, ROOT.parent / name / relative
            if relative.suffix == ".mat":
                new_meta, old_meta = scipy.io.loadmat(str(new)), scipy.io.loadmat(str(old))
                for key in (key for key in old_meta if not key.startswith("__")):
                    if np.issubdtype(old_meta[key].dtype, np.floating):  # the last bit varies with the CPU's maths
                        np.testing.assert_allclose(new_meta[key], old_meta[key], rtol=1e-12, atol=1e-12)
                    else:
                        np.testing.assert_array_equal(new_meta[key], old_meta[key])
            elif relative.suffix in (".png", ".jpg"):  # pixels, not bytes: encoders differ between builds
                decoded = [cv2.imdecode(np.fromfile(p, np.uint8), cv2.IMREAD_UNCHANGED).astype(int) for p in (new, old)]
                tolerance = 3 if relative.suffix == ".jpg" else 0
                assert np.abs(decoded[0] - decoded[1]).max() <= tolerance, relative
            else:
                assert new.read_bytes() == old.read_bytes(), relative
