"""AAE end to end at toy size: training lowers the loss and resumes, the run loads into ImplicitPose6D,
a rendering at a codebook rotation gives that exact rotation back, and bad inputs raise clear errors.

Rendering happens in this process (``workers=0``), after TensorFlow is loaded through the RTLD_LOCAL guard.
"""

from __future__ import annotations

import csv
import json
import shutil
from dataclasses import replace

import numpy as np
import pytest

from paz6d.backend.tensorflow_guard import import_tensorflow

import_tensorflow()  # before any renderer in this process

from paz6d.abstract import Box2D, Pose6D  # noqa: E402
from paz6d.assets.demo_object import write_demo_object  # noqa: E402
from paz6d.backend.camera import Camera  # noqa: E402
from paz6d.aae.config import QUICK, Augmentation  # noqa: E402
from paz6d.aae.train import train_aae  # noqa: E402

TOY = replace(QUICK, crop_size=16, latent_size=16, filters=(8, 16), kernel_size=3, render_size=40, views=24,
              in_plane=6, steps=40, batch_size=8, learning_rate=2e-3, bootstrap_fraction=0.25,
              checkpoint_every=20, sample_every=20, log_every=5,
              augmentation=Augmentation(occlusion_probability=0.3))


@pytest.fixture(scope="module")
def toy_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("aae")
    mesh = write_demo_object(root / "mesh")
    summary = train_aae(mesh, root / "run", TOY, mesh_scale=0.001, seed=3, workers=0, progress=False)
    return root, mesh, summary


def _losses(run_dir):
    with (run_dir / "log.csv").open() as handle:
        return [float(row["loss"]) for row in csv.DictReader(handle)]


def test_training_lowers_the_loss_and_writes_the_run(toy_run):
    root, _, summary = toy_run
    run = root / "run"
    losses = _losses(run)
    assert len(losses) == 8 and losses[-1] < 0.8 * losses[0]
    for name in ("config.json", "object.npz", "views.npz", "model.keras", "codebook.npz", "summary.json"):
        assert (run / name).is_file(), name
    assert sorted(p.name for p in (run / "samples").iterdir()) == ["step_00000020.png", "step_00000040.png"]
    assert summary["codebook_size"] == 24 * 6 and summary["steps"] == 40
    assert summary["loader_samples_per_second_one_thread"] > 0 and summary["model_samples_per_second"] > 0


def test_rerun_resumes_and_extends(toy_run):
    root, mesh, _ = toy_run
    run = root / "resumed"
    shutil.copytree(root / "run", run)
    summary = train_aae(mesh, run, replace(TOY, steps=50), mesh_scale=0.001, workers=0, progress=False)
    assert summary["resumed_from_step"] == 40 and summary["steps"] == 50
    assert len(_losses(run)) == 10
    assert json.loads((run / "config.json").read_text())["seed"] == 3  # the stored seed wins
    with pytest.raises(ValueError, match="trained on"):
        train_aae(mesh, run, TOY, mesh_scale=0.002, workers=0, progress=False)


def test_learning_rate_drop_trains_resumes_and_moves_to_the_new_end(toy_run):
    """The last ``lr_drop_steps`` updates run at the dropped rate; a run with the drop checkpoints and resumes."""
    from paz6d.aae.train import learning_rate_at

    assert [learning_rate_at(TOY, step) for step in (0, 39)] == [2e-3, 2e-3]
    dropped = replace(TOY, lr_drop_steps=10, lr_drop_factor=0.25)
    rates = [learning_rate_at(dropped, step) for step in range(40)]
    np.testing.assert_allclose(rates[:30], 2e-3)
    np.testing.assert_allclose(rates[30:], 5e-4)
    assert learning_rate_at(replace(TOY, lr_drop_steps=40), 0) == pytest.approx(2e-4)

    root, mesh, _ = toy_run
    run = root / "dropped"
    run.mkdir()
    for name in ("object.npz", "views.npz"):  # cached: no rendering
        shutil.copy(root / "run" / name, run / name)
    train_aae(mesh, run, replace(TOY, steps=20, lr_drop_steps=10), mesh_scale=0.001, workers=0, progress=False)
    rate = np.load(run / "checkpoints" / "step_00000020" / "optimizer.npz")["1"]  # Adam: iterations, rate, ...
    assert rate == pytest.approx(2e-4)  # the dropped rate was in use at the end
    summary = train_aae(mesh, run, replace(TOY, steps=30), mesh_scale=0.001, workers=0, progress=False)
    assert summary["resumed_from_step"] == 20 and summary["steps"] == 30
    stored = json.loads((run / "config.json").read_text())["config"]
    assert (stored["lr_drop_steps"], stored["steps"]) == (10, 30)  # the stored drop stays, at the new end


@pytest.mark.parametrize("changes, match", [({"lr_drop_steps": -1}, "lr_drop_steps"),
                                            ({"lr_drop_steps": 41}, r"lr_drop_steps.*0 to steps \(40\)"),
                                            ({"lr_drop_steps": 2.5}, "lr_drop_steps"),
                                            ({"lr_drop_factor": 0.0}, "lr_drop_factor"),
                                            ({"lr_drop_factor": 1.5}, "lr_drop_factor")])
def test_learning_rate_drop_settings_are_checked(changes, match):
    with pytest.raises(ValueError, match=match):
        replace(TOY, **changes)


def test_rendering_at_a_codebook_rotation_returns_that_rotation(toy_run):
    """Render with the codebook's own camera at in-plane angle 0: the crop equals the codebook crop."""
    from paz6d.aae.codebook import Codebook
    from paz6d.aae.pipeline import ImplicitPose6D
    from paz6d.backend.mesh import load_mesh
    from paz6d.aae.views import coverage_box
    from renderers import Renderer

    root, mesh_path, _ = toy_run
    run = root / "run"
    codebook = Codebook.load(run / "codebook.npz")
    estimator = ImplicitPose6D(run, codebook.render_K, neighbours=1)
    mesh = load_mesh(mesh_path, 0.001)
    with Renderer(TOY.render_size, TOY.render_size) as renderer:
        for view in (0, 5, 11, 23):
            index = view * TOY.in_plane  # in-plane angle 0
            T = np.eye(4)
            T[:3, :3] = codebook.rotations[index]
            T[2, 3] = codebook.render_distance
            output = renderer.render(codebook.render_K, [(mesh, T)], masks=False)
            box = tuple(coverage_box(output.alpha))
            indices, similarities = codebook.nearest(estimator.encode(estimator.crop(output.rgb, box)[None]))
            assert indices[0, 0] == index and similarities[0, 0] == pytest.approx(1.0, abs=1e-5)
            pose = estimator(output.rgb, box)
            # the pose adds only the ray correction for the sub-pixel offset of the mask box (< 0.2 deg)
            cosine = (np.trace(pose.rotation_matrix.T @ codebook.rotations[index]) - 1) / 2
            assert np.degrees(np.arccos(min(cosine, 1.0))) < 0.2
            # the mask box is within a pixel of the silhouette box: z within 3 %, x/y within half a pixel
            assert abs(pose.translation[2] / codebook.render_distance - 1) < 0.03
            half_pixel = 0.5 * codebook.render_distance / codebook.render_K[0, 0]
            assert np.all(np.abs(pose.translation[:2]) < half_pixel)


def test_in_plane_warp_matches_a_direct_rendering(toy_run):
    """The codebook's in-plane views come from image rotation; check it against rendering R_z @ R."""
    from paz6d.backend.mesh import load_mesh
    from paz6d.backend.viewpoints import in_plane_rotation
    from paz6d.aae.views import rotate_view
    from renderers import Renderer

    root, mesh_path, _ = toy_run
    views = np.load(root / "run" / "views.npz")
    mesh = load_mesh(mesh_path, 0.001)
    angle = 1.1
    with Renderer(TOY.render_size, TOY.render_size) as renderer:
        T = np.eye(4)
        T[:3, :3] = in_plane_rotation(angle) @ views["rotations"][7]
        T[2, 3] = float(views["distance"])
        direct = renderer.render(views["K"], [(mesh, T)], masks=False)
    _, warped_alpha = rotate_view(views["rgb"][7], views["alpha"][7], angle, views["K"])
    a, b = direct.alpha >= 128, warped_alpha >= 128
    assert (a & b).sum() / (a | b).sum() > 0.9  # resampling blurs a 40-px silhouette by about a pixel


def test_batch_api_matches_single_calls_and_accepts_box_types(toy_run):
    from paz6d.aae.pipeline import ImplicitPose6D

    root, _, _ = toy_run
    views = np.load(root / "run" / "views.npz")
    camera = Camera(views["K"], TOY.render_size, TOY.render_size)
    estimator = ImplicitPose6D(root / "run", camera)
    images = [views["rgb"][i] for i in (1, 2, 3)]
    boxes = [(8.0, 9.0, 30.0, 31.0), Box2D(6, 7, 33, 30), np.array([10.0, 5.0, 28.0, 35.0])]
    batch = estimator.estimate_batch(images, boxes)
    for image, box, pose in zip(images, boxes, batch):
        single = estimator(image, box)
        assert isinstance(single, Pose6D)
        np.testing.assert_allclose(single.to_matrix(), pose.to_matrix(), atol=1e-6)
    assert len(estimator.candidates(images[0], boxes[0], top_k=3)) == 3
    assert estimator.estimate_batch(images[0], []) == []


def test_box_variants_pick_the_crop_that_matches_the_codebook_best(toy_run):
    """``box_variants``: the pose equals the plain pose of the variant box with the highest cosine similarity
    (a brute-force search over the same boxes); a single unchanged variant gives the plain pose."""
    from paz6d.aae.pipeline import ImplicitPose6D
    from paz6d.processors.crops import BoxVariants

    root, _, _ = toy_run
    views = np.load(root / "run" / "views.npz")
    camera = Camera(views["K"], TOY.render_size, TOY.render_size)
    plain = ImplicitPose6D(root / "run", camera)
    variants = BoxVariants(shifts=(-0.1, 0.0, 0.1), scales=(0.9, 1.0, 1.1))
    searching = ImplicitPose6D(root / "run", camera, box_variants=variants)
    assert searching.names == ["vary", "crop", "encode", "lookup", "pick", "pose_from_codebook", "refine_with_depth"]
    images = [views["rgb"][i] for i in (2, 9, 17)]
    boxes = [(10.0, 8.0, 31.0, 33.0), (5.0, 6.0, 30.0, 28.0), (-4.0, 12.0, 20.0, 36.0)]  # the last at the border
    found = searching.estimate_batch(images, boxes)
    improved = 0
    for image, box, pose in zip(images, boxes, found):
        candidates = [variant for variant in variants(box) if variant[2] > 0]
        brute = max(plain.estimate_batch([image] * len(candidates), candidates), key=lambda p: p.score)
        np.testing.assert_allclose(pose.to_matrix(), brute.to_matrix(), atol=1e-5)
        assert pose.score == pytest.approx(brute.score, abs=1e-5)
        assert pose.score >= plain(image, box).score - 1e-6
        improved += pose.score > plain(image, box).score + 1e-6
        assert searching(image, box) == pose or np.allclose(searching(image, box).to_matrix(), pose.to_matrix(),
                                                            atol=1e-5)
    assert improved >= 1
    identity = ImplicitPose6D(root / "run", camera, box_variants=BoxVariants(shifts=(0.0,), scales=(1.0,)))
    np.testing.assert_allclose(identity(images[0], boxes[0]).to_matrix(), plain(images[0], boxes[0]).to_matrix(),
                               atol=1e-6)


def test_expand_boxes_and_pick_best_crop_keep_one_entry_per_box():
    from paz6d.aae.pipeline import ExpandBoxes, PickBestCrop
    from paz6d.processors.crops import BoxVariants

    image = np.zeros((20, 30, 3), np.uint8)
    expand = ExpandBoxes(BoxVariants(shifts=(-1.0, 0.0), scales=(1.0,)))
    images, boxes, cameras, depths, groups = expand([image, image], [np.array([0.0, 0, 10, 10]),
                                                                     np.array([15.0, 5, 25, 15])],
                                                    ["a", "b"], [None, None])
    # the first box's copies shifted by a whole side to the left or up leave the image: only it is kept
    assert groups.tolist() == [0, 1, 1, 1, 1] and cameras == ["a", "b", "b", "b", "b"] and len(images) == 5
    np.testing.assert_allclose(boxes[0], [0, 0, 10, 10])
    similarities = np.array([[0.5, 0.1], [0.3, 0.2], [0.9, 0.0], [0.9, 0.5], [0.1, 0.0]])
    indices = np.arange(10).reshape(5, 2)
    rotations = np.arange(5)[:, None, None] * np.ones((5, 3, 3))
    picked = PickBestCrop()(groups, indices, similarities, rotations, boxes, cameras, depths)
    assert picked[0].tolist() == [[0, 1], [4, 5]]  # the first of two equal best similarities wins
    np.testing.assert_allclose(picked[1], [[0.5, 0.1], [0.9, 0.0]])
    assert picked[2][:, 0, 0].tolist() == [0, 2] and picked[4] == ["a", "b"] and len(picked[3]) == 2


def test_bad_inputs_raise_clear_value_errors(toy_run, tmp_path):
    from paz6d.aae.pipeline import ImplicitPose6D

    root, _, _ = toy_run
    views = np.load(root / "run" / "views.npz")
    estimator = ImplicitPose6D(root / "run", Camera(views["K"], TOY.render_size, TOY.render_size))
    image = views["rgb"][0]
    with pytest.raises(ValueError, match="empty box"):
        estimator(image, (10, 10, 10, 20))
    with pytest.raises(ValueError, match="outside"):
        estimator(image, (50, 50, 60, 60))
    with pytest.raises(ValueError, match=r"image.*\(H, W, 3\)"):
        estimator(np.dstack([image, image[..., :1]]), (5, 5, 30, 30))
    with pytest.raises(ValueError, match=r"image.*\(H, W, 3\)"):
        estimator(image[..., 0], (5, 5, 30, 30))
    with pytest.raises(ValueError, match="uint8"):
        estimator(image.astype(np.float32), (5, 5, 30, 30))
    with pytest.raises(ValueError, match="camera"):
        estimator(np.zeros((20, 20, 3), np.uint8), (5, 5, 10, 10))
    with pytest.raises(ValueError, match="box"):
        estimator(image, (1, 2, 3))
    broken = tmp_path / "broken"
    shutil.copytree(root / "run", broken)
    (broken / "model.keras").write_bytes(b"corrupt")
    with pytest.raises(ValueError, match="model.keras"):
        ImplicitPose6D(broken, views["K"])
    with pytest.raises(ValueError, match="not a directory"):
        ImplicitPose6D(tmp_path / "nothing", views["K"])
    (broken / "config.json").unlink()
    with pytest.raises(ValueError, match="config.json"):
        ImplicitPose6D(broken, views["K"])


def test_icp_refinement_with_depth_recovers_the_pose(toy_run):
    from paz6d.backend.mesh import load_mesh
    from paz6d.aae.pipeline import ImplicitPose6D
    from paz6d.aae.views import coverage_box
    from renderers import Renderer
    from scipy.spatial.transform import Rotation

    root, mesh_path, _ = toy_run
    K = np.array([[300.0, 0, 79.5], [0, 300.0, 59.5], [0, 0, 1]])
    estimator = ImplicitPose6D(root / "run", K)
    T_true = np.eye(4)
    T_true[:3, :3] = Rotation.from_rotvec([0.4, -0.3, 1.0]).as_matrix()
    T_true[:3, 3] = [0.02, -0.01, 0.45]
    with Renderer(160, 120) as renderer:
        output = renderer.render(K, [(load_mesh(mesh_path, 0.001), T_true)])
    box = coverage_box(output.masks[0].astype(np.uint8) * 255)
    start = Pose6D.from_rotation_matrix(Rotation.from_rotvec([0.05, 0.03, -0.04]).as_matrix() @ T_true[:3, :3],
                                        T_true[:3, 3] + [0.004, -0.003, 0.01])
    refined = estimator.refine_with_depth([start], output.depth, box)
    angle = np.degrees(np.linalg.norm(Rotation.from_matrix(refined.rotation_matrix.T @ T_true[:3, :3]).as_rotvec()))
    assert angle < 1.5 and np.linalg.norm(refined.translation - T_true[:3, 3]) < 0.002
    full = estimator(output.rgb, box, depth=output.depth)  # whole path: codebook guess, then ICP
    assert isinstance(full, Pose6D)


def test_training_from_a_generated_data_set(toy_run, tmp_path):
    """--dataset: inputs are crops of the data set's images, targets clean renderings through the same
    crop windows; they line up with the data generator's own crops of the full masks."""
    from data_gen.config import GenerationConfig
    from data_gen.generator import generate
    from paz6d.backend.image import load_image
    from paz6d.aae.views import coverage_box

    root, mesh, _ = toy_run
    data = tmp_path / "data"
    generate(GenerationConfig(meshes=(mesh,), out=data, num_images=3, seed=5, mesh_scale=0.001,
                              objects_per_image=(1, 1),
                              crop_size=TOY.crop_size), workers=1, show_progress=False)
    summary = train_aae(mesh, tmp_path / "run", replace(TOY, steps=10), mesh_scale=0.001, workers=0, progress=False,
                        dataset=data, object_id=1)
    pairs = np.load(tmp_path / "run" / "pairs.npz")
    assert summary["dataset_pairs"] == len(pairs["inputs"]) >= 1
    scene = next(data.glob("train/*"))
    crops = json.loads((scene / "crops.json").read_text())
    kept = [(int(key), entry) for key, entries in sorted(crops.items(), key=lambda item: int(item[0]))
            for entry in entries if entry["visib_fract"] >= 0.1]
    assert len(kept) == len(pairs["inputs"])
    for index, (im_id, entry) in enumerate(kept):
        name = f"{im_id:06d}_{entry['inst_id']:06d}.png"
        np.testing.assert_array_equal(pairs["inputs"][index], load_image(scene / "crop_rgb" / name))  # data_gen's crop
        mask = load_image(scene / "crop_mask" / name, grayscale=True)
        target_mask = (pairs["targets"][index].max(axis=-1) > 0).astype(np.uint8) * 255
        # the target sits on the object
        np.testing.assert_allclose(coverage_box(target_mask), coverage_box(mask), atol=1.0)
    with pytest.raises(ValueError, match="--dataset"):
        train_aae(mesh, tmp_path / "run", TOY, mesh_scale=0.001, workers=0, progress=False)


def test_estimate_command_writes_bop_results_that_evaluate_scores(toy_run, tmp_path, capsys):
    """`paz6d estimate` on a small generated BOP set -> results CSV -> `paz6d evaluate bop`."""
    from data_gen.config import GenerationConfig
    from data_gen.generator import generate
    from paz6d.cli import main
    from paz6d.datasets.bop import BOPDataset, read_pose_results

    root, mesh, _ = toy_run
    dataset = tmp_path / "set"
    generate(GenerationConfig(meshes=(mesh,), out=dataset, num_images=3, width=160, height=120, seed=5,
                              split="test", mesh_scale=0.001, objects_per_image=(1, 1), distractors=0,
                              occluder_probability=0.0), workers=1, show_progress=False)
    visible = [(sample.im_id, instance.T_model2cam) for sample in BOPDataset(dataset, "test")
               for instance in sample.objects if instance.info["visib_fract"] >= 0.1]
    targets = json.loads((dataset / "test_targets_bop19.json").read_text())
    assert sum(target["inst_count"] for target in targets) == len(visible)
    results = tmp_path / "results.csv"
    assert main(["estimate", "--run", str(root / "run"), "--dataset", str(dataset), "--object-id", "1",
                 "--out", str(results), "--targets-out", str(tmp_path / "targets.json")]) == 0
    assert json.loads((tmp_path / "targets.json").read_text()) == targets
    estimates = read_pose_results(results)
    assert sorted(estimates.im_ids.tolist()) == sorted(im_id for im_id, _ in visible)
    assert np.all(estimates.obj_ids == 1) and np.all(estimates.scores == 1.0)
    scores = tmp_path / "scores.json"
    assert main(["evaluate", "bop", "--dataset", str(dataset), "--results", str(results), "--metrics",
                 "mssd,mspd,add", "--out", str(scores), "--no-progress"]) == 0
    report = json.loads(scores.read_text())
    assert 0.0 <= report["AR_MSSD"] <= 1.0 and 0.0 <= report["ADD(-S)_recall"] <= 1.0
    assert main(["estimate", "--run", str(root / "run"), "--dataset", str(dataset), "--object-id", "7",
                 "--out", str(tmp_path / "none.csv")]) == 2
    assert "was trained on object 1, not 7" in capsys.readouterr().err  # checked before any image is read
    assert not (tmp_path / "none.csv").exists()


def test_pipeline_steps_can_be_replaced_and_the_camera_given_per_call(toy_run):
    from paz6d.abstract import KeyedStep
    from paz6d.aae.pipeline import ImplicitPose6D, PosesFromCodebook

    root, _, _ = toy_run
    views = np.load(root / "run" / "views.npz")
    camera = Camera(views["K"], TOY.render_size, TOY.render_size)
    image, box = views["rgb"][3], (8.0, 9.0, 30.0, 31.0)
    estimator = ImplicitPose6D(root / "run", camera)
    assert estimator.names == ["crop", "encode", "lookup", "pose_from_codebook", "refine_with_depth"]
    reference = estimator(image, box)
    # the camera given per call wins over the constructor's; a K takes the image's size
    assert ImplicitPose6D(root / "run")(image, box, camera=views["K"]) == reference
    wider = Camera(views["K"] * [[0.8], [0.8], [1]], TOY.render_size, TOY.render_size)
    moved = estimator(image, box, camera=wider)
    assert moved.translation[2] < reference.translation[2]  # a shorter focal length: the same box is nearer
    # a batch of two goes through other float32 kernels than one image: scores may differ in the last bits
    for batched, single in zip(estimator.estimate_batch([image, image], [box, box], [None, wider]), [reference, moved]):
        np.testing.assert_allclose(batched.quaternion, single.quaternion, atol=1e-6)
        np.testing.assert_allclose(batched.translation, single.translation, atol=1e-6)
        assert batched.score == pytest.approx(single.score, rel=1e-5)
    # without the depth-free refinement (a replaced pose step) the translation comes from the box alone
    old = estimator.replace("pose_from_codebook", KeyedStep(
        PosesFromCodebook(estimator.codebook, estimator.hull_points, refine=False),
        ("indices", "similarities", "rotations", "boxes", "cameras"), "candidates", "pose_from_codebook",
        per_sample=True))
    assert old.processor.refine
    unrefined = estimator(image, box)
    assert not np.allclose(unrefined.translation, reference.translation, atol=1e-6)
    # a step removed, then inserted back by name
    lookup = estimator.remove("lookup")
    with pytest.raises(ValueError, match=r"step 'pose_from_codebook': needs \['indices', 'similarities', "
                                         r"'rotations'\]"):
        estimator(image, box)
    estimator.insert("pose_from_codebook", lookup)
    assert estimator(image, box) == unrefined


def test_boxes_far_larger_than_the_image_are_rejected_at_once(toy_run):
    import time

    from paz6d.aae.pipeline import ImplicitPose6D

    root, _, _ = toy_run
    estimator = ImplicitPose6D(root / "run", np.array([[300.0, 0, 79.5], [0, 300.0, 59.5], [0, 0, 1]]))
    image = np.zeros((120, 160, 3), np.uint8)
    for box in ((-1e9, -1e9, 1e9, 1e9), (-1e5, -1e5, 1e5, 1e5)):
        started = time.perf_counter()
        with pytest.raises(ValueError, match="larger than 4 times the 160x120 image"):
            estimator(image, box)
        assert time.perf_counter() - started < 1.0  # was > 10 minutes (blur and resampling grew with the box)


def test_precision_is_resolved_once_recorded_and_kept_on_resume(toy_run, monkeypatch):
    """A new run records the resolved precision and builds its model with it; a resume keeps the stored one."""
    from paz6d.aae.config import AAEConfig, AAETraining
    from paz6d.aae.model import encoder_of, load_model
    from paz6d.training import precision

    monkeypatch.setattr(precision, "native_bfloat16", lambda: True)  # "auto" resolves to bfloat16 on a CPU
    expected = precision.resolve_precision("auto")
    root, mesh, _ = toy_run
    run = root / "precision"
    run.mkdir()
    for name in ("object.npz", "views.npz"):  # cached: no rendering
        shutil.copy(root / "run" / name, run / name)
    summary = train_aae(mesh, run, replace(TOY, steps=10, precision="auto"), mesh_scale=0.001, workers=0,
                        progress=False)
    stored = json.loads((run / "config.json").read_text())["config"]
    assert stored["precision"] == summary["precision"] == expected
    assert encoder_of(load_model(run / "model.keras")).get_layer("encoder_conv0").compute_dtype == expected
    summary = train_aae(mesh, run, replace(TOY, steps=15, precision="float32"), mesh_scale=0.001, workers=0,
                        progress=False)
    assert summary["precision"] == expected and summary["resumed_from_step"] == 10
    legacy = {key: value for key, value in json.loads(json.dumps(stored)).items() if key != "precision"}
    assert AAEConfig.from_dict(legacy).precision == "float32"  # runs from before the setting
    assert AAETraining(out=root / "x", mesh=mesh, precision="bfloat16").model_config.precision == "bfloat16"
    assert AAETraining(out=root / "x", mesh=mesh).model_config.precision == "auto"
    with pytest.raises(ValueError, match="AAEConfig.precision: expected 'auto'"):
        replace(TOY, precision="half")


def test_pretrained_encoder_trains_records_its_body_and_loads_as_a_pose_model(toy_run):
    """``encoder_backbone="efficientnet-lite0"``: the loss falls, config.json records the body (runs from before
    the setting read as ``"none"``), and the run answers as an ImplicitPose6D with its codebook."""
    from paz6d.aae.config import AAEConfig, AAETraining
    from paz6d.aae.model import encoder_of, load_model
    from paz6d.pipelines import ImplicitPose6D

    root, mesh, _ = toy_run
    run = root / "pretrained"
    run.mkdir()
    for name in ("object.npz", "views.npz"):  # cached: no rendering
        shutil.copy(root / "run" / name, run / name)
    summary = train_aae(mesh, run, replace(TOY, encoder_backbone="efficientnet-lite0"), mesh_scale=0.001, seed=3,
                        workers=0, progress=False)
    losses = _losses(run)
    assert summary["codebook_size"] == 24 * 6 and losses[-1] < 0.8 * losses[0]
    stored = json.loads((run / "config.json").read_text())["config"]
    assert stored["encoder_backbone"] == "efficientnet-lite0"
    assert encoder_of(load_model(run / "model.keras")).get_layer("encoder_backbone_stride16") is not None
    legacy = {key: value for key, value in stored.items() if key != "encoder_backbone"}
    assert AAEConfig.from_dict(legacy).encoder_backbone == "none"
    assert AAETraining(out=root / "x", mesh=mesh, encoder_backbone="efficientnet-lite0").model_config \
        .encoder_backbone == "efficientnet-lite0"
    assert AAETraining(out=root / "x", mesh=mesh).model_config.encoder_backbone == "none"
    with pytest.raises(ValueError, match="AAEConfig.encoder_backbone: expected one of"):
        replace(TOY, encoder_backbone="resnet50")
    views = np.load(run / "views.npz")
    estimator = ImplicitPose6D(run, Camera(views["K"], TOY.render_size, TOY.render_size))
    pose = estimator(views["rgb"][1], (8.0, 9.0, 30.0, 31.0))
    assert isinstance(pose, Pose6D) and np.isfinite(pose.to_matrix()).all()


def test_config_json_round_trip_and_unknown_fields_at_either_level_are_named():
    from dataclasses import asdict

    from paz6d.aae.config import AAEConfig

    stored = json.loads(json.dumps(asdict(QUICK)))  # as config.json holds it: lists, not tuples
    assert AAEConfig.from_dict(stored) == QUICK
    with pytest.raises(ValueError, match=r"AAE config: unknown field\(s\) \['colour'\]"):
        AAEConfig.from_dict({**stored, "colour": 1})
    with pytest.raises(ValueError, match=r"AAE config: augmentation: unknown field\(s\) \['blurr'\]"):
        AAEConfig.from_dict({**stored, "augmentation": {**stored["augmentation"], "blurr": 1.0}})


def test_visible_box_crops_keep_the_whole_object_targets(toy_run, tmp_path):
    """crop_box="visib": each input is the crop of the instance's visible-part box (what a detector sees),
    its target the same whole-object view as with "obj"; a run directory keeps its choice, and the other
    pose formats (no visible boxes) are refused."""
    from data_gen.config import GenerationConfig
    from data_gen.generator import generate
    from paz6d.aae.config import AAETraining
    from paz6d.aae.dataset import dataset_pairs
    from paz6d.aae.model import crop_object
    from paz6d.datasets.bop import BOPDataset

    root, mesh, _ = toy_run
    data = tmp_path / "data"
    generate(GenerationConfig(meshes=(mesh,), out=data, num_images=4, seed=7, mesh_scale=0.001,
                              objects_per_image=(3, 3), occluder_probability=1.0, occluders=2),
             workers=1, show_progress=False)
    whole, seen = (dataset_pairs(data, 1, mesh, 0.001, TOY.crop_size, TOY.padding, workers=0, progress=False,
                                 crop_box=box) for box in ("obj", "visib"))
    np.testing.assert_array_equal(seen.targets, whole.targets)
    np.testing.assert_array_equal(seen.T_model2cam, whole.T_model2cam)
    expected, hidden = [], []
    for sample in BOPDataset(data, split="train"):
        for instance in sample.objects:
            if instance.info["visib_fract"] >= 0.1:
                x, y, w, h = instance.info["bbox_visib"]
                expected.append(crop_object(sample.image, (x, y, x + w, y + h), TOY.crop_size, TOY.padding))
                hidden.append(instance.info["bbox_visib"] != instance.info["bbox_obj"])
    np.testing.assert_array_equal(seen.inputs, np.stack(expected))
    assert any(hidden)  # the set holds partly hidden instances, whose two crops differ
    differs = [not np.array_equal(a, b) for a, b in zip(seen.inputs, whole.inputs)]
    assert differs == hidden

    train_aae(mesh, tmp_path / "run", replace(TOY, steps=2), mesh_scale=0.001, workers=0, progress=False,
              dataset=data, object_id=1, crop_box="visib")
    assert json.loads((tmp_path / "run" / "config.json").read_text())["crop_box"] == "visib"
    with pytest.raises(ValueError, match="'visib' boxes; use another --out for --crop-box obj"):
        train_aae(mesh, tmp_path / "run", replace(TOY, steps=4), mesh_scale=0.001, workers=0, progress=False,
                  dataset=data, object_id=1)
    with pytest.raises(ValueError, match="crop_box: expected one of"):
        train_aae(mesh, tmp_path / "other", TOY, mesh_scale=0.001, workers=0, progress=False, dataset=data,
                  object_id=1, crop_box="whole")
    with pytest.raises(ValueError, match="crop_box: 'visib' needs a BOP --dataset"):  # before anything is written
        train_aae(mesh, tmp_path / "fat_run", TOY, mesh_scale=0.001, workers=0, progress=False, dataset=data,
                  dataset_format="fat", object_class="x", crop_box="visib")
    assert not (tmp_path / "fat_run").exists()
    with pytest.raises(ValueError, match="needs a BOP data set"):
        dataset_pairs(data, 1, mesh, 0.001, TOY.crop_size, TOY.padding, workers=0, progress=False,
                      dataset_format="fat", object_class="x", crop_box="visib")
    with pytest.raises(ValueError, match="crop_box: 'visib' needs a BOP --dataset"):
        AAETraining(out=tmp_path / "fat", dataset=data, format="fat", dataset_mesh=mesh, object_class="x",
                    crop_box="visib")
