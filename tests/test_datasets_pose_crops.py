"""YCB-Video / FAT data sets feeding the pose trainers: format detection, the crop adapter
(:mod:`paz6d.datasets.pose_crops`), ``paz6d train aae|keypointnet --dataset`` flags, and tiny training
runs on the fixtures of ``tests/data/datasets`` (``make_pose_fixtures.py``)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from paz6d.backend.tensorflow_guard import import_tensorflow

import_tensorflow()  # before any renderer in this process (workers=0)

from paz6d.backend.camera import transform_and_project  # noqa: E402
from paz6d.backend.mesh import load_mesh  # noqa: E402
from paz6d.cli import main  # noqa: E402
from paz6d.datasets import pose_crops  # noqa: E402
from paz6d.datasets.pose_format import check_pose_split, detect_pose_format  # noqa: E402

DATA = Path(__file__).parent / "data" / "datasets"
YCB = DATA / "ycb_video"
FAT = DATA / "fat"
FAT_MESH = FAT / "ycb_models" / "003_cracker_box" / "google_16k" / "textured.obj"


def test_formats_are_detected_and_splits_checked(tmp_path):
    assert detect_pose_format(YCB) == "ycb_video" and detect_pose_format(FAT) == "fat"
    assert detect_pose_format(FAT / "mixed" / "kitchen_0") == "fat" and detect_pose_format(tmp_path) == "bop"
    assert check_pose_split("mixed/kitchen_0", "fat") == "mixed/kitchen_0"
    for split, dataset_format in (("../x", "fat"), ("/etc", "fat"), ("a/b", "ycb_video"), ("..", "bop"), ("", "bop")):
        with pytest.raises(ValueError, match="^split: expected"):
            check_pose_split(split, dataset_format)


def test_resolving_the_object_and_its_mesh():
    source = pose_crops.pose_dataset(YCB, "ycb_video", object_class="003_cracker_box")
    assert source.mesh_path == YCB / "models/003_cracker_box/textured.obj" and source.mesh_scale == 1.0
    assert pose_crops.pose_dataset(YCB, "ycb_video", object_id=5).class_name == "006_mustard_bottle"  # BOP YCB-V id
    assert pose_crops.pose_dataset(FAT, "fat", "single", mesh=FAT_MESH).class_name == "003_cracker_box_16k"
    with pytest.raises(ValueError, match="^object_class: .* has 2 classes; choose one with --object-class"):
        pose_crops.pose_dataset(FAT, "fat", mesh=FAT_MESH)
    with pytest.raises(ValueError, match="^object_class: no class '999_x'"):
        pose_crops.pose_dataset(FAT, "fat", object_class="999_x", mesh=FAT_MESH)
    with pytest.raises(ValueError, match="^dataset_mesh: FAT data sets ship no meshes"):
        pose_crops.pose_dataset(FAT, "fat", object_class="003_cracker_box")
    with pytest.raises(ValueError, match="^object_id: expected a class index in 1..21"):
        pose_crops.pose_dataset(YCB, "ycb_video", object_id=30)


@pytest.mark.parametrize("dataset_format, root, split, mesh", [("ycb_video", YCB, "train", None),
                                                               ("fat", FAT, "mixed", FAT_MESH)])
def test_crops_carry_intrinsics_and_poses_that_put_the_model_where_the_object_is(dataset_format, root, split, mesh):
    """AAE crops (around the data set's boxes) and KeypointNet views (around the visible masks): the
    model projected with each crop's intrinsics and pose fills the crop as the box or mask does."""
    from paz6d.aae.dataset import sample_crops
    from paz6d.keypointnet.dataset import sample_object_views

    source = pose_crops.pose_dataset(root, dataset_format, split, "003_cracker_box", mesh=mesh)
    vertices = np.asarray(load_mesh(source.mesh_path, source.mesh_scale).vertices)
    crops, Ks, poses = sample_crops(root, dataset_format, source.class_name, 32, 1.2, split, progress=False)
    assert crops.shape == (2, 32, 32, 3) and crops.dtype == np.uint8
    for K, T in zip(Ks, poses):
        uv = transform_and_project(vertices, T, K) + 0.5
        extent = np.concatenate([uv.min(axis=0), uv.max(axis=0)])
        side = max(extent[2] - extent[0], extent[3] - extent[1])
        assert abs(side - 32 / 1.2) < 1.5 and np.all(np.abs((extent[:2] + extent[2:]) / 2 - 16) < 1.5)
    views, mesh_path, scale = sample_object_views(root, dataset_format, split, "003_cracker_box", None, mesh,
                                                  input_size=32, progress=False)
    assert len(views) == 2 and mesh_path == source.mesh_path and scale == 1.0
    for mask, K, T in zip(views.masks, views.K, views.T_model2cam):
        uv = transform_and_project(vertices, T, K)
        rows, columns = np.nonzero(mask)
        box = np.array([columns.min(), rows.min(), columns.max() + 1, rows.max() + 1])
        np.testing.assert_allclose(np.concatenate([uv.min(axis=0), uv.max(axis=0)]) + 0.5, box, atol=1.5)


def test_train_commands_take_ycb_video_and_fat_data_sets(tmp_path, monkeypatch, capsys):
    import paz6d.aae.train
    import paz6d.keypointnet.command

    calls = []
    monkeypatch.setattr(paz6d.aae.train, "train_aae", lambda mesh, out, *args, **kwargs: calls.append(
        (mesh, args[1], kwargs)) or {"steps": 0})
    monkeypatch.setattr(paz6d.keypointnet.command, "train_keypointnet", lambda job, views=None: calls.append(
        (job, views)) or {"steps": 0})
    assert main(["train", "aae", "--dataset", str(YCB), "--object-class", "003_cracker_box", "--out",
                 str(tmp_path / "a"), "--no-progress"]) == 0
    mesh, scale, kwargs = calls.pop()
    assert mesh == YCB / "models/003_cracker_box/textured.obj" and scale == 1.0
    assert kwargs["dataset_format"] == "ycb_video" and kwargs["object_class"] == "003_cracker_box"
    assert kwargs["split"] == "train"
    assert main(["train", "aae", "--dataset", str(FAT), "--format", "fat", "--split", "single", "--dataset-mesh",
                 str(FAT_MESH), "--out", str(tmp_path / "b"), "--no-progress"]) == 0
    mesh, scale, kwargs = calls.pop()
    assert mesh == FAT_MESH and kwargs["object_class"] == "003_cracker_box_16k" and kwargs["split"] == "single"
    assert main(["train", "keypointnet", "--dataset", str(FAT), "--object-class", "003_cracker_box",
                 "--dataset-mesh", str(FAT_MESH), "--out", str(tmp_path / "k"), "--no-progress"]) == 0
    job, views = calls.pop()
    assert job.mesh == FAT_MESH and job.dataset is None and job.mesh_scale == 1.0 and len(views) == 2
    capsys.readouterr()
    failures = [(["train", "aae", "--dataset", str(FAT), "--object-class", "003_cracker_box"], "--dataset-mesh: FAT"),
                (["train", "keypointnet", "--dataset", str(YCB), "--object-class", "nope"], "--object-class: no class"),
                (["train", "aae", "--dataset", str(YCB), "--object-id", "3", "--object-class", "x"], "--object-class"),
                (["train", "aae", "--dataset", str(YCB), "--split", "nope"], "--split: "),
                (["train", "keypointnet", "--mesh", str(FAT_MESH), "--format", "fat"], "--format: only with --dataset"),
                (["train", "aae", "--dataset", str(FAT), "--object-id", "1"], "--object-id: FAT classes have no ids")]
    for argv, expected in failures:
        assert main(argv + ["--out", str(tmp_path / "x"), "--no-progress"]) == 2
        assert expected in capsys.readouterr().err, argv
    assert not calls


def test_tiny_aae_training_on_ycb_video_crops(tmp_path):
    from paz6d.aae.config import QUICK, Augmentation
    from paz6d.aae.train import train_aae

    toy = replace(QUICK, crop_size=16, latent_size=8, filters=(8,), kernel_size=3, render_size=24, views=6,
                  in_plane=2, steps=3, batch_size=4, checkpoint_every=3, sample_every=3, log_every=1,
                  augmentation=Augmentation(occlusion_probability=0.0))
    mesh = YCB / "models/003_cracker_box/textured.obj"
    summary = train_aae(mesh, tmp_path / "run", toy, 1.0, workers=0, progress=False, dataset=YCB, split="train",
                        dataset_format="ycb_video", object_class="003_cracker_box")
    pairs = np.load(tmp_path / "run" / "pairs.npz")
    assert summary["steps"] == 3 and summary["dataset_pairs"] == 2 and pairs["inputs"].shape == (2, 16, 16, 3)
    assert np.all(pairs["targets"].reshape(2, -1).max(axis=1) > 0)  # rendered targets show the object


@pytest.mark.slow  # ~12 s: the AAE run above keeps the default suite's check of the wiring
def test_tiny_keypointnet_training_on_fat_views(tmp_path):
    from paz6d.keypointnet.config import QUICK, KeypointTraining
    from paz6d.keypointnet.dataset import sample_object_views
    from paz6d.keypointnet.train import train_keypointnet

    tiny = QUICK.replace(num_keypoints=4, input_size=32, filters=8, downsample=2, dilations=(1,), views=4,
                         validation_views=2, lift_views=2, pairs=2, checkpoint_every=3, sample_every=3)
    views, mesh, scale = sample_object_views(FAT, "fat", "mixed", "003_cracker_box", mesh=FAT_MESH, input_size=32,
                                             progress=False)
    job = KeypointTraining(tmp_path / "run", mesh, mesh_scale=scale, workers=0, steps=3, progress=False,
                           settings=tiny)
    summary = train_keypointnet(job, views=views)
    assert summary["steps"] == 3 and (tmp_path / "run" / "model.keras").is_file()
