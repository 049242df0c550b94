"""KeypointNet data and training: rendered views, batch geometry, tiny training runs, resume, CLI, BOP views."""

import argparse
import csv
import json

import cv2
import numpy as np
import pytest

from paz6d.backend.camera import Camera, transform_and_project
from paz6d.backend.tensorflow_guard import import_tensorflow
from paz6d.keypointnet import views as kv
from paz6d.keypointnet.config import QUICK

import_tensorflow()  # the renderer shares this process with TensorFlow (workers=0)

TINY = QUICK.replace(num_keypoints=6, input_size=32, filters=8, downsample=2, dilations=(1, 2), views=24,
                     validation_views=8, lift_views=8, pairs=4, learning_rate=3e-3, checkpoint_every=20,
                     sample_every=20)
SMALL_CAMERA = Camera(np.array([[150.0, 0.0, 79.5], [0.0, 150.0, 59.5], [0.0, 0.0, 1.0]]), 160, 120)


@pytest.fixture(scope="module")
def mesh_path(tmp_path_factory):
    from paz6d.assets.demo_object import write_demo_object

    return write_demo_object(tmp_path_factory.mktemp("mesh"))  # millimetres, BOP style


@pytest.fixture(scope="module")
def views(mesh_path):
    return kv.render_views(mesh_path, 6, seed=3, sampling=kv.ViewSampling(input_size=32), mesh_scale=1e-3,
                           workers=0, progress=False)


def test_views_depend_on_seed_and_index_only(mesh_path, views):
    sampling = kv.ViewSampling(input_size=32)
    other_chunks = kv.render_views(mesh_path, 6, seed=3, sampling=sampling, mesh_scale=1e-3, workers=0, chunk=4,
                                   progress=False)
    np.testing.assert_array_equal(other_chunks.rgb, views.rgb)
    np.testing.assert_array_equal(other_chunks.T_model2cam, views.T_model2cam)
    prefix = kv.render_views(mesh_path, 3, seed=3, sampling=sampling, mesh_scale=1e-3, workers=0, progress=False)
    np.testing.assert_array_equal(prefix.rgb, views.rgb[:3])
    other_seed = kv.render_views(mesh_path, 2, seed=4, sampling=sampling, mesh_scale=1e-3, workers=0, progress=False)
    assert not np.array_equal(other_seed.T_model2cam, views.T_model2cam[:2])


@pytest.mark.slow
def test_spawn_workers_render_the_same_views(mesh_path, views):
    in_workers = kv.render_views(mesh_path, 6, seed=3, sampling=kv.ViewSampling(input_size=32), mesh_scale=1e-3,
                                 workers=2, chunk=2, progress=False)
    np.testing.assert_array_equal(in_workers.rgb, views.rgb)
    np.testing.assert_array_equal(in_workers.masks, views.masks)


def _silhouette_box_error(mask, vertices, T, K) -> float:
    rows, columns = np.nonzero(mask)
    projected = transform_and_project(vertices, T, K)
    box = np.array([columns.min(), rows.min(), columns.max() + 1, rows.max() + 1])
    return float(np.abs(np.concatenate([projected.min(0) + 0.5, projected.max(0) + 0.5]) - box).max())


def test_view_masks_and_jittered_batches_agree_with_their_intrinsics(mesh_path, views):
    from paz6d.backend.mesh import load_mesh

    vertices = np.asarray(load_mesh(mesh_path, 1e-3).vertices)
    for index in range(len(views)):
        assert _silhouette_box_error(views.masks[index], vertices, views.T_model2cam[index], views.K[index]) <= 1.0
    rng = np.random.default_rng(0)
    strong = kv.Augmentation(crop_scale=0.2, crop_shift=0.1)
    for index in range(len(views)):
        picture, mask, K = kv.augmented_view(views, index, rng, strong)
        assert picture.shape == (32, 32, 3) and picture.dtype == np.uint8
        if mask.any() and not (mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any()):
            assert _silhouette_box_error(mask, vertices, views.T_model2cam[index], K) <= 1.5
    batch = kv.training_batch(views, np.random.default_rng(1), pairs=3, downsample=2)
    assert batch["images"].shape == (6, 32, 32, 3) and batch["masks"].shape == (6, 16, 16)
    assert batch["K"].shape == (6, 3, 3) and batch["T_model2cam"].shape == (6, 4, 4)
    pairs_differ = [not np.array_equal(batch["T_model2cam"][i], batch["T_model2cam"][i + 3]) for i in range(3)]
    assert all(pairs_differ)  # a pair is two different views


def test_relighting_and_background_noise_change_only_their_part_of_a_crop(views):
    plain = kv.Augmentation(crop_scale=0.0, crop_shift=0.0, colour=False)
    opaque = views.alpha == 255
    noisy_views = 0
    for index in range(len(views)):
        base, _, _ = kv.augmented_view(views, index, np.random.default_rng([5, index]), plain)
        noisy, _, _ = kv.augmented_view(views, index, np.random.default_rng([5, index]),
                                        kv.Augmentation(0.0, 0.0, colour=False, background_noise=40.0))
        assert np.array_equal(noisy[opaque[index]], base[opaque[index]])  # the object is untouched
        clear = views.alpha[index] == 0
        noisy_views += int(not np.array_equal(noisy[clear], base[clear]))
        lit, _, _ = kv.augmented_view(views, index, np.random.default_rng([5, index]),
                                      kv.Augmentation(0.0, 0.0, colour=False, relight=0.6))
        assert not np.array_equal(lit[opaque[index]], base[opaque[index]])
    assert 0 < noisy_views < len(views)  # on about half of the crops


def test_photo_backgrounds_are_collages_of_the_bundled_photographs(views):
    from paz6d.synthesis.photo_backgrounds import photo_collage, sample_photographs

    size = views.rgb.shape[1]
    photographs = sample_photographs()
    chosen = 0
    for seed in range(12):
        index = seed % len(views)
        picture, _, _ = kv.augmented_view(views, index, np.random.default_rng([6, seed]),
                                          kv.Augmentation(crop_scale=0.0, crop_shift=0.0, colour=False, photos=0.5))
        replay = np.random.default_rng([6, seed])
        replay.uniform(), replay.uniform(size=2)  # the crop jitter's draws
        clear, opaque = views.alpha[index] == 0, views.alpha[index] == 255
        np.testing.assert_array_equal(picture[opaque], views.rgb[index][opaque])  # the object is untouched
        if replay.random() < 0.5:
            chosen += 1
            np.testing.assert_array_equal(picture[clear], photo_collage(replay, photographs, size, size)[clear])
    assert 0 < chosen < 12  # a photo collage on about half of the crops, the shapes style on the others


def test_relight_gains_and_ramp_stay_in_their_bounds():
    from paz6d.synthesis.augment import relight

    image = np.full((20, 30, 3), 100, np.uint8)
    rng = np.random.default_rng(0)
    state = rng.bit_generator.state
    assert np.array_equal(relight(image, rng, 0.0), image.astype(np.float32)) and rng.bit_generator.state == state
    for seed in range(20):
        lit = relight(image, np.random.default_rng(seed), 0.6)
        assert lit.dtype == np.float32 and lit.shape == image.shape
        # gains within 1 +- 0.3, ramp within 1 +- 0.6 / 2 (half an image side from the centre)
        assert lit.min() >= 100 * 0.7 * 0.7 - 1e-3 and lit.max() <= 100 * 1.3 * 1.3 + 1e-3
        assert np.ptp(lit[..., 0]) > 0  # a ramp across the image


def test_view_lighting_styles_are_drawn_per_view_and_recorded(mesh_path, views):
    mixed = kv.ViewSampling(input_size=32, lighting=("key-fill", "surround"))
    assert kv.ViewSampling.from_dict(mixed.to_dict()).lighting == ("key-fill", "surround")
    old = kv.ViewSampling(input_size=32).to_dict()
    del old["lighting"]  # run directories written before the setting existed
    assert kv.ViewSampling.from_dict(old).lighting == ("key-fill",)
    relit = kv.render_views(mesh_path, 6, seed=3, sampling=mixed, mesh_scale=1e-3, workers=0, progress=False)
    assert np.array_equal(relit.T_model2cam, views.T_model2cam)  # same poses: the style is drawn after them
    assert all(not np.array_equal(relit.rgb[i], views.rgb[i]) for i in range(6))  # other lights
    assert np.array_equal(relit.masks, views.masks)
    with pytest.raises(ValueError, match="lighting: expected one or more of"):
        kv.ViewSampling(lighting=("studio",))


@pytest.mark.parametrize("field, value", [("photos", 1.5), ("photos", -0.1), ("photos", float("nan")),
                                          ("background_noise", -1.0), ("relight", float("nan"))])
def test_augmentation_refuses_bad_strengths(field, value):
    with pytest.raises(ValueError, match=f"^{field}: expected"):
        kv.Augmentation(**{field: value})
    with pytest.raises(ValueError, match=f"^augmentation.{field}: expected"):  # as read back from config.json
        QUICK.from_dict({"augmentation": {field: value}})


def test_an_unknown_augmentation_setting_is_named():
    assert kv.Augmentation.from_dict({"photos": 0.5}) == kv.Augmentation(photos=0.5)
    assert QUICK.from_dict({"augmentation": {}}).augmentation == kv.Augmentation()
    with pytest.raises(ValueError, match="^augmentation.photo: unknown setting; known: crop_scale, crop_shift"):
        QUICK.from_dict({"augmentation": {"photo": 0.5}})


def test_a_lighting_style_listed_twice_is_drawn_twice_as_often():
    rng = np.random.default_rng(0)
    styles = [kv._light_style(rng, ("key-fill", "key-fill", "surround")) for _ in range(3000)]
    assert styles.count("key-fill") / 3000 == pytest.approx(2 / 3, abs=0.03)
    state = rng.bit_generator.state
    assert kv._light_style(rng, ("scene",)) == "scene" and rng.bit_generator.state == state  # one style: no draw


def test_empty_masks_are_a_clear_error(views):
    masks = views.masks.copy()
    masks[2] = False
    with pytest.raises(ValueError, match=r"views \[2\] have empty masks"):
        kv.ViewSet(views.rgb, views.alpha, masks, views.K, views.T_model2cam)
    with pytest.raises(ValueError, match="ViewSet.K"):
        kv.ViewSet(views.rgb, views.alpha, views.masks, views.K[:2], views.T_model2cam)


def test_view_set_save_load_round_trip(views, tmp_path):
    path = views.save(tmp_path / "views.npz")
    loaded = kv.ViewSet.load(path)
    np.testing.assert_array_equal(loaded.rgb, views.rgb)
    np.testing.assert_array_equal(loaded.K, views.K)
    (tmp_path / "broken.npz").write_bytes(b"nope")
    with pytest.raises(ValueError, match="broken.npz"):
        kv.ViewSet.load(tmp_path / "broken.npz")


def test_downsample_masks_area_average():
    masks = np.zeros((1, 4, 4), bool)
    masks[0, :2, :1] = True
    np.testing.assert_allclose(kv.downsample_masks(masks, 2)[0], [[0.5, 0.0], [0.0, 0.0]])


def _losses(run_dir) -> list[float]:
    with (run_dir / "log.csv").open() as handle:
        return [float(row["loss"]) for row in csv.DictReader(handle)]


# discovery mode also trains in tests/test_keypointnet_discovery.py (tiny run from anchors)
@pytest.mark.parametrize("mode", ["supervised", pytest.param("discovery", marks=pytest.mark.slow)])
def test_tiny_training_lowers_the_loss_and_writes_a_loadable_run(mode, mesh_path, tmp_path):
    from paz6d.keypointnet.pipeline import KeypointPose6D
    from paz6d.keypointnet.config import KeypointTraining
    from paz6d.keypointnet.train import train_keypointnet

    job = KeypointTraining(tmp_path / mode, mesh_path, mesh_scale=1e-3, mode=mode, seed=0, workers=0, steps=40,
                           progress=False, settings=TINY)
    summary = train_keypointnet(job)
    losses = _losses(job.out)
    assert len(losses) == 4 and np.mean(losses[-2:]) < np.mean(losses[:2])
    for name in ("config.json", "model.keras", "keypoints.json", "metrics.json", "views_train.npz",
                 "views_lift.npz", "samples/step_00000040.png"):
        assert (job.out / name).exists(), name
    assert summary["steps"] == 40 and np.isfinite(summary["cross_view_px_median"])
    keypoints = json.loads((job.out / "keypoints.json").read_text())
    assert keypoints["method"] == "triangulated" and (keypoints["targets"] is not None) == (mode == "supervised")
    assert len(keypoints["points_model"]) == len(keypoints["usable"]) == 6
    if mode == "supervised":
        # 40 steps do not make usable lifted keypoints; with the targets the pipeline loads the run
        from paz6d.keypointnet.run_dir import write_keypoints

        write_keypoints(job.out, keypoints["targets"], np.ones(6, bool), "farthest-point")
        estimator = KeypointPose6D(job.out, SMALL_CAMERA.K, depth_from_box=True)
        image = np.random.default_rng(0).integers(0, 256, (120, 160, 3), dtype=np.uint8)
        assert len(estimator.detect(image, (60, 40, 100, 80))) == 6
        # resuming continues from the last checkpoint up to the new total (and lifts keypoints again)
        resumed = train_keypointnet(KeypointTraining(job.out, mesh_path, mesh_scale=1e-3, mode=mode, workers=0,
                                                     steps=50,
                                                     progress=False, settings=TINY))
        assert resumed["steps"] == 50 and len(_losses(job.out)) == 5


@pytest.mark.slow  # the backbone's weights and gradients through its frozen maps; the model test runs by default
def test_tiny_training_on_the_pretrained_body_lowers_the_loss_and_loads(mesh_path, tmp_path):
    from paz6d.keypointnet.config import KeypointTraining
    from paz6d.keypointnet.model import BACKBONE_LAYER, load_keypointnet
    from paz6d.keypointnet.train import train_keypointnet

    job = KeypointTraining(tmp_path / "lite0", mesh_path, mesh_scale=1e-3, seed=0, workers=0, steps=40,
                           progress=False, settings=TINY, backbone="efficientnet-lite0")
    train_keypointnet(job)
    losses = _losses(job.out)
    assert len(losses) == 4 and np.mean(losses[-2:]) < np.mean(losses[:2])
    assert json.loads((job.out / "config.json").read_text())["settings"]["backbone"] == "efficientnet-lite0"
    model = load_keypointnet(job.out / "model.keras")
    assert not model.get_layer(BACKBONE_LAYER).trainable_weights
    with pytest.raises(ValueError, match="backbone"):  # the body is fixed for a run: resuming with the own refused
        train_keypointnet(KeypointTraining(job.out, mesh_path, mesh_scale=1e-3, workers=0, steps=50, progress=False,
                                           settings=TINY))


@pytest.mark.slow  # the preset's photos and lights; the training loop itself runs in the tiny training tests
def test_the_robust_preset_trains_on_photos_and_mixed_lights(mesh_path, tmp_path, monkeypatch):
    from paz6d.keypointnet.config import ROBUST, KeypointTraining
    from paz6d.keypointnet.train import train_keypointnet

    collages = []
    real_collage = kv.photo_collage
    monkeypatch.setattr(kv, "photo_collage", lambda *args,
                        **kwargs: collages.append(1) or real_collage(*args, **kwargs))
    job = KeypointTraining(tmp_path, mesh_path, mesh_scale=1e-3, config="robust", seed=0, workers=0, steps=4,
                           progress=False, settings=TINY.replace(lighting=ROBUST.lighting,
                                                                 augmentation=ROBUST.augmentation))
    assert job.model_config.augmentation == kv.Augmentation(photos=0.5, background_noise=40.0)
    train_keypointnet(job)
    config = json.loads((tmp_path / "config.json").read_text())
    assert config["config"] == "robust" and config["sampling"]["lighting"] == ["key-fill", "key-fill", "surround"]
    assert config["settings"]["augmentation"] == ROBUST.augmentation.to_dict()
    crops = 4 * 2 * TINY.pairs  # steps x the two views of each pair
    assert 0.25 * crops < len(collages) < 0.75 * crops  # about half of the training crops over photo collages
    assert ROBUST.replace(steps=QUICK.steps, lighting=QUICK.lighting, augmentation=QUICK.augmentation) == QUICK


def test_lifting_crops_are_cut_as_at_inference_with_matching_intrinsics():
    from paz6d.backend.square_crop import square_window
    from paz6d.keypointnet.train import inference_crops

    T = np.eye(4)
    T[:3, 3] = [0.01, -0.005, 0.4]
    point = np.array([[0.012, 0.007, 0.0]])
    u, v = transform_and_project(point, T, SMALL_CAMERA.K)[0]
    image = np.zeros((120, 160, 3), np.uint8)
    image[int(round(v)) - 1:int(round(v)) + 2, int(round(u)) - 1:int(round(u)) + 2] = 255  # a 3x3 dot
    box = np.array([[u - 20.0, v - 15.0, u + 12.0, v + 9.0]])
    test = kv.TestImages(images=image[None], boxes=box, T_model2cam=T[None], masks=np.zeros((1, 120, 160), bool))
    crops, intrinsics, poses = inference_crops(test, SMALL_CAMERA.K, 1.25, 64)
    assert crops.shape == (1, 64, 64, 3) and intrinsics.shape == (1, 3, 3)
    np.testing.assert_array_equal(poses, T[None])
    weights = crops[0, ..., 0].astype(float)
    rows, columns = np.mgrid[:64, :64]
    centroid = np.array([(weights * columns).sum(), (weights * rows).sum()]) / weights.sum()
    expected = transform_and_project(point, T, intrinsics[0])[0]
    dot_centre = np.array([round(u), round(v)])  # the dot is drawn around the rounded pixel
    side = square_window(box[0], 1.25)[2]
    # bilinear resampling keeps the centroid to ~0.05 px; a half-pixel convention slip would move it 0.8 px
    np.testing.assert_allclose(centroid, expected + (dot_centre - [u, v]) * 64 / side, atol=0.15)


def test_a_run_directory_refuses_a_different_run(mesh_path, tmp_path):
    from paz6d.keypointnet.config import KeypointTraining
    from paz6d.keypointnet.train import _prepare_run_dir

    job = KeypointTraining(tmp_path, mesh_path, mesh_scale=1e-3, mode="supervised", settings=TINY)
    _prepare_run_dir(job, job.model_config, 0.1, kv.ViewSampling(input_size=32))
    other = KeypointTraining(tmp_path, mesh_path, mesh_scale=1e-3, mode="discovery", settings=TINY)
    with pytest.raises(ValueError, match="different run"):
        _prepare_run_dir(other, other.model_config, 0.1, kv.ViewSampling(input_size=32))
    longer = KeypointTraining(tmp_path, mesh_path, mesh_scale=1e-3, mode="supervised", steps=7, settings=TINY)
    assert _prepare_run_dir(longer, longer.model_config, 0.1, kv.ViewSampling(input_size=32))["settings"]["steps"] == 7
    edited = KeypointTraining(tmp_path, mesh_path, mesh_scale=1e-3, mode="supervised",
                              settings=TINY.replace(augmentation=kv.Augmentation(photos=0.5)))
    with pytest.raises(ValueError, match=r"settings changed since this run started \(augmentation=Augmentation\("):
        _prepare_run_dir(edited, edited.model_config, 0.1, kv.ViewSampling(input_size=32))
    # a config.json from before a setting existed reads back with the setting's default: the run resumes
    path = tmp_path / "config.json"
    written = json.loads(path.read_text())
    for key in ("augmentation", "lighting", "anchor_lifting", "discovery_weights"):
        del written["settings"][key]
    path.write_text(json.dumps(written))
    assert "augmentation" not in _prepare_run_dir(longer, longer.model_config, 0.1,
                                                  kv.ViewSampling(input_size=32))["settings"]
    with pytest.raises(ValueError, match="view sampling changed"):
        _prepare_run_dir(job, job.model_config, 0.1, kv.ViewSampling(input_size=32, lighting=("surround",)))
    with pytest.raises(ValueError, match="mode"):
        KeypointTraining(tmp_path, mesh_path, mode="other")
    with pytest.raises(ValueError, match="steps"):
        KeypointTraining(tmp_path, mesh_path, steps=0)
    with pytest.raises(ValueError, match="exactly one of mesh and dataset"):
        KeypointTraining(tmp_path)
    assert KeypointTraining(tmp_path, dataset=tmp_path).mesh_scale == 1e-3  # BOP meshes are millimetres


def test_cross_view_errors_are_zero_for_geometrically_consistent_keypoints():
    from paz6d.keypointnet.train import cross_view_errors

    rng = np.random.default_rng(0)
    points = rng.uniform(-0.05, 0.05, (5, 3))
    K = np.repeat(SMALL_CAMERA.K[None], 4, 0)
    poses = []
    for _ in range(4):
        T = np.eye(4)
        T[:3, :3] = cv2.Rodrigues(rng.normal(size=3))[0]
        T[:3, 3] = [0.0, 0.0, 0.5]
        poses.append(T)
    poses = np.stack(poses)
    uv = np.stack([transform_and_project(points, T, SMALL_CAMERA.K) for T in poses])
    depth = np.stack([(points @ T[:3, :3].T + T[:3, 3])[:, 2] for T in poses])
    np.testing.assert_allclose(cross_view_errors(uv, depth, K, poses), 0.0, atol=1e-9)
    uv[1, 0] += [3.0, 4.0]  # view 1 keypoint 0 off by 5 px: only pair (0, 1), keypoint 0 changes
    errors = cross_view_errors(uv, depth, K, poses)
    assert errors[0, 0] > 2.0 and np.allclose(errors[1], 0.0) and np.allclose(errors[0, 1:], 0.0)


def test_cli_arguments_and_clear_errors(tmp_path, capsys):
    from paz6d.cli import main
    from paz6d.keypointnet.command import configure

    parser = argparse.ArgumentParser()
    configure(parser)
    args = parser.parse_args(["--mesh", "m.ply", "--out", "run", "--mode", "discovery", "--steps", "5"])
    assert args.mode == "discovery" and args.steps == 5 and args.config == "quick"
    with pytest.raises(SystemExit):
        parser.parse_args(["--mesh", "m.ply", "--dataset", "d", "--out", "run"])
    assert main(["train", "keypointnet", "--mesh", str(tmp_path / "missing.ply"), "--out", str(tmp_path / "r")]) == 2
    assert "missing.ply" in capsys.readouterr().err
    assert main(["train", "keypointnet", "--dataset", str(tmp_path), "--out", str(tmp_path / "r")]) == 2
    assert "models_info.json" in capsys.readouterr().err


def test_backbone_flag_replaces_the_config_and_is_checked_against_its_strides():
    from paz6d.keypointnet.config import QUICK, KeypointConfig, KeypointTraining
    from paz6d.keypointnet.command import configure

    parser = argparse.ArgumentParser()
    configure(parser)
    args = parser.parse_args(["--mesh", "m.ply", "--out", "run", "--backbone", "efficientnet-lite0"])
    assert args.backbone == "efficientnet-lite0"
    settings = KeypointTraining(out="run", mesh="m.ply", backbone="efficientnet-lite0").model_config
    assert settings == QUICK.replace(backbone="efficientnet-lite0")
    assert KeypointTraining(out="run", mesh="m.ply").model_config.backbone == "none"
    with pytest.raises(SystemExit):
        parser.parse_args(["--mesh", "m.ply", "--out", "run", "--backbone", "resnet50"])
    with pytest.raises(ValueError, match="backbone: efficientnet-lite0 gives the maps of strides 2 to 8"):
        KeypointTraining(out="run", mesh="m.ply", config="full", backbone="efficientnet-lite0")  # stack at stride 2
    recorded = QUICK.to_dict()
    del recorded["backbone"]  # a run directory from before the setting: its own body
    assert KeypointConfig.from_dict(recorded).backbone == "none"


def _write_bop_set(root, mesh_path, count: int = 3):
    """A tiny BOP train split of the demo object rendered at 160x120 (millimetres in the files)."""
    from paz6d.backend.mesh import diameter, load_mesh
    from renderers import Renderer

    (root / "models").mkdir(parents=True)
    (root / "models" / "obj_000001.ply").write_bytes(mesh_path.read_bytes())
    mesh = load_mesh(mesh_path, 1e-3)
    (root / "models" / "models_info.json").write_text(json.dumps({"1": {"diameter": diameter(mesh.vertices) * 1e3}}))
    scene = root / "train" / "000000"
    (scene / "rgb").mkdir(parents=True)
    (scene / "mask_visib").mkdir()
    gt, cameras, poses = {}, {}, []
    sampling = kv.ViewSampling(input_size=32, camera=SMALL_CAMERA)
    vertices = np.asarray(mesh.vertices)
    with Renderer(160, 120) as renderer:
        for im_id in range(count):
            T = kv.sample_pose(np.random.default_rng(im_id), vertices, diameter(vertices), sampling)
            out = renderer.render(SMALL_CAMERA.K, [(mesh, T)])
            cv2.imwrite(str(scene / "rgb" / f"{im_id:06d}.png"), out.rgb[..., ::-1])
            mask = out.masks[0] if im_id != 1 else np.zeros_like(out.masks[0])  # image 1: empty mask, skipped
            cv2.imwrite(str(scene / "mask_visib" / f"{im_id:06d}_000000.png"), mask.astype(np.uint8) * 255)
            gt[str(im_id)] = [{"obj_id": 1, "cam_R_m2c": T[:3, :3].ravel().tolist(),
                               "cam_t_m2c": (T[:3, 3] * 1e3).tolist()}]
            cameras[str(im_id)] = {"cam_K": SMALL_CAMERA.K.ravel().tolist(), "depth_scale": 1.0}
            poses.append(T)
    (scene / "scene_gt.json").write_text(json.dumps(gt))
    (scene / "scene_camera.json").write_text(json.dumps(cameras))
    return np.stack(poses), vertices


def test_bop_object_views_crop_around_visible_instances(mesh_path, tmp_path):
    from paz6d.keypointnet.dataset import bop_object_views

    poses, vertices = _write_bop_set(tmp_path, mesh_path)
    views, found_mesh, scale = bop_object_views(tmp_path, input_size=32)
    assert len(views) == 2 and found_mesh.name == "obj_000001.ply" and scale == 1e-3
    np.testing.assert_allclose(views.T_model2cam, poses[[0, 2]], atol=1e-9)
    for index in range(2):
        assert _silhouette_box_error(views.masks[index], vertices, views.T_model2cam[index], views.K[index]) <= 1.0
    assert np.all(views.alpha == 255)  # real backgrounds are kept
    with pytest.raises(ValueError, match="no object id 7"):
        bop_object_views(tmp_path, object_id=7)
    with pytest.raises(ValueError, match="found 1 usable views"):
        bop_object_views(tmp_path, input_size=32, max_views=1)


@pytest.mark.slow  # the demo's keypoint path end to end; tests/test_demo.py runs the demo's default path
def test_keypoint_demo_trains_evaluates_and_reports(mesh_path, tmp_path, capsys):
    from paz6d.demo.keypoint_demo import run_keypoint_demo

    report = run_keypoint_demo(tmp_path, mesh_path, mesh_scale=1e-3, test_images=3, workers=0, steps=10,
                               progress=False, settings=TINY)
    result = report["modes"]["supervised"]
    for variant in ("pnp", "pnp_13_crops", "pnp_depth_from_box"):
        assert result[variant]["count"] == 3 and 0.0 <= result[variant]["recall_0.1d"] <= 1.0
        assert result[variant]["metric"] == "ADD"
        # 10 steps leave too few usable lifted keypoints: every image is a reported miss, not a crash
        assert result[variant]["error"] is None or result[variant]["failures"] == 3
    assert result["training"]["steps"] == 10
    for name in ("keypoint_report.json", "keypoint_recall.png", "keypointnet_supervised/evaluation.json"):
        assert (tmp_path / name).exists(), name
    assert json.loads((tmp_path / "keypoint_report.json").read_text())["test_images"] == 3
    printed = capsys.readouterr().out
    recall = 100 * result["pnp"]["recall_0.1d"]
    line = next(line for line in printed.splitlines() if line.split("  ")[1:2] == ["ADD recall @ 0.1 d, PnP"])
    assert line.endswith(f"{recall:.1f} %")  # the printed summary shows the report's number
    assert "keypoint_report.json" in printed
