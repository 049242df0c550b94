"""The detect -> crop -> pose hierarchy: DetectAndEstimatePose6D with a detector and pose models trained for
seconds in this module, its drawing, and `paz6d estimate` with several runs and with `--detector`, through
`paz6d evaluate bop`.

Rendering happens in this process (``workers=0``), after TensorFlow is loaded through the RTLD_LOCAL guard.
"""

from __future__ import annotations

import csv
import json
import shutil
import warnings
from dataclasses import replace

import numpy as np
import pytest

from paz6d.backend.tensorflow_guard import import_tensorflow

import_tensorflow()  # before any renderer in this process

from paz6d.abstract import Box2D, Pose6D  # noqa: E402
from paz6d.backend.camera import Camera, project_points  # noqa: E402
from paz6d.aae.config import QUICK, Augmentation  # noqa: E402
from paz6d.ssd.config import QUICK as SSD_QUICK  # noqa: E402
from paz6d.cli import main  # noqa: E402

OBJECTS = (5, 8)
TOY = replace(QUICK, crop_size=16, latent_size=16, filters=(8, 16), kernel_size=3, render_size=40, views=24,
              in_plane=6, steps=20, batch_size=8, learning_rate=2e-3, bootstrap_fraction=0.25,
              checkpoint_every=20, sample_every=20, log_every=10, augmentation=Augmentation())
TINY_SSD = SSD_QUICK.replace(input_size=128, width=0.25, learning_rate=5e-3, warmup_steps=0, expand_probability=0.0,
                            checkpoint_every=30, sample_every=30)


@pytest.fixture(scope="module")
def world(tmp_path_factory, shared_data):
    """A 4-image generated BOP set of two LM-O objects (both in every image), an SSD trained on it for 30 steps
    and one toy AAE per object."""
    from data_gen.config import GenerationConfig
    from data_gen.generator import generate
    from paz6d.aae.train import train_aae
    from paz6d.ssd.config import SSDTraining
    from paz6d.ssd.train import train_ssd

    root = tmp_path_factory.mktemp("detect_and_estimate")
    models = shared_data / "bop_lmo" / "models"
    meshes = tuple(models / f"obj_{obj_id:06d}.ply" for obj_id in OBJECTS)
    generate(GenerationConfig(meshes=meshes, out=root / "set", num_images=4, width=160, height=120, mesh_scale=0.001,
                              split="test", objects_per_image=(2, 2), distractors=0, occluder_probability=0.0,
                              distance=(0.5, 0.7), seed=3), workers=1, show_progress=False)
    train_ssd(SSDTraining(dataset=root / "set", out=root / "ssd", split="test", steps=30, batch_size=4,
                          progress=False, settings=TINY_SSD))
    for obj_id, mesh in zip(OBJECTS, meshes):
        train_aae(mesh, root / f"aae_{obj_id}", TOY, mesh_scale=0.001, seed=obj_id, workers=0, progress=False)
    return root


def _samples(world):
    from paz6d.datasets.bop import BOPDataset

    return list(BOPDataset(world / "set", "test"))


class TruthDetector:
    """A detector returning the ground-truth visible boxes of one image (class names as SSD's)."""

    class_names = tuple(f"obj_{obj_id:06d}" for obj_id in OBJECTS)

    def __init__(self, sample, extra: tuple[Box2D, ...] = ()):
        self.boxes = [Box2D(x, y, x + w, y + h, 0.9, f"obj_{instance.obj_id:06d}")
                      for instance in sample.objects for x, y, w, h in [instance.info["bbox_visib"]]] + list(extra)

    def __call__(self, image):
        return list(self.boxes)


def test_pipeline_returns_one_pose_per_detected_object_in_metres_in_the_camera_frame(world):
    from paz6d.pipelines import DetectAndEstimatePose6D, ImplicitPose6D
    from paz6d.ssd.pipeline import DetectSingleShot

    sample = _samples(world)[0]
    estimators = {obj_id: ImplicitPose6D(world / f"aae_{obj_id}") for obj_id in OBJECTS}
    # the trained detector (30 steps: any boxes it finds get exactly one pose each)
    detector = DetectSingleShot(world / "ssd", score_threshold=0.0, max_detections=4)
    pipeline = DetectAndEstimatePose6D(detector, estimators, sample.camera)
    assert pipeline.names == ["check", "detect", "select", "estimate", "pair"]
    values = pipeline.run(sample.image)
    assert 1 <= len(values["detections"]) <= 4
    results = pipeline(sample.image)
    assert [box for box, _ in results] == values["boxes"] == values["detections"]
    assert all(isinstance(pose, Pose6D) and pose.class_name == box.class_name for box, pose in results)
    # with the ground-truth boxes as detections: each object's pose sits in its box at its distance (metres)
    truth = DetectAndEstimatePose6D(TruthDetector(sample), {f"obj_{obj_id:06d}": estimator for obj_id, estimator
                                                            in estimators.items()}, sample.camera.K)
    results = truth(sample.image)
    assert [box.class_name for box, _ in results] == [f"obj_{instance.obj_id:06d}" for instance in sample.objects]
    for (box, pose), instance in zip(results, sample.objects):
        true_depth = instance.T_model2cam[2, 3]
        assert 0.4 < true_depth < 0.9 and abs(pose.translation[2] / true_depth - 1) < 0.35
        u, v = project_points(pose.translation[None], sample.camera.K)[0]
        assert box.x_min - 2 <= u <= box.x_max + 2 and box.y_min - 2 <= v <= box.y_max + 2


def test_from_run_dirs_loads_the_detector_and_a_pose_model_per_object(world):
    from paz6d.pipelines import DetectAndEstimatePose6D, ImplicitPose6D

    sample = _samples(world)[0]
    runs = {obj_id: world / f"aae_{obj_id}" for obj_id in OBJECTS}
    for flip in (False, True):
        pipeline = DetectAndEstimatePose6D.from_run_dirs(world / "ssd", runs, sample.camera, score_threshold=0.0,
                                                         flip=flip)
        assert pipeline.names == ["check", "detect", "select", "estimate", "pair"]
        detector = pipeline.detector
        assert detector.flip is flip and detector.run_dir == world / "ssd"
        assert type(detector["predict"].processor).__name__ == ("PredictImageAndMirror" if flip else "PredictImage")
        estimators = pipeline.estimators
        assert sorted(estimators) == sorted(pipeline.meshes) == ["obj_000005", "obj_000008"]  # meshes: for draw()
        assert all(isinstance(estimator, ImplicitPose6D) for estimator in estimators.values())
        results = pipeline(sample.image)
        assert results and all(pose.class_name == box.class_name for box, pose in results)


def test_detected_class_without_pose_model_is_skipped_with_a_warning_or_refused_when_strict(world):
    from paz6d.detect_and_estimate import DetectAndEstimatePose6D, MissingPoseModelWarning
    from paz6d.pipelines import ImplicitPose6D

    sample = _samples(world)[0]
    only_5 = {5: ImplicitPose6D(world / "aae_5")}
    detector = TruthDetector(sample)
    with pytest.warns(MissingPoseModelWarning, match="class 'obj_000008' has no pose model"):
        results = DetectAndEstimatePose6D(detector, only_5, sample.camera)(sample.image)
    assert [box.class_name for box, _ in results] == ["obj_000005"]
    with pytest.raises(ValueError, match=r"class 'obj_000008' has no pose model .*strict=True"):
        DetectAndEstimatePose6D(detector, only_5, sample.camera, strict=True)(sample.image)
    # a pose model for a class the detector cannot output, and keys that are no class
    with pytest.raises(ValueError, match=r"classes \['obj_000009'\] are not among the detector's classes"):
        DetectAndEstimatePose6D(detector, {9: only_5[5]}, sample.camera)
    with pytest.raises(ValueError, match="expected positive BOP object ids"):
        DetectAndEstimatePose6D(detector, {0: only_5[5]})
    with pytest.raises(ValueError, match="at least one pose model"):
        DetectAndEstimatePose6D(detector, {})
    # a pose model failing on one box skips that box (warned), the other objects still get poses
    def failing(image, box, camera=None):
        raise ValueError("PnP: 2 usable keypoints")

    with pytest.warns(MissingPoseModelWarning, match="pose model of 'obj_000008' failed .*PnP"):
        results = DetectAndEstimatePose6D(detector, {5: only_5[5], 8: failing}, sample.camera)(sample.image)
    assert [box.class_name for box, _ in results] == ["obj_000005"]


def test_verify_multiplies_each_box_score_by_its_pose_score(world):
    from paz6d.detect_and_estimate import DetectAndEstimatePose6D, VerifyBoxes
    from paz6d.pipelines import ImplicitPose6D

    boxes = [Box2D(0, 0, 10, 10, score, "obj_000005") for score in (0.8, 0.8, 0.8, 0.5, 0.5)]
    poses = [Pose6D.from_rotation_matrix(np.eye(3), [0, 0, 1], score=score) for score in (0.5, -0.3, 1.7, 1.0)]
    verified = VerifyBoxes()(boxes, poses + [None])
    assert [round(box.score, 6) for box in verified] == [0.4, 0.0, 0.8, 0.5, 0.5]  # clipped to [0, 1]; None kept
    assert [box.to_array().tolist() for box in verified] == [box.to_array().tolist() for box in boxes]
    sample = _samples(world)[0]
    estimators = {obj_id: ImplicitPose6D(world / f"aae_{obj_id}") for obj_id in OBJECTS}
    plain = DetectAndEstimatePose6D(TruthDetector(sample), estimators, sample.camera)
    checked = DetectAndEstimatePose6D(TruthDetector(sample), estimators, sample.camera, verify=True)
    assert checked.names == ["check", "detect", "select", "estimate", "verify", "pair"]
    for (box, pose), (verified_box, verified_pose) in zip(plain(sample.image), checked(sample.image)):
        assert 0 < pose.score <= 1 and verified_box.score == pytest.approx(box.score * pose.score)
        np.testing.assert_allclose(verified_pose.translation, pose.translation)


def test_keep_top_per_class_keeps_each_class_best_boxes_in_their_order():
    from paz6d.detect_and_estimate import KeepTopPerClass

    boxes = [Box2D(i, 0, i + 5, 5, score, name) for i, (score, name) in enumerate(
        [(0.3, "a"), (0.9, "b"), (0.7, "a"), (0.7, "a"), (0.2, "b"), (0.8, "c")])]
    kept, left_out = KeepTopPerClass(1)(boxes)
    assert kept == [boxes[1], boxes[2], boxes[5]] and left_out == [boxes[0], boxes[3], boxes[4]]  # tie: earlier box
    kept, left_out = KeepTopPerClass(2)(boxes)
    assert kept == [boxes[1], boxes[2], boxes[3], boxes[4], boxes[5]] and left_out == [boxes[0]]
    assert KeepTopPerClass(3)([]) == ([], [])
    for bad in (0, -1, 1.5, True, "1"):
        with pytest.raises(ValueError, match="poses_per_class: expected a whole number >= 1"):
            KeepTopPerClass(bad)


def test_poses_per_class_estimates_only_each_class_best_detection(world):
    from paz6d.detect_and_estimate import DetectAndEstimatePose6D
    from paz6d.pipelines import ImplicitPose6D

    sample = _samples(world)[0]
    estimators = {obj_id: ImplicitPose6D(world / f"aae_{obj_id}") for obj_id in OBJECTS}
    truth = TruthDetector(sample)
    weaker = [Box2D(box.x_min + 3, box.y_min, box.x_max + 3, box.y_max, 0.5, box.class_name) for box in truth.boxes]
    detector = TruthDetector(sample, extra=tuple(weaker))  # each object twice, the shifted copy scoring lower
    calls = []

    def counted(estimator):
        def estimate(image, box, camera=None):
            calls.append(box)
            return estimator(image, box, camera=camera)
        return estimate

    counting = {obj_id: counted(estimator) for obj_id, estimator in estimators.items()}
    every = DetectAndEstimatePose6D(detector, estimators, sample.camera)(sample.image)
    pipeline = DetectAndEstimatePose6D(detector, counting, sample.camera, poses_per_class=1)
    assert pipeline.names == ["check", "detect", "select", "top", "estimate", "pair"]
    values = pipeline.run(sample.image)
    assert [box for box, _ in values["results"]] == truth.boxes == calls and values["left_out"] == weaker
    with pytest.raises(ValueError, match="verify: not with poses_per_class"):
        DetectAndEstimatePose6D(detector, counting, sample.camera, verify=True, poses_per_class=1)
    for (box, pose), (same_box, same_pose) in zip(values["results"], every):
        assert box == same_box and pose.class_name == same_pose.class_name
        np.testing.assert_allclose(pose.to_matrix(), same_pose.to_matrix())


def test_viewpoints_keep_the_aae_answers_within_the_camera_range_in_the_pipeline_and_the_command(world, tmp_path):
    from paz6d.backend.viewpoints import ViewpointRange
    from paz6d.detect_and_estimate import DetectAndEstimatePose6D
    from paz6d.datasets.bop import read_pose_results
    from paz6d.pipelines import ImplicitPose6D

    above = ViewpointRange((30, 90))
    every = ImplicitPose6D(world / "aae_5").codebook
    estimator = ImplicitPose6D(world / "aae_5", viewpoints=above)
    assert 0 < len(estimator.codebook) < len(every) and above.contains(estimator.codebook.rotations).all()
    assert not above.contains(every.rotations).all()
    with pytest.raises(ValueError, match=r"aae_5/codebook.npz: viewpoints: none of the codebook's \d+ views"):
        ImplicitPose6D(world / "aae_5", viewpoints=ViewpointRange((90, 90), 0))
    loaded = DetectAndEstimatePose6D.from_run_dirs(world / "ssd", {5: world / "aae_5"}, viewpoints=above)
    np.testing.assert_array_equal(loaded.estimators["obj_000005"].codebook.rotations, estimator.codebook.rotations)
    runs = [f"--run={obj_id}={world / f'aae_{obj_id}'}" for obj_id in OBJECTS]
    out = tmp_path / "above.csv"
    assert main(["estimate", *runs, "--dataset", str(world / "set"), "--out", str(out), "--box", "visib",
                 "--elevation-degrees", "30", "90", "--no-progress"]) == 0
    estimates = read_pose_results(out)
    assert len(estimates) >= 6
    # a pose R = ray_rotation(t) @ R_view sees its object along its codebook view: the object->camera ray in the
    # model frame is the view's direction, above 30 degrees (less the neighbour average's 15-degree radius)
    rays = -np.einsum("nji,nj->ni", estimates.rotations,
                      estimates.translations / np.linalg.norm(estimates.translations, axis=1, keepdims=True))
    assert np.degrees(np.arcsin(rays[:, 2])).min() >= 30 - 15


def test_image_that_does_not_match_the_camera_is_refused(world):
    from paz6d.detect_and_estimate import DetectAndEstimatePose6D

    sample = _samples(world)[0]
    pipeline = DetectAndEstimatePose6D(TruthDetector(sample), {5: lambda image, box, camera=None: None},
                                       Camera(sample.camera.K, 320, 240))
    with pytest.raises(ValueError, match=r"image: 160x120 pixels does not match the camera's 320x240"):
        pipeline(sample.image)
    with pytest.raises(ValueError, match=r"image: expected .*3"):
        pipeline(sample.image[..., 0], camera=sample.camera.K)
    with pytest.raises(ValueError, match="camera: none given"):
        DetectAndEstimatePose6D(TruthDetector(sample), {5: lambda *a, **k: None})(sample.image)


def test_overlay_draws_the_model_outline_where_the_projected_model_lies(world, shared_data):
    from paz6d.backend.draw import draw_model_outline, model_silhouette
    from paz6d.backend.mesh import load_mesh
    from paz6d.detect_and_estimate import DetectAndEstimatePose6D

    sample = _samples(world)[0]
    instance = sample.objects[0]
    mesh = load_mesh(shared_data / "bop_lmo" / "models" / f"obj_{instance.obj_id:06d}.ply", 0.001)
    K, T = sample.camera.K, instance.T_model2cam
    silhouette = model_silhouette(mesh.vertices, mesh.faces, T, K, 160, 120)
    # the projected silhouette agrees with the renderer's mask of the unoccluded object
    rendered = instance.mask if instance.mask is not None else instance.mask_visib
    assert (silhouette & rendered).sum() / (silhouette | rendered).sum() > 0.9
    blank = np.zeros((120, 160, 3), np.uint8)
    outline = draw_model_outline(blank, mesh.vertices, mesh.faces, T, K, (0, 255, 0))
    changed = outline.any(axis=-1)
    assert changed.sum() > 20 and not np.any(changed & ~silhouette)  # only on the silhouette
    interior = silhouette.copy()
    for axis in (0, 1):
        interior &= np.roll(silhouette, 1, axis) & np.roll(silhouette, -1, axis)
    assert not np.any(changed & interior)  # its contour, not its fill
    # the pipeline's overlay: outline (mesh given), box and axes, all in and around that object's box
    pose = Pose6D.from_matrix(T, f"obj_{instance.obj_id:06d}")
    box = Box2D(*[float(v) for v in (instance.info["bbox_obj"][0], instance.info["bbox_obj"][1],
                                     instance.info["bbox_obj"][0] + instance.info["bbox_obj"][2],
                                     instance.info["bbox_obj"][1] + instance.info["bbox_obj"][3])], 0.9,
                f"obj_{instance.obj_id:06d}")
    pipeline = DetectAndEstimatePose6D(TruthDetector(sample), {instance.obj_id: lambda *a, **k: pose}, sample.camera,
                                       meshes={instance.obj_id: (mesh.vertices, mesh.faces)})
    overlay = pipeline.draw(sample.image, [(box, pose)], axis_length=0.01)
    changed = np.any(overlay != sample.image, axis=-1)
    assert np.any(changed & silhouette)
    rows, cols = np.nonzero(changed)
    margin = 15  # the label above the box
    assert rows.min() >= box.y_min - margin and rows.max() <= box.y_max + 2
    assert not np.any(changed[:, :max(int(box.x_min) - 2, 0)])


# ------------------------------------------------------------------------------------------ paz6d estimate
def _evaluate(world, results, tmp_path, name):
    scores = tmp_path / f"{name}.json"
    assert main(["evaluate", "bop", "--dataset", str(world / "set"), "--results", str(results), "--metrics",
                 "mssd,mspd,add", "--out", str(scores), "--no-progress"]) == 0
    return json.loads(scores.read_text())


def test_estimate_with_several_runs_and_with_the_detector_through_evaluate_bop(world, tmp_path, capsys):
    from paz6d.datasets.bop import read_pose_results

    runs = [f"--run={obj_id}={world / f'aae_{obj_id}'}" for obj_id in OBJECTS]
    truth = tmp_path / "truth.csv"
    assert main(["estimate", *runs, "--dataset", str(world / "set"), "--out", str(truth), "--box", "visib",
                 "--method", "aae", "--no-progress"]) == 0
    estimates = read_pose_results(truth)
    visible = sum(instance.info["visib_fract"] >= 0.1 for sample in _samples(world) for instance in sample.objects)
    assert sorted(set(estimates.obj_ids.tolist())) == list(OBJECTS) and len(estimates) == visible >= 6
    with truth.open() as handle:
        rows = list(csv.DictReader(handle))
    times = {}
    for row in rows:  # one time per image, on every row of that image, in seconds
        times.setdefault(row["im_id"], set()).add(float(row["time"]))
    assert all(len(values) == 1 and 0 < next(iter(values)) < 30 for values in times.values())
    report = _evaluate(world, truth, tmp_path, "truth")
    assert sorted(report["per_object"]) == ["5", "8"] and 0 <= report["AR_MSSD"] <= 1
    # from detections: the COCO file beside --out, every image's detections, scored through evaluate bop
    detected = tmp_path / "det.csv"
    assert main(["estimate", "--detector", str(world / "ssd"), *runs, "--dataset", str(world / "set"),
                 "--out", str(detected), "--score-threshold", "0", "--targets-out", str(tmp_path / "targets.json"),
                 "--no-progress"]) == 0
    coco = json.loads((tmp_path / "det_detections.json").read_text())
    assert {entry["category_id"] for entry in coco} <= set(OBJECTS) and len(coco) >= 4
    assert all(len(entry["bbox"]) == 4 and 0 <= entry["score"] <= 1 for entry in coco)
    estimates = read_pose_results(detected)
    assert len(estimates) >= 4 and set(estimates.obj_ids.tolist()) <= set(OBJECTS)
    assert np.all((estimates.scores >= 0) & (estimates.scores <= 1))
    targets = json.loads((tmp_path / "targets.json").read_text())
    assert targets == json.loads((world / "set" / "test_targets_bop19.json").read_text())
    report = _evaluate(world, detected, tmp_path, "detected")
    assert 0 <= report["AR_MSPD"] <= 1 and 0 <= report["ADD(-S)_recall"] <= 1
    assert "detections ->" in capsys.readouterr().out
    # --verify: the same detections, each score times its pose's (the AAE's cosine similarity, at most 1)
    assert main(["estimate", "--detector", str(world / "ssd"), *runs, "--dataset", str(world / "set"),
                 "--out", str(tmp_path / "verified.csv"), "--score-threshold", "0", "--verify", "--no-progress"]) == 0
    verified = json.loads((tmp_path / "verified_detections.json").read_text())
    key = lambda entry: (entry["image_id"], entry["category_id"], tuple(entry["bbox"]))  # noqa: E731
    assert sorted(map(key, verified)) == sorted(map(key, coco))
    plain_scores = {key(entry): entry["score"] for entry in coco}
    assert all(entry["score"] <= plain_scores[key(entry)] + 1e-5 for entry in verified)
    assert any(entry["score"] < plain_scores[key(entry)] - 1e-3 for entry in verified)
    assert main(["estimate", *runs, "--dataset", str(world / "set"), "--out", str(tmp_path / "x.csv"),
                 "--verify"]) == 2
    assert "--verify: only with --detector" in capsys.readouterr().err
    # --flip: the detector also sees each mirror image; other boxes, the same classes
    assert main(["estimate", "--detector", str(world / "ssd"), *runs, "--dataset", str(world / "set"),
                 "--out", str(tmp_path / "flipped.csv"), "--score-threshold", "0", "--flip", "--no-progress"]) == 0
    flipped = json.loads((tmp_path / "flipped_detections.json").read_text())
    assert len(flipped) >= 4 and {entry["category_id"] for entry in flipped} <= set(OBJECTS)
    assert sorted(map(key, flipped)) != sorted(map(key, coco))
    assert main(["estimate", *runs, "--dataset", str(world / "set"), "--out", str(tmp_path / "x.csv"),
                 "--flip"]) == 2
    assert "--flip: only with --detector" in capsys.readouterr().err
    # --vote-iou: the same detections and scores, each box the score-weighted mean of its neighbours
    assert main(["estimate", "--detector", str(world / "ssd"), *runs, "--dataset", str(world / "set"),
                 "--out", str(tmp_path / "voted.csv"), "--score-threshold", "0", "--vote-iou", "0.3",
                 "--no-progress"]) == 0
    voted = json.loads((tmp_path / "voted_detections.json").read_text())
    ranked = lambda entries: sorted((e["image_id"], e["category_id"], round(e["score"], 4)) for e in entries)  # noqa: E731
    assert ranked(voted) == ranked(coco) and sorted(map(key, voted)) != sorted(map(key, coco))
    # --box-search: the same detections; the AAEs pick among shifted and scaled copies of each box
    assert main(["estimate", "--detector", str(world / "ssd"), *runs, "--dataset", str(world / "set"),
                 "--out", str(tmp_path / "searched.csv"), "--score-threshold", "0", "--box-search",
                 "--no-progress"]) == 0
    searched = json.loads((tmp_path / "searched_detections.json").read_text())
    assert sorted(map(key, searched)) == sorted(map(key, coco))
    plain, moved = read_pose_results(detected), read_pose_results(tmp_path / "searched.csv")
    assert len(moved) == len(plain) and not np.allclose(moved.translations, plain.translations)
    assert main(["estimate", *runs, "--dataset", str(world / "set"), "--out", str(tmp_path / "x.csv"),
                 "--box-search"]) == 2
    assert "--box-search: only with --detector" in capsys.readouterr().err
    # --poses-per-class 1: every detection in the JSON, a pose for each class's best detection per image only
    assert main(["estimate", "--detector", str(world / "ssd"), *runs, "--dataset", str(world / "set"),
                 "--out", str(tmp_path / "best.csv"), "--score-threshold", "0", "--poses-per-class", "1",
                 "--no-progress"]) == 0
    assert sorted(map(key, json.loads((tmp_path / "best_detections.json").read_text()))) == sorted(map(key, coco))
    best, every = read_pose_results(tmp_path / "best.csv"), read_pose_results(detected)
    pairs = list(zip(best.im_ids.tolist(), best.obj_ids.tolist()))
    assert len(set(pairs)) == len(pairs) == len(set(zip(every.im_ids.tolist(), every.obj_ids.tolist()))) < len(every)
    for row, (im_id, obj_id) in enumerate(pairs):
        same = np.flatnonzero((every.im_ids == im_id) & (every.obj_ids == obj_id))
        top = same[np.argmax(every.scores[same])]
        assert best.scores[row] == every.scores[top]
        np.testing.assert_allclose(best.translations[row], every.translations[top])
    for flags, message in ((["--poses-per-class", "1"], "--poses-per-class: only with --detector"),
                           (["--detector", str(world / "ssd"), "--poses-per-class", "0"],
                            "--poses-per-class: expected a whole number >= 1, got 0"),
                           (["--detector", str(world / "ssd"), "--poses-per-class", "1", "--verify"],
                            "--poses-per-class: not with --verify")):
        assert main(["estimate", *runs, "--dataset", str(world / "set"), "--out", str(tmp_path / "x.csv"),
                     *flags]) == 2
        assert message in capsys.readouterr().err
    # a bare run directory with --object-id still works (and its object is checked)
    assert main(["estimate", "--run", str(world / "aae_5"), "--object-id", "5", "--dataset", str(world / "set"),
                 "--out", str(tmp_path / "bare.csv"), "--no-progress"]) == 0
    assert set(read_pose_results(tmp_path / "bare.csv").obj_ids.tolist()) == {5}


def _rows_without_time(path) -> list[dict]:
    with path.open() as handle:
        return [{key: value for key, value in row.items() if key != "time"} for row in csv.DictReader(handle)]


def test_estimate_images_of_a_folder_gives_the_poses_of_the_split_with_the_detector(world, tmp_path, capsys):
    """The split's RGB files as a plain folder with its camera.json: the detections and poses of `--dataset`
    with the detector (scene 0, im_id each image's position), one JSON line per image and a summary."""
    from paz6d.datasets.bop import read_pose_results
    from paz6d.video.records import read_records

    runs = [f"--run={obj_id}={world / f'aae_{obj_id}'}" for obj_id in OBJECTS]
    flags = ["estimate", "--detector", str(world / "ssd"), *runs, "--score-threshold", "0", "--poses-per-class", "1",
             "--no-progress"]
    assert main([*flags, "--dataset", str(world / "set"), "--out", str(tmp_path / "split.csv")]) == 0
    photos, camera = tmp_path / "photos", world / "set" / "camera.json"
    shutil.copytree(world / "set" / "test" / "000000" / "rgb", photos)
    out = tmp_path / "photos.csv"
    capsys.readouterr()
    assert main([*flags, "--images", str(photos), "--camera", str(camera), "--out", str(out)]) == 0
    assert f"4 images of {photos}" in capsys.readouterr().out
    rows = _rows_without_time(out)
    assert rows == _rows_without_time(tmp_path / "split.csv") and len(rows) >= 4
    detections = json.loads((tmp_path / "photos_detections.json").read_text())
    assert detections == json.loads((tmp_path / "split_detections.json").read_text()) and len(detections) >= 4
    records = list(read_records(tmp_path / "photos_frames.jsonl"))
    assert [(record.frame, record.file) for record in records] == list(enumerate(sorted(
        path.name for path in photos.iterdir())))
    estimates = read_pose_results(out)
    for record in records:  # the records hold the rows of their image, box and pose
        mine = np.flatnonzero(estimates.im_ids == record.frame)
        assert len(record.results) == len(mine) and record.latency_ms > 0
        assert [entry["box"].class_name for entry in record.results] == [f"obj_{obj_id:06d}"
                                                                         for obj_id in estimates.obj_ids[mine]]
        np.testing.assert_allclose([entry["box"].score for entry in record.results], estimates.scores[mine],
                                   atol=1e-6)
        np.testing.assert_allclose([entry["pose"].translation for entry in record.results],
                                   estimates.translations[mine], atol=1e-6)
    summary = json.loads((tmp_path / "photos_summary.json").read_text())
    assert (summary["frames"], summary["estimates"], summary["undistorted"]) == (4, len(rows), False)
    assert summary["records_out"] == str(tmp_path / "photos_frames.jsonl") and summary["images"] == str(photos)
    # an image of another size than the camera's, after the first: refused naming it, nothing written
    from paz6d.backend.image import load_image, save_image

    save_image(photos / "000002.png", load_image(photos / "000002.png")[:60, :80])
    assert main([*flags, "--images", str(photos), "--camera", str(camera), "--out", str(tmp_path / "bad.csv")]) == 2
    assert "000002.png: frame 2 is 80x60 pixels, expected 160x120" in capsys.readouterr().err
    assert not list(tmp_path.glob("bad*"))


def test_estimate_skips_images_without_rgb_and_fails_clearly_when_nothing_is_estimated(world, tmp_path, capsys):
    dataset = tmp_path / "set"
    shutil.copytree(world / "set", dataset)
    rgb = sorted((dataset / "test" / "000000" / "rgb").iterdir())
    for path in rgb[1:]:
        path.unlink()
    run5 = f"5={world / 'aae_5'}"
    out = tmp_path / "one.csv"
    assert main(["estimate", "--detector", str(world / "ssd"), "--run", run5, "--dataset", str(dataset),
                 "--out", str(out), "--score-threshold", "0", "--no-progress"]) == 0
    assert "3 images without RGB skipped" in capsys.readouterr().out
    rgb[0].unlink()
    assert main(["estimate", "--detector", str(world / "ssd"), "--run", run5, "--dataset", str(dataset),
                 "--out", str(tmp_path / "none.csv"), "--no-progress"]) == 2
    assert "no image of split 'test' has an RGB file" in capsys.readouterr().err
    assert main(["estimate", "--run", run5, "--dataset", str(dataset), "--out", str(tmp_path / "none.csv"),
                 "--no-progress"]) == 2
    assert "no instance of objects [5] with an RGB image" in capsys.readouterr().err
    assert not (tmp_path / "none.csv").exists()


def test_estimate_scores_an_object_whose_pose_model_cannot_estimate_as_misses(world, tmp_path, capsys, monkeypatch):
    from paz6d import split_estimation as module
    from paz6d.backend.pnp import PnPError
    from paz6d.datasets.bop import read_pose_results

    real = module._estimator

    def estimator(run_dir, **options):  # as a KeypointNet run with 2 usable keypoints fails to load
        if run_dir.name == "aae_8":
            raise PnPError(f"{run_dir}/keypoints.json: only 2 usable keypoints, PnP needs at least 4")
        return real(run_dir, **options)

    monkeypatch.setattr(module, "_estimator", estimator)
    runs = [f"--run={obj_id}={world / f'aae_{obj_id}'}" for obj_id in OBJECTS]
    for name, flags in (("truth", ["--box", "visib"]), ("det", ["--detector", str(world / "ssd"), "--score-threshold",
                                                                "0"])):
        out, targets = tmp_path / f"{name}.csv", tmp_path / f"{name}_targets.json"
        with pytest.warns(UserWarning, match="object 8 is not estimated .*only 2 usable keypoints"):
            assert main(["estimate", *runs, *flags, "--dataset", str(world / "set"), "--out", str(out),
                         "--targets-out", str(targets), "--no-progress"]) == 0
        assert set(read_pose_results(out).obj_ids.tolist()) == {5}
        assert {entry["obj_id"] for entry in json.loads(targets.read_text())} == set(OBJECTS)  # 8 scores as misses
        assert "objects [8] not estimated (unusable pose model)" in capsys.readouterr().out
        report = _evaluate(world, out, tmp_path, name)
        assert report["per_object"]["8"]["AR_MSSD"] == 0
    assert main(["estimate", runs[1], "--dataset", str(world / "set"), "--out", str(tmp_path / "none.csv"),
                 "--no-progress"]) == 2
    assert "no pose model can estimate: " in capsys.readouterr().err and not (tmp_path / "none.csv").exists()


@pytest.mark.parametrize("flags, expected", [
    (["--run", "{world}/missing"], "--run: {world}/missing is not a directory"),
    (["--run", "5={world}/set"], "is not a run directory of any method"),
    (["--run", "5={world}/ssd"], "is an SSD detector run directory; give it as --detector"),
    (["--run", "0={world}/aae_5"], "expected a BOP object id"),
    (["--run", "8={world}/aae_5"], "was trained on object 5, not 8"),
    (["--run", "5={world}/aae_5", "--run", "{world}/aae_5"], "object 5 given twice"),
    (["--run", "5={world}/aae_5", "--method", "keypoints"], "is a aae run directory; use --method aae"),
    (["--run", "5={world}/aae_5", "--detector", "{world}/aae_8"], "--detector: .* is a aae run directory"),
    (["--run", "5={world}/aae_5", "--detector", "{world}/missing"], "--detector: .*missing is not a directory"),
    (["--run", "5={world}/aae_5", "--detections-out", "{tmp}/d.json"], "--detections-out: only with --detector"),
    (["--run", "5={world}/aae_5", "--elevation-degrees", "50", "10"], "--elevation-degrees: elevation_degrees: expec"),
    (["--run", "5={world}/aae_5", "--inplane-degrees", "200"], "--inplane-degrees: inplane_degrees: expected"),
    (["--run", "5={world}/corrupt"], "codebook.npz"),
    (["--run", "5={world}/aae_5", "--detector", "{world}/corrupt_ssd"], "detector.json"),
    (["--run", "5={world}/aae_5", "--detector", "{world}/ssd_only_8"], r"does not detect objects \[5\]"),
])
def test_estimate_refuses_bad_run_directories_before_reading_images(world, tmp_path, capsys, flags, expected):
    if not (world / "corrupt").exists():
        shutil.copytree(world / "aae_5", world / "corrupt")
        (world / "corrupt" / "codebook.npz").write_bytes(b"PK\x03\x04truncated")
        shutil.copytree(world / "ssd", world / "corrupt_ssd")
        (world / "corrupt_ssd" / "detector.json").write_text("{")
        shutil.copytree(world / "ssd", world / "ssd_only_8")
        detector = json.loads((world / "ssd" / "detector.json").read_text())
        (world / "ssd_only_8" / "detector.json").write_text(json.dumps({**detector, "class_names": ["obj_000008",
                                                                                                   "obj_000009"]}))
    fill = {"world": str(world), "tmp": str(tmp_path)}
    argv = ["estimate", *[flag.format(**fill) for flag in flags], "--dataset", str(world / "set"),
            "--out", str(tmp_path / "r.csv"), "--no-progress"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(argv) == 2
    import re

    assert re.search(expected.format(**fill), capsys.readouterr().err)
    assert not (tmp_path / "r.csv").exists()
