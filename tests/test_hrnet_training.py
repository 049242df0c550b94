"""HRNet training and run directory: a tiny run lowers the loss and resumes, the pipeline maps keypoints back
to image pixels for a known box and plugs into PnP, corrupt run directories are clear errors, the CLI."""

import argparse
import csv
import json

import numpy as np
import pytest

from paz6d.backend.camera import Camera, transform_and_project
from paz6d.backend.square_crop import square_window, to_full_image
from paz6d.backend.tensorflow_guard import import_tensorflow
from paz6d.hrnet.config import QUICK, HRNetTraining
from paz6d.hrnet.heatmaps import gaussian_heatmaps
from paz6d.hrnet.run_dir import HRNetRunDir
from paz6d.run_dirs import is_run_dir

import_tensorflow()  # the renderer shares this process with TensorFlow (workers=0)

TINY = QUICK.replace(num_keypoints=5, input_size=32, stem_width=8, stem_blocks=0, widths=(8, 16), stage_modules=(1,),
                     blocks=1, precision="float32", views=16, validation_views=4, test_images=4, batch_size=8,
                     learning_rate=1e-2, checkpoint_every=20, sample_every=20)
SMALL_CAMERA = Camera(np.array([[150.0, 0.0, 79.5], [0.0, 150.0, 59.5], [0.0, 0.0, 1.0]]), 160, 120)


@pytest.fixture(scope="module")
def mesh_path(tmp_path_factory):
    from paz6d.assets.demo_object import write_demo_object

    return write_demo_object(tmp_path_factory.mktemp("mesh"))  # millimetres, BOP style


def _losses(run_dir) -> list[float]:
    with (run_dir / "log.csv").open() as handle:
        return [float(row["loss"]) for row in csv.DictReader(handle)]


@pytest.fixture(scope="module")
def trained(mesh_path, tmp_path_factory):
    from paz6d.hrnet.train import train_hrnet

    job = HRNetTraining(tmp_path_factory.mktemp("hrnet") / "run", mesh_path, mesh_scale=1e-3, seed=0, workers=0,
                        steps=40, progress=False, settings=TINY)
    return job, train_hrnet(job)


def test_tiny_training_lowers_the_loss_writes_a_scored_run_and_resumes(trained, mesh_path):
    from paz6d.hrnet.train import train_hrnet

    job, summary = trained
    losses = _losses(job.out)
    assert len(losses) == 4 and np.mean(losses[-2:]) < np.mean(losses[:2])
    for name in ("hrnet.json", "model.keras", "config.json", "metrics.json", "evaluation.json", "keypoints.png",
                 "pck.png", "views_train.npz", "crops_test.npz", "samples/step_00000040.png"):
        assert (job.out / name).exists(), name
    evaluation = json.loads((job.out / "evaluation.json").read_text())
    assert evaluation["held_out_crops"] == 4 and 0.0 <= evaluation["pck@0.05"] <= 1.0
    assert set(evaluation["decoders"]) == {"quadratic", "quarter", "soft_argmax", "argmax"}
    assert summary["steps"] == 40 and summary["pck@0.05"] == evaluation["pck@0.05"]
    description = HRNetRunDir.read_description(job.out)
    assert description["points_model"].shape == (5, 3) and description["domain"] == "log"
    # resuming continues from the last checkpoint up to the new total
    resumed = train_hrnet(HRNetTraining(job.out, mesh_path, mesh_scale=1e-3, workers=0, steps=50, progress=False,
                                        settings=TINY))
    assert resumed["steps"] == 50 and len(_losses(job.out)) == 5
    again = train_hrnet(HRNetTraining(job.out, mesh_path, mesh_scale=1e-3, workers=0, steps=50, progress=False,
                                      settings=TINY))  # finished: re-scored, the training record kept
    assert again["final_losses"] == resumed["final_losses"] and again["train_seconds"] == resumed["train_seconds"]
    with pytest.raises(ValueError, match="different network"):
        train_hrnet(HRNetTraining(job.out, mesh_path, mesh_scale=1e-3, workers=0, steps=50, progress=False,
                                  settings=TINY.replace(widths=(8, 12))))


def test_pipeline_maps_keypoints_back_to_image_pixels_for_a_known_box(trained):
    from paz6d.hrnet.pipeline import HRNetKeypoints2D

    job, _ = trained
    detector = HRNetKeypoints2D(job.out, decode="quadratic")  # exact for ideal Gaussians
    assert detector.names == ["crop", "predict", "decode", "to_image", "to_keypoints2d"]
    crop_uv = np.array([[5.3, 7.9], [20.2, 11.6], [14.0, 25.5], [9.7, 17.1], [26.4, 4.8]])
    fake = gaussian_heatmaps(crop_uv[None], 8, 8, 4, 1.0)  # what a perfect network would say
    detector["predict"].processor.function = lambda crops: np.repeat(np.log(fake), len(crops), axis=0)
    box = (40.0, 30.0, 80.0, 90.0)  # 40 x 60 pixels: window side 75 at (22, 22); crop 32 pixels
    image = np.zeros((120, 160, 3), np.uint8)
    keypoints = detector(image, box)
    window = square_window(box, 1.25)
    assert window == (22, 22, 75)  # centre (60, 60) - 37.5, rounded half to even
    expected = (crop_uv + 0.5) * 75 / 32 + np.array([22.0, 22.0]) - 0.5
    np.testing.assert_allclose(keypoints.points, expected, atol=1e-6)
    np.testing.assert_allclose(keypoints.points, to_full_image(crop_uv, window, 32), atol=1e-6)
    assert keypoints.scores.shape == (5,) and np.all(keypoints.scores > 0.5)
    batch = detector.detect_batch([image, image], [box, (10, 10, 42, 42)])
    assert len(batch) == 2 and np.allclose(batch[0].points, expected)
    with pytest.raises(ValueError, match="box2d"):
        detector(image, (500, 500, 600, 600))
    with pytest.raises(ValueError, match="images/boxes"):
        detector.detect_batch([image], [])


def test_pose_pipeline_recovers_a_known_pose_from_perfect_heatmaps(trained):
    from paz6d.hrnet.pipeline import HRNetPose6D

    job, _ = trained
    estimator = HRNetPose6D(job.out, SMALL_CAMERA.K, decode="quadratic")
    assert estimator.names[-2:] == ["solve_pnp", "refine_with_depth"]
    T = np.eye(4)
    T[:3, :3] = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]) @ np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = [0.01, -0.005, 0.45]
    points = estimator.points_model
    image_uv = transform_and_project(points, T, SMALL_CAMERA.K)
    box = np.concatenate([image_uv.min(0) - 5, image_uv.max(0) + 5])
    window = square_window(box, 1.25)
    crop_uv = (image_uv + 0.5) * 32 / window[2] - np.array(window[:2]) * 32 / window[2] - 0.5
    logits = np.log(gaussian_heatmaps(crop_uv[None], 8, 8, 4, 1.0) + 1e-300)
    estimator["predict"].processor.function = lambda crops: np.repeat(logits, len(crops), axis=0)
    pose = estimator(np.zeros((120, 160, 3), np.uint8), box)
    np.testing.assert_allclose(pose.to_matrix()[:3, 3], T[:3, 3], atol=2e-3)
    # a depth image reaches the ICP step (on the training mesh); one without data keeps the PnP pose
    assert estimator(np.zeros((120, 160, 3), np.uint8), box, depth=np.zeros((120, 160), np.float32)) == pose
    assert estimator["refine_with_depth"].processor.statistics["refinements"] == 1
    assert len(estimator.detect_batch([np.zeros((120, 160, 3), np.uint8)], [box])[0]) == 5


def test_corrupt_run_directories_are_clear_errors(trained, tmp_path):
    import shutil

    from paz6d.hrnet.pipeline import HRNetKeypoints2D

    job, _ = trained
    run = tmp_path / "run"
    run.mkdir()
    with pytest.raises(ValueError, match="hrnet.json: file not found"):
        HRNetKeypoints2D(run)
    with pytest.raises(ValueError, match="is not a directory"):
        HRNetKeypoints2D(tmp_path / "nothing")
    shutil.copy(job.out / "hrnet.json", run / "hrnet.json")
    with pytest.raises(ValueError, match="model.keras: file not found"):
        HRNetKeypoints2D(run)
    shutil.copy(job.out / "model.keras", run / "model.keras")
    assert len(HRNetKeypoints2D(run)(np.zeros((60, 60, 3), np.uint8), (10, 10, 40, 40))) == 5
    good = json.loads((job.out / "hrnet.json").read_text())
    cases = [({**good, "stride": 0}, "stride: expected a positive integer"),
             ({**good, "domain": "prob"}, "domain: expected one of"),
             ({**good, "points_model": [[0.0, 1.0]] * 5}, r"points_model \(metres\): expected shape \(\.\.\., 3\)"),
             ({**good, "points_model": good["points_model"][:4]}, "points_model: expected num_keypoints = 5 points"),
             ({**good, "points_model": [[0.0, 1.0, 1e400]] * 5}, r"points_model \(metres\).*finite"),
             ({**good, "points_model": "x"}, "points_model"),
             ({key: value for key, value in good.items() if key != "margin"}, r"missing field\(s\) \['margin'\]"),
             ({**good, "num_keypoints": 4, "points_model": good["points_model"][:4]}, "predicts 5 maps"),
             ([1, 2], "expected a JSON object")]
    for data, message in cases:
        (run / "hrnet.json").write_text(json.dumps(data))
        with pytest.raises(ValueError, match=message):
            HRNetKeypoints2D(run)
    (run / "hrnet.json").write_text("{not json")
    with pytest.raises(ValueError, match="hrnet.json: invalid JSON"):
        HRNetKeypoints2D(run)
    (run / "hrnet.json").write_text(json.dumps(good))
    (run / "model.keras").write_bytes(b"truncated")
    with pytest.raises(ValueError, match="model.keras: not a readable"):
        HRNetKeypoints2D(run)
    (run / "config.json").write_text(json.dumps({"seed": 0}))
    with pytest.raises(ValueError, match="config.json: missing field 'mesh_path'"):
        HRNetRunDir.read_config(run)
    assert is_run_dir(job.out, "hrnet") and not is_run_dir(tmp_path, "hrnet")


def test_settings_and_cli_errors(mesh_path, tmp_path, capsys):
    from paz6d.cli import main
    from paz6d.hrnet.command import configure

    parser = argparse.ArgumentParser()
    configure(parser)
    args = parser.parse_args(["--mesh", "m.ply", "--out", "run", "--steps", "5", "--config", "full"])
    assert args.steps == 5 and args.config == "full" and args.mesh_scale == 1.0
    with pytest.raises(ValueError, match="steps: expected a positive"):
        HRNetTraining(tmp_path, mesh_path, steps=0)
    with pytest.raises(ValueError, match="config: expected one of"):
        HRNetTraining(tmp_path, mesh_path, config="huge")
    with pytest.raises(ValueError, match="width: unknown setting; known: num_keypoints"):
        QUICK.from_dict({"width": 3})
    with pytest.raises(ValueError, match="loss: expected one of"):
        QUICK.replace(loss="l1")
    with pytest.raises(ValueError, match="input_size: expected a multiple of 16"):
        QUICK.replace(input_size=120)
    with pytest.raises(ValueError, match="batch_size: expected an even number"):
        QUICK.replace(batch_size=15)
    with pytest.raises(ValueError, match="settings: expected HRNetConfig settings"):
        HRNetTraining(tmp_path, mesh_path, settings={"loss": "mse"})
    assert HRNetTraining(tmp_path, mesh_path, settings=TINY, steps=7).model_config == TINY.replace(steps=7)
    with pytest.raises(ValueError, match="mesh_scale"):
        HRNetTraining(tmp_path, mesh_path, mesh_scale=-1.0)
    assert main(["train", "hrnet", "--mesh", str(tmp_path / "missing.ply"), "--out", str(tmp_path / "r")]) == 2
    assert "missing.ply" in capsys.readouterr().err


def test_pose_scores_from_exact_keypoints_are_perfect_and_wrong_ones_miss():
    from paz6d.hrnet.evaluate import score_poses, true_keypoints

    rng = np.random.default_rng(0)
    points = rng.uniform(-0.05, 0.05, (8, 3))
    poses = np.stack([np.eye(4)] * 3)
    poses[:, :3, 3] = [[0.0, 0.0, 0.5], [0.02, -0.01, 0.6], [-0.01, 0.0, 0.4]]
    K = np.repeat(np.array([[300.0, 0.0, 63.5], [0.0, 300.0, 63.5], [0.0, 0.0, 1.0]])[None], 3, axis=0)
    uv = true_keypoints(points, K, poses)
    scores = score_poses(uv, K, poses, points, points, diameter=0.1, input_size=128)
    assert scores["count"] == 3 and scores["failures"] == 0 and scores["add_recall_0.1d"] == 1.0
    assert scores["median_rotation_deg"] < 1e-3 and scores["median_translation_mm"] < 1e-3
    uv[1] = uv[1][::-1]  # keypoints in the wrong order: a wrong pose
    assert score_poses(uv, K, poses, points, points, 0.1, 128)["add_recall_0.1d"] == 2 / 3
