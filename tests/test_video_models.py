"""``paz6d run --detector RUN --run ID=RUN`` end to end with tiny untrained SSD and AAE runs: the JSON lines
hold the poses that ``DetectAndEstimatePose6D`` gives on the same frames as stills."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from paz6d import cli
from paz6d.backend.camera import Camera
from paz6d.backend.camera_file import write_camera_json
from paz6d.video.frames import open_frames
from paz6d.backend.image import save_image
from paz6d.video.video_file import VideoFileWriter
from paz6d.video.records import read_records

CLASS_NAMES = ["obj_000001", "obj_000002"]
K = np.array([[120.0, 0.0, 63.5], [0.0, 120.0, 47.5], [0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> tuple[Path, Path]:
    """An SSD run (light, 128 px, random weights, heads scaled so that it detects something) and an AAE run
    (16 px crops, random weights, a codebook of 40 random crops with their own rotations)."""
    from scipy.spatial.transform import Rotation

    from paz6d.aae import run_dir as aae_files
    from paz6d.aae.codebook import Codebook
    from paz6d.aae.run_dir import AAERunDir
    from paz6d.aae.model import build_autoencoder, encode_function, encoder_of
    from paz6d.backend.files import save_keras_model_atomically
    from paz6d.backend.tensorflow_guard import import_keras
    from paz6d.ssd.model import build_ssd, save_ssd
    from paz6d.ssd.run_dir import SSDRunDir, write_detector

    import_keras().utils.set_random_seed(0)
    root = tmp_path_factory.mktemp("video_models")
    model, spec = build_ssd(len(CLASS_NAMES) + 1, "light", input_size=128, width=0.25)
    for weight in model.weights:
        if weight.path.startswith(("conf_", "loc_")) and weight.path.endswith("pointwise_kernel"):
            weight.assign(weight.numpy() * 1000)
    write_detector(root / "ssd", "light", CLASS_NAMES, spec.to_dict())
    save_ssd(model, SSDRunDir.model_path(root / "ssd"))
    aae = root / "aae"
    autoencoder = build_autoencoder(16, 8, filters=(8, 16))
    hull = np.array([[x, y, z] for x in (-0.025, 0.025) for y in (-0.02, 0.02) for z in (-0.015, 0.015)])
    AAERunDir.write_config(aae, {"crop_size": 16, "padding": 1.2, "latent_size": 8}, root / "obj_000001.ply", 1.0,
                           0, None)
    aae_files.write_object(aae, hull, hull * 0.9, 0.07, hull)
    crops = np.random.default_rng(1).uniform(0, 1, (40, 16, 16, 3)).astype(np.float32)
    codes = encode_function(encoder_of(autoencoder))(crops)
    codes /= np.linalg.norm(codes, axis=1, keepdims=True)
    Codebook(codes, Rotation.random(40, random_state=2).as_matrix(), np.tile([40.0, 40, 60, 60], (40, 1)),
             np.diag([100.0, 100.0, 1.0]), 0.5).save(aae_files.codebook_path(aae))
    save_keras_model_atomically(autoencoder, AAERunDir.model_path(aae))
    return root / "ssd", aae


def test_paz6d_run_detector_and_poses_equal_the_pipeline_on_stills(runs, tmp_path, capsys):
    from paz6d.detect_and_estimate import DetectAndEstimatePose6D

    ssd, aae = runs
    generator = np.random.default_rng(3)
    frames = [generator.integers(0, 256, (96, 128, 3), dtype=np.uint8) for _ in range(3)]
    with VideoFileWriter(tmp_path / "clip.mkv", 10.0, (128, 96)) as writer:  # lossless: the stills exactly
        for image in frames:
            writer.write(image)
    camera = write_camera_json(tmp_path / "camera.json", Camera(K, 128, 96))
    code = cli.main(["run", "--input", str(tmp_path / "clip.mkv"), "--camera", str(camera), "--detector", str(ssd),
                     "--run", f"1={aae}", "--score-threshold", "0.05", "--out", str(tmp_path / "out"),
                     "--no-progress"])
    assert code == 0, capsys.readouterr().err
    records = list(read_records(tmp_path / "out" / "frames.jsonl"))
    pipeline = DetectAndEstimatePose6D.from_run_dirs(ssd, {1: aae}, Camera(K, 128, 96), score_threshold=0.05)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # boxes of obj_000002, which has no pose model, are skipped as in the run
        stills = [pipeline(image) for image in frames]
    ran = [[(entry["box"], entry["pose"]) for entry in record.results] for record in records]
    assert [[box for box, _ in found] for found in ran] == [[box for box, _ in found] for found in stills]
    for found, expected in zip(ran, stills):  # poses equal but for the last bit of a float64 sum's order
        for (_, pose), (_, still) in zip(found, expected):
            assert (pose.class_name, pose.score) == (still.class_name, still.score)
            np.testing.assert_allclose(pose.quaternion, still.quaternion, rtol=0, atol=1e-12)
            np.testing.assert_allclose(pose.translation, still.translation, rtol=0, atol=1e-12)
    assert sum(len(found) for found in stills) > 0  # poses were estimated: the comparison is not vacuous
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert "bop_results" not in summary
    assert summary["frames"] == 3 and summary["pipeline"].endswith("poses of objects [1]")
    with open_frames(tmp_path / "out" / "annotated.mp4") as source:
        assert source.size == (128, 96) and len(list(source)) == 3


def test_paz6d_run_writes_a_bop_results_csv_with_image_ids_from_file_names(runs, tmp_path, capsys):
    from paz6d.datasets.bop import read_pose_results

    ssd, aae = runs
    generator = np.random.default_rng(4)
    folder = tmp_path / "rgb"
    for im_id in (3, 7):
        save_image(folder / f"{im_id:06d}.png", generator.integers(0, 256, (96, 128, 3), dtype=np.uint8))
    camera = write_camera_json(tmp_path / "camera.json", Camera(K, 128, 96))
    code = cli.main(["run", "--input", str(folder), "--camera", str(camera), "--detector", str(ssd), "--run",
                     f"1={aae}", "--score-threshold", "0.05", "--bop-scene-id", "2", "--out", str(tmp_path / "out"),
                     "--no-progress"])
    assert code == 0, capsys.readouterr().err
    records = list(read_records(tmp_path / "out" / "frames.jsonl"))
    poses = [(int(record.file[:6]), entry["box"].score, entry["pose"]) for record in records
             for entry in record.results]
    results = read_pose_results(tmp_path / "out" / "results.csv")
    assert len(poses) > 0 and json.loads((tmp_path / "out" / "summary.json").read_text())["bop_rows"] == len(poses)
    assert results.scene_ids.tolist() == [2] * len(poses) and results.obj_ids.tolist() == [1] * len(poses)
    assert results.im_ids.tolist() == [im_id for im_id, _, _ in poses] and set(results.im_ids) <= {3, 7}
    np.testing.assert_allclose(results.scores, [score for _, score, _ in poses])
    np.testing.assert_allclose(results.translations, [pose.translation for _, _, pose in poses], atol=1e-9)
    np.testing.assert_allclose(results.rotations, [pose.rotation_matrix for _, _, pose in poses], atol=1e-9)
