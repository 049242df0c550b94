"""Probabilistic keypoints: the Gaussian NLL against hand-computed values, the Cholesky head, the builder's
shapes and save/load round trip, a tiny training run, the covariance scale, the pipeline and the run directory."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from paz6d.probabilistic_keypoints.config import QUICK
from paz6d.probabilistic_keypoints import run_dir as run_files
from paz6d.probabilistic_keypoints.run_dir import ProbabilisticKeypointsRunDir
from paz6d.run_dirs import is_run_dir
from paz6d.probabilistic_keypoints.model import (CholeskyFromMaps, ProbabilisticKeypointsError,
                                                 build_probabilistic_keypointnet, covariance_from_cholesky,
                                                 gaussian_nll, gaussian_nll_terms, inverse_softplus, load_model,
                                                 save_model)

LOG_2PI = math.log(2 * math.pi)


def tiny_model(keypoints: int = 5):
    return build_probabilistic_keypointnet(keypoints, 32, 4, 4, (1,), context_stride=8)


def test_gaussian_nll_matches_hand_computed_values():
    # L = [[2, 0], [1, 3]], r = (2, 4): e1 = 1, e2 = (4 - 1) / 3 = 1 -> ½·2 + log 2 + log 3 + log 2π
    value = gaussian_nll_terms([[[0.0, 0.0]]], [[[[2.0, 0.0], [1.0, 3.0]]]], [[[2.0, 4.0]]])
    assert float(value[0, 0]) == pytest.approx(1.0 + math.log(6.0) + LOG_2PI, rel=1e-6)
    # identity covariance, r = (3, 4): ½·25 + 0 + log 2π
    value = gaussian_nll_terms([[[1.0, 1.0]]], [[np.eye(2)]], [[[4.0, 5.0]]])
    assert float(value[0, 0]) == pytest.approx(12.5 + LOG_2PI, rel=1e-6)
    # against the textbook formula ½ rᵀΣ⁻¹r + ½ log det Σ + log 2π for a correlated covariance
    L = np.array([[1.5, 0.0], [-0.7, 0.4]])
    sigma = L @ L.T
    r = np.array([0.3, -1.2])
    expected = 0.5 * r @ np.linalg.solve(sigma, r) + 0.5 * math.log(np.linalg.det(sigma)) + LOG_2PI
    assert float(gaussian_nll([[[0.0, 0.0]]], [[L]], [[r]])) == pytest.approx(expected, rel=1e-5)
    # weights: only the second keypoint counts
    terms = np.asarray(gaussian_nll_terms(np.zeros((1, 2, 2)), np.tile(np.eye(2), (1, 2, 1, 1)),
                                          [[[1.0, 0], [2.0, 0]]]))
    weighted = gaussian_nll(np.zeros((1, 2, 2)), np.tile(np.eye(2), (1, 2, 1, 1)), [[[1.0, 0], [2.0, 0]]], [[0.0, 1.0]])
    assert float(weighted) == pytest.approx(terms[0, 1], rel=1e-6)
    np.testing.assert_allclose(covariance_from_cholesky(L), sigma)


def test_cholesky_head_pools_under_the_maps_with_a_positive_diagonal():
    probabilities = np.zeros((1, 2, 2, 1), np.float32)
    probabilities[0, 0, 1, 0] = 1.0  # all mass on cell (0, 1)
    maps = np.zeros((1, 2, 2, 3), np.float32)
    maps[0, 0, 1] = [inverse_softplus(2.0), 0.5, -30.0]
    maps[0, 1, 1] = [100.0, 100.0, 100.0]  # no mass there: ignored
    cholesky = np.asarray(CholeskyFromMaps(min_sigma=0.05)([probabilities, maps]))
    np.testing.assert_allclose(cholesky[0, 0], [[2.05, 0.0], [0.5, 0.05]], atol=1e-5)
    assert inverse_softplus(3.0) == pytest.approx(math.log(math.expm1(3.0)))
    with pytest.raises(ValueError, match="min_sigma"):
        CholeskyFromMaps(min_sigma=-1.0)


def test_builder_shapes_initial_sigma_and_save_load_round_trip(tmp_path):
    model = tiny_model()
    images = np.random.default_rng(0).uniform(0, 255, (2, 32, 32, 3)).astype(np.float32)
    outputs = model(images)
    assert outputs["uv"].shape == (2, 5, 2) and outputs["cholesky"].shape == (2, 5, 2, 2)
    assert outputs["probabilities"].shape == (2, 8, 8, 5) and outputs["depth"].shape == (2, 5)
    diagonal = np.asarray(outputs["cholesky"])[..., [0, 1], [0, 1]]
    np.testing.assert_allclose(diagonal, 3.0, atol=0.05)  # INITIAL_SIGMA
    path = save_model(model, tmp_path / "model.keras")
    loaded = load_model(path)
    for key, value in model(images).items():
        np.testing.assert_array_equal(np.asarray(loaded(images)[key]), np.asarray(value))
    (tmp_path / "bad.keras").write_bytes(b"nope")
    with pytest.raises(ProbabilisticKeypointsError, match="bad.keras"):
        load_model(tmp_path / "bad.keras")
    with pytest.raises(ProbabilisticKeypointsError, match="initial_sigma"):
        build_probabilistic_keypointnet(4, 32, 4, 4, (1,), initial_sigma=0.0)


def test_tiny_training_lowers_the_loss(tmp_path):
    from paz6d.keypointnet.model import keras
    from paz6d.probabilistic_keypoints.train import _loss_function
    from paz6d.training.trainer import Trainer

    keras.utils.set_random_seed(0)
    model = tiny_model(4)
    generator = np.random.default_rng(1)
    points = np.array([[0.03, 0, 0], [0, 0.03, 0], [0, 0, 0.03], [-0.02, -0.02, 0.01]])
    K = np.tile(np.array([[60.0, 0, 15.5], [0, 60.0, 15.5], [0, 0, 1]], np.float32), (8, 1, 1))
    T = np.tile(np.eye(4, dtype=np.float32), (8, 1, 1))
    T[:, 2, 3] = 0.5
    T[:, :2, 3] = generator.uniform(-0.02, 0.02, (8, 2))
    images = generator.uniform(0, 255, (8, 32, 32, 3)).astype(np.float32)
    batch = {"images": images, "K": K, "T_model2cam": T}
    loss_fn = _loss_function(QUICK.replace(input_size=32, downsample=4, nll_weight=0.1), points, 0.1)
    Trainer(model, keras.optimizers.Adam(3e-3), loss_fn, lambda step: batch, tmp_path, 40, log_every=5,
            progress=False, tensorboard=False).fit()
    rows = (tmp_path / "log.csv").read_text().splitlines()
    header = rows[0].split(",")
    losses = [float(row.split(",")[header.index("loss")]) for row in rows[1:]]
    nll = [float(row.split(",")[header.index("nll")]) for row in rows[1:]]
    assert losses[-1] < 0.9 * losses[0], losses
    assert nll[-1] < nll[0], nll


def test_covariance_scale_and_occluders_are_seeded():
    from paz6d.probabilistic_keypoints.train import fit_covariance_scale, occlude, occluder

    generator = np.random.default_rng(2)
    means = generator.uniform(0, 100, (4000, 2))
    covariances = np.tile(np.array([[2.0, 0.5], [0.5, 1.0]]), (4000, 1, 1))
    truth = means + generator.normal(size=(4000, 2)) @ np.linalg.cholesky(4.0 * covariances[0]).T
    assert fit_covariance_scale(truth, means, covariances) == pytest.approx(4.0, rel=0.08)
    settings = QUICK.replace(test_occluders=3, occluder_size=(0.3, 0.7))
    images = np.full((3, 32, 32, 3), 128, np.uint8)
    first = occlude(images, occluder(settings, 1.0, 1.25), 0, 2)
    np.testing.assert_array_equal(first, occlude(images, occluder(settings, 1.0, 1.25), 0, 2))
    assert (first != 128).any(axis=(1, 2, 3)).all()
    np.testing.assert_array_equal(images, 128)  # inputs untouched


@pytest.fixture()
def tiny_run(tmp_path):
    """A run directory with an untrained tiny model and 5 keypoints."""
    run = tmp_path / "run"
    ProbabilisticKeypointsRunDir.write_config(run, {"input_size": 32, "margin": 1.25, "downsample": 4})
    save_model(tiny_model(5), run / ProbabilisticKeypointsRunDir.MODEL_FILE)
    points = np.array([[0.03, 0, 0], [0, 0.03, 0], [0, 0, 0.03], [-0.02, -0.02, 0.01], [0.02, -0.01, -0.02]])
    run_files.write_keypoints(run, points, 2.0)
    return run


def test_pipeline_steps_covariances_in_image_pixels_and_a_pose(tiny_run):
    from paz6d.abstract import Pose6D
    from paz6d.backend.pnp import PnPError
    from paz6d.probabilistic_keypoints.pipeline import ProbabilisticKeypointPose6D

    K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    estimator = ProbabilisticKeypointPose6D(tiny_run, K)
    assert estimator.names == ["crop", "predict", "gaussians", "to_image", "covariances_to_image", "to_keypoints2d",
                               "solve_pnp", "refine_with_depth"]
    image = np.random.default_rng(3).integers(0, 255, (480, 640, 3), dtype=np.uint8)
    box = (300.0, 200.0, 364.0, 264.0)  # 64 px: window 80 px, crop 32 px -> covariances x (80/32)^2
    keypoints, covariances = estimator.detect(image, box)
    assert keypoints.points.shape == (5, 2) and covariances.shape == (5, 2, 2)
    # untrained head: sigma 3 crop px, scale 2 -> variance 2 * 9 * 2.5^2 image px^2 on the diagonal
    np.testing.assert_allclose(covariances[:, [0, 1], [0, 1]], 2 * 9 * 2.5 ** 2, rtol=0.05)
    try:
        pose = estimator(image, box)
        assert isinstance(pose, Pose6D)
    except PnPError:  # an untrained network may give degenerate keypoints; the error is the documented one
        pass


def test_corrupt_run_directories_are_reported_by_file(tiny_run, tmp_path):
    assert ProbabilisticKeypointsRunDir.validate(tiny_run) == tiny_run
    assert is_run_dir(tiny_run, "probabilistic-keypoints")
    with pytest.raises(ValueError, match="is not a directory"):
        ProbabilisticKeypointsRunDir.validate(tmp_path / "absent")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="config.json: file not found"):
        ProbabilisticKeypointsRunDir.validate(tmp_path / "empty")
    path = tiny_run / run_files.KEYPOINTS_FILE
    for data, message in (({"points_model": [[0, 0, 0]]}, "missing field"),
                          ({"points_model": [[0, 0]] * 5, "covariance_scale": 1.0}, "points_model"),
                          ({"points_model": [[0, 0, 0]] * 5, "covariance_scale": -1.0}, "covariance_scale"),
                          ({"points_model": "abc", "covariance_scale": 1.0}, "points_model")):
        path.write_text(json.dumps(data))
        with pytest.raises(ValueError, match=message):
            ProbabilisticKeypointsRunDir.read_keypoints(tiny_run)
    path.write_text("{broken")
    with pytest.raises(ValueError, match="invalid JSON"):
        ProbabilisticKeypointsRunDir.validate(tiny_run)
    (tiny_run / ProbabilisticKeypointsRunDir.CONFIG_FILE).write_text(json.dumps({"input_size": 32, "margin": 1.25}))
    with pytest.raises(ValueError, match="downsample"):
        ProbabilisticKeypointsRunDir.read_config(tiny_run)
    with pytest.raises(ValueError, match="covariance_scale"):
        run_files.write_keypoints(tiny_run, np.zeros((5, 3)), float("nan"))


def test_command_line_errors_name_the_flag(tmp_path, capsys):
    from paz6d import cli

    assert cli.main(["train", "probabilistic-keypoints", "--mesh", "m.ply", "--out", str(tmp_path / "run"),
                     "--mesh-scale", "-1"]) == 2
    assert "--mesh-scale: expected a positive factor to metres, got -1.0" in capsys.readouterr().err
    assert cli.main(["train", "probabilistic-keypoints", "--mesh", "m.ply", "--out", str(tmp_path / "run"),
                     "--steps", "0"]) == 2
    assert "--steps" in capsys.readouterr().err


def test_settings_are_checked_where_made(tmp_path):
    from paz6d.probabilistic_keypoints.config import FULL, ProbabilisticTraining

    assert FULL.replace(views=2000, validation_views=200, test_images=200, lift_images=200, steps=2500) == QUICK
    job = ProbabilisticTraining(mesh=tmp_path / "m.ply", out=tmp_path / "run", config="full", steps=9)
    assert job.model_config == FULL.replace(steps=9)
    for changes, message in (({"lifting": "median"}, "lifting: expected one of"),
                             ({"train_occlusion": 1.5}, "train_occlusion: expected at most 1.0"),
                             ({"occluder_size": (0.7, 0.3)}, "occluder_size: expected values that do not decrease"),
                             ({"context_stride": 2}, r"context_stride: expected at least downsample \(4\)"),
                             ({"input_size": 100}, "input_size: expected a multiple of 8")):
        with pytest.raises(ValueError, match=message):
            QUICK.replace(**changes)


@pytest.mark.slow
def test_render_train_evaluate_and_estimate_end_to_end(tmp_path):
    """Renders a few views of the demo object, trains a tiny network, evaluates and runs the pipeline."""
    from paz6d.assets.demo_object import write_demo_object
    from paz6d.probabilistic_keypoints.config import ProbabilisticTraining
    from paz6d.probabilistic_keypoints.pipeline import ProbabilisticKeypointPose6D
    from paz6d.probabilistic_keypoints.train import train_probabilistic_keypoints

    mesh = write_demo_object(tmp_path / "mesh")
    out = tmp_path / "run"
    tiny = QUICK.replace(views=40, validation_views=16, test_images=8, lift_images=6, filters=8, input_size=64,
                         num_keypoints=6, dilations=(1, 2), pairs=2, checkpoint_every=10, sample_every=10,
                         precision="float32")
    job = ProbabilisticTraining(mesh=mesh, mesh_scale=0.001, out=out, steps=20, workers=1, progress=False,
                                settings=tiny)
    summary = train_probabilistic_keypoints(job)
    assert summary["steps"] == 20 and summary["covariance_scale"] > 0
    evaluation = json.loads((out / run_files.EVALUATION_FILE).read_text())
    for name in ("clean", "occluded"):
        assert evaluation[name]["pnp"]["count"] == 8 and evaluation[name]["weighted_pnp"]["count"] == 8
        assert 0.0 <= evaluation[name]["calibration_scaled"]["observed"]["1sigma"] <= 1.0
    assert (out / run_files.CALIBRATION_PNG).stat().st_size > 0 and (out / run_files.EXAMPLES_PNG).stat().st_size > 0
    saved = json.loads((out / run_files.KEYPOINTS_FILE).read_text())
    assert saved["method"] == "triangulate" and np.asarray(saved["targets"]).shape == (6, 3)
    estimator = ProbabilisticKeypointPose6D(out, np.array([[572.4, 0, 325.3], [0, 573.6, 242.0], [0, 0, 1]]))
    keypoints, covariances = estimator.detect(np.zeros((480, 640, 3), np.uint8), (300, 200, 360, 260))
    assert keypoints.points.shape == (6, 2) and np.all(np.linalg.eigvalsh(covariances) > 0)
    with pytest.raises(ValueError, match="different run"):
        train_probabilistic_keypoints(ProbabilisticTraining(mesh=mesh, mesh_scale=0.001, out=out, seed=1, steps=20,
                                                            workers=1, progress=False, settings=tiny))
