"""Spatial transformer: the bilinear sampler against OpenCV and a float64 numpy oracle, its gradients,
the builders, the run directory, the pipeline, the digits data and a tiny training run."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from paz6d.run_dirs import is_run_dir
from paz6d.stn import run_dir as run_files
from paz6d.stn.model import (IDENTITY, AffineFromParameters, BilinearSampler, STNModelError, affine_sample,
                             build_classifier, load_classifier, save_classifier, tf, theta_to_pixel_matrix)
from paz6d.stn.run_dir import STNRunDir


def numpy_sampler(image: np.ndarray, theta: np.ndarray, size: tuple[int, int], padding: str) -> np.ndarray:
    """Bilinear sampling of ``image (H, W)`` written out per pixel (float64 oracle)."""
    height, width = image.shape
    M = theta_to_pixel_matrix(theta, (height, width), size)
    out = np.zeros(size)
    for i in range(size[0]):
        for j in range(size[1]):
            x, y = M @ [j, i, 1.0]
            x0, y0 = int(np.floor(x)), int(np.floor(y))
            for column, weight_x in ((x0, 1 - (x - x0)), (x0 + 1, x - x0)):
                for row, weight_y in ((y0, 1 - (y - y0)), (y0 + 1, y - y0)):
                    if padding == "border":
                        row, column = min(max(row, 0), height - 1), min(max(column, 0), width - 1)
                    elif not (0 <= row < height and 0 <= column < width):
                        continue
                    out[i, j] += weight_x * weight_y * image[row, column]
    return out


@pytest.fixture(scope="module")
def image() -> np.ndarray:
    return np.random.default_rng(0).random((2, 20, 30, 3)).astype(np.float32)


def test_identity_returns_the_input(image):
    out = np.asarray(affine_sample(image, np.repeat(IDENTITY[None], 2, axis=0)))
    np.testing.assert_allclose(out, image, atol=1e-6)
    layer = BilinearSampler(padding="border")
    np.testing.assert_allclose(np.asarray(layer([image, np.repeat(IDENTITY[None], 2, axis=0)])), image, atol=1e-6)


@pytest.mark.parametrize("padding, border", [("zeros", cv2.BORDER_CONSTANT), ("border", cv2.BORDER_REPLICATE)])
def test_translation_matches_opencv_warp_affine(image, padding, border):
    # shifts of whole 1/32 pixels: OpenCV's fixed-point bilinear weights are then exact
    shift_x, shift_y = 2.25, -1.5  # input pixels
    theta = np.array([[1.0, 0.0, shift_x * 2 / 30], [0.0, 1.0, shift_y * 2 / 20]], np.float32)
    out = np.asarray(affine_sample(image, np.stack([theta, theta]), padding=padding))
    M = np.array([[1.0, 0.0, shift_x], [0.0, 1.0, shift_y]])
    np.testing.assert_allclose(theta_to_pixel_matrix(theta, (20, 30), (20, 30)), M, atol=1e-6)
    for index in range(2):
        expected = cv2.warpAffine(image[index], M, (30, 20), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                  borderMode=border, borderValue=0)
        np.testing.assert_allclose(out[index], expected, atol=1e-5)


@pytest.mark.parametrize("padding", ["zeros", "border"])
def test_general_affine_with_another_output_size_matches_the_oracle(image, padding):
    theta = np.array([[0.6, 0.25, 0.3], [-0.2, 0.7, -0.4]])
    out = np.asarray(affine_sample(image[:1].astype(np.float64), theta[None], (12, 16), padding))
    assert out.shape == (1, 12, 16, 3)
    expected = numpy_sampler(image[0, ..., 1].astype(np.float64), theta, (12, 16), padding)
    np.testing.assert_allclose(out[0, ..., 1], expected, atol=1e-9)
    opencv = cv2.warpAffine(image[0, ..., 1], theta_to_pixel_matrix(theta, (20, 30), (12, 16)), (16, 12),
                            flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                            borderMode=cv2.BORDER_CONSTANT if padding == "zeros" else cv2.BORDER_REPLICATE)
    np.testing.assert_allclose(out[0, ..., 1], opencv, atol=0.02)  # OpenCV rounds weights to 1/32 pixel


def test_gradients_to_theta_and_image_match_finite_differences(image):
    images = tf.constant(image[:1].astype(np.float64))
    theta = tf.Variable([[[0.8, 0.1, 0.05], [-0.15, 0.9, 0.1]]], dtype=tf.float64)
    weights = tf.constant(np.random.default_rng(1).random((1, 9, 11, 3)))

    def objective(theta_value, image_value):
        return tf.reduce_sum(weights * affine_sample(image_value, theta_value, (9, 11), "zeros"))

    with tf.GradientTape(persistent=True) as tape:
        tape.watch(images)
        value = objective(theta, images)
    gradient = tape.gradient(value, theta).numpy()
    image_gradient = tape.gradient(value, images).numpy()
    step = 1e-6
    numeric = np.zeros((2, 3))
    for row in range(2):
        for column in range(3):
            delta = np.zeros((1, 2, 3))
            delta[0, row, column] = step
            numeric[row, column] = (objective(theta + delta, images) - objective(theta - delta,
                                                                                 images)).numpy() / (2 * step)
    np.testing.assert_allclose(gradient[0], numeric, rtol=1e-4, atol=1e-6)
    # the sampler is linear in the image: its gradient is the sampler's adjoint applied to the weights
    probe = np.random.default_rng(2).random(image[:1].shape)
    along = (objective(theta, images + probe) - objective(theta, images)).numpy()
    np.testing.assert_allclose(np.sum(image_gradient * probe), along, rtol=1e-9)


def test_layer_and_builder_errors_name_the_argument():
    with pytest.raises(ValueError, match="padding"):
        BilinearSampler(padding="reflect")
    with pytest.raises(ValueError, match="output_size"):
        BilinearSampler((0, 4))
    with pytest.raises(ValueError, match="scale"):
        AffineFromParameters(0.0)
    with pytest.raises(STNModelError, match="num_classes"):
        build_classifier(1)
    with pytest.raises(STNModelError, match="input_size"):
        build_classifier(10, 8)
    with pytest.raises(STNModelError, match="padding"):
        build_classifier(10, 32, padding="wrap")


def test_classifier_shapes_identity_start_and_save_load_round_trip(tmp_path):
    model = build_classifier(10, 32, transformer=True, crop_size=24, filters=4)
    images = np.random.default_rng(3).random((3, 32, 32, 1)).astype(np.float32)
    outputs = model(images)
    assert outputs["logits"].shape == (3, 10) and outputs["probabilities"].shape == (3, 10)
    assert outputs["theta"].shape == (3, 2, 3) and outputs["crop"].shape == (3, 24, 24, 1)
    np.testing.assert_allclose(np.asarray(outputs["theta"]), np.repeat(IDENTITY[None], 3, axis=0), atol=1e-7)
    plain = build_classifier(10, 32, transformer=False, filters=4)
    assert set(plain(images)) == {"logits", "probabilities"}
    for network in (model, plain):
        path = save_classifier(network, tmp_path / f"{network.name}.keras")
        loaded = load_classifier(path)
        for key, value in network(images).items():
            np.testing.assert_array_equal(np.asarray(loaded(images)[key]), np.asarray(value))
    (tmp_path / "broken.keras").write_bytes(b"not a zip")
    with pytest.raises(STNModelError, match="broken.keras"):
        load_classifier(tmp_path / "broken.keras")


def test_digits_are_seeded_and_split_by_digit_sample():
    pytest.importorskip("sklearn")
    from paz6d.stn.digits import TEST, TRAIN, ClutteredDigits, DigitCanvas

    data = ClutteredDigits(DigitCanvas(canvas_size=40, scale=(10.0, 16.0), clutter=3))
    train, test = data.splits
    assert len(set(train) & set(test)) == 0 and len(train) + len(test) == 1797
    images, labels, boxes = data.batch(TRAIN, 5, 4, seed=7)
    assert images.shape == (4, 40, 40, 1) and images.dtype == np.float32 and labels.shape == (4,)
    assert 0.0 <= images.min() and images.max() <= 1.0
    assert np.all((boxes[:, 2] - boxes[:, 0] >= 10) & (boxes[:, 2] - boxes[:, 0] <= 16) & (boxes[:, 2] <= 40))
    again, _, _ = data.batch(TRAIN, 6, 2, seed=7)  # sample i does not depend on the batch it is in
    np.testing.assert_array_equal(again, images[1:3])
    other, _, _ = data.batch(TEST, 5, 4, seed=7)
    assert not np.array_equal(other, images)
    with pytest.raises(ValueError, match="scale"):
        DigitCanvas(canvas_size=20, scale=(10.0, 30.0))
    with pytest.raises(ValueError, match="fragment_size"):
        DigitCanvas(fragment_size=0)
    with pytest.raises(ValueError, match="images/labels"):
        ClutteredDigits(images=np.zeros((5, 7, 7)), labels=np.zeros(5))


def test_tiny_training_lowers_the_loss_and_the_pipeline_reads_the_run(tmp_path):
    pytest.importorskip("sklearn")
    from paz6d.stn.config import QUICK, STNTraining
    from paz6d.stn.pipeline import ClassifyDigit
    from paz6d.stn.train import train_stn

    out = tmp_path / "run"
    # large centred digits without clutter: learnable in a few dozen steps
    tiny = QUICK.replace(canvas_size=16, crop_size=16, scale=(14.0, 16.0), clutter=0, filters=8, learning_rate=3e-3,
                         test_samples=64, checkpoint_every=40, sample_every=0)
    summary = train_stn(STNTraining(out=out, steps=60, batch_size=32, progress=False, settings=tiny))
    rows = (out / "log.csv").read_text().splitlines()[1:]
    losses = [float(row.split(",")[4]) for row in rows]
    assert losses[-1] < losses[0] - 0.5, losses
    assert summary["steps"] == 60 and 0.0 <= summary["test_accuracy"] <= 1.0
    assert (out / run_files.CROPS_FILE).stat().st_size > 0
    classify = ClassifyDigit(out)
    assert classify.names == ["to_grey", "resize", "normalize", "predict", "label"]
    canvas = np.zeros((64, 64, 3), np.uint8)
    canvas[20:40, 24:36] = 255
    prediction = classify(canvas)
    assert prediction.class_name in classify.class_names and 0.0 < prediction.score <= 1.0
    assert prediction.crop.shape == (16, 16) and prediction.crop.dtype == np.uint8
    assert prediction.theta.shape == (2, 3)
    with pytest.raises(ValueError, match="image"):
        classify(np.zeros((4, 4, 2), np.uint8))
    # the same settings resume (nothing left to do, the training figures are kept); different ones are refused
    again = train_stn(STNTraining(out=out, steps=60, batch_size=32, progress=False, settings=tiny))
    assert again["final_losses"] == summary["final_losses"] and again["test_accuracy"] == summary["test_accuracy"]
    with pytest.raises(ValueError, match="transformer"):
        train_stn(STNTraining(out=out, steps=60, transformer=False, progress=False, settings=tiny))


def test_corrupt_run_directories_are_reported_by_file(tmp_path):
    with pytest.raises(ValueError, match="is not a directory"):
        STNRunDir.validate(tmp_path / "missing")
    with pytest.raises(ValueError, match="classifier.json: file not found"):
        STNRunDir.validate(tmp_path)
    run_files.write_classifier(tmp_path, 32, 24, True, [str(d) for d in range(10)], "zeros")
    with pytest.raises(ValueError, match="model.keras: file not found"):
        STNRunDir.validate(tmp_path)
    (tmp_path / STNRunDir.MODEL_FILE).write_bytes(b"garbage")
    with pytest.raises(ValueError, match="model.keras"):
        run_files.read_model(tmp_path)
    save_classifier(build_classifier(10, 40, transformer=True, filters=2), tmp_path / STNRunDir.MODEL_FILE)
    with pytest.raises(ValueError, match="canvas_size 32"):
        run_files.read_model(tmp_path)
    path = tmp_path / run_files.CLASSIFIER_FILE
    for text, message in (("{", "invalid JSON"), ("[]", "expected a JSON object"),
                          (json.dumps({"canvas_size": 32}), "missing field"),
                          (json.dumps({"canvas_size": 8, "crop_size": 24, "transformer": True,
                                       "class_names": ["a", "b"]}), "canvas_size"),
                          (json.dumps({"canvas_size": 32, "crop_size": 24, "transformer": "yes",
                                       "class_names": ["a", "b"]}), "transformer"),
                          (json.dumps({"canvas_size": 32, "crop_size": 24, "transformer": True,
                                       "class_names": ["a", "a"]}), "class_names")):
        path.write_text(text)
        with pytest.raises(ValueError, match=message):
            STNRunDir.read_description(tmp_path)
    assert is_run_dir(tmp_path, "stn") and not is_run_dir(tmp_path / "nothing", "stn")


def test_command_line_flags_and_errors(tmp_path, capsys):
    from paz6d import cli

    assert cli.main(["train", "stn", "--out", str(tmp_path / "run"), "--steps", "0"]) == 2
    assert "paz6d train stn: error: --steps: expected a positive number, got 0" in capsys.readouterr().err
    (tmp_path / "file").write_text("x")
    assert cli.main(["train", "stn", "--out", str(tmp_path / "file")]) == 2
    assert "--out" in capsys.readouterr().err
    assert cli.main(["train", "stn", "--out", str(tmp_path / "run"), "--crop-size", "8"]) == 2
    assert "--crop-size: expected at least 16, got 8" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        cli.main(["train", "stn", "--out", str(tmp_path / "run"), "--config", "huge"])
    from paz6d.stn.config import STNTraining

    assert STNTraining(out=tmp_path, crop_size=48).model_config.crop_size == 48
