"""SSD on the pretrained EfficientNet-Lite0 (``paz6d train ssd --backbone efficientnet-lite0``): settings and
flags, the network (frozen parts, feature maps matching the priors, input scaling), the per-variable
learning rate, a tiny training that lowers the loss and loads back through the detection pipeline."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from paz6d.cli import build_parser
from paz6d.cli_options import config_from_args
from paz6d.ssd import run_dir as run_files
from paz6d.ssd.config import BACKBONE_SETTINGS, QUICK, SSDTraining
from paz6d.ssd.run_dir import SSDRunDir

BACKBONE = "efficientnet-lite0"
TINY = QUICK.replace(input_size=128, width=0.25, learning_rate=5e-3, warmup_steps=0, expand_probability=0.0,
                     checkpoint_every=20, sample_every=20)
#: The tiny network with the backbone's body, learning-rate factor and frozen stages.
TINY_BACKBONE = TINY.replace(backbone=BACKBONE, backbone_rate_factor=0.1, frozen_stages=3)


@pytest.fixture(scope="module")
def generated(two_object_scenes) -> Path:
    return two_object_scenes(3)


@pytest.fixture(scope="module")
def trained(generated, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ssd_backbone_run") / "run"
    from paz6d.ssd.train import train_ssd

    train_ssd(SSDTraining(dataset=generated, out=out, steps=20, batch_size=4, progress=False,
                          settings=TINY_BACKBONE))
    return out


def test_backbone_flag_brings_its_settings_and_leaves_the_light_defaults_alone():
    assert SSDTraining(dataset="d", out="o").model_config == QUICK
    assert SSDTraining(dataset="d", out="o", backbone="none").model_config == QUICK
    settings = SSDTraining(dataset="d", out="o", backbone=BACKBONE).model_config
    assert settings == QUICK.replace(**BACKBONE_SETTINGS[BACKBONE])
    assert settings.input_size == 320 and settings.batch_size == 8 and settings.backbone_rate_factor == 0.1
    given = SSDTraining(dataset="d", out="o", backbone=BACKBONE, input_size=256, batch_size=4).model_config
    assert (given.input_size, given.batch_size, given.learning_rate) == (256, 4, 1e-3)
    args = build_parser().parse_args(["train", "ssd", "--dataset", "d", "--out", "o", "--backbone", BACKBONE])
    assert config_from_args(SSDTraining, args, exclude=("settings",)).model_config.backbone == BACKBONE
    with pytest.raises(ValueError, match="backbone: only the light network"):
        SSDTraining(dataset="d", out="o", config="full", backbone=BACKBONE)
    with pytest.raises(ValueError, match="backbone: expected one of"):
        SSDTraining(dataset="d", out="o", backbone="resnet50")
    with pytest.raises(SystemExit):
        build_parser().parse_args(["train", "ssd", "--dataset", "d", "--out", "o", "--backbone", "resnet50"])


def test_top_down_flag_replaces_the_config_and_builds_on_the_backbone(tmp_path):
    from paz6d.ssd.model import build_ssd, load_ssd, save_ssd

    parse = build_parser().parse_args
    for flags, expected in (([], False), (["--top-down"], True), (["--no-top-down"], False)):
        args = parse(["train", "ssd", "--dataset", "d", "--out", "o", "--backbone", BACKBONE, *flags])
        settings = config_from_args(SSDTraining, args, exclude=("settings",)).model_config
        assert settings.top_down is expected and settings.backbone == BACKBONE
    on = QUICK.replace(top_down=True)
    assert SSDTraining(dataset="d", out="o", settings=on).model_config.top_down  # the flag off keeps the settings'
    with pytest.raises(ValueError, match="top_down: only the light network"):
        SSDTraining(dataset="d", out="o", config="full", top_down=True)
    model, spec = build_ssd(3, "light", 128, width=0.25, backbone=BACKBONE, top_down=True)
    fused = [layer for layer in model.layers if layer.name.startswith("topdown_") and layer.name.endswith("pw_relu")]
    assert len(fused) == 3 and all(layer.output.shape[-1] == 32 for layer in fused)  # 128 channels x width 0.25
    image = np.random.default_rng(1).normal(size=(1, 128, 128, 3)).astype(np.float32)
    save_ssd(model, tmp_path / "model.keras")
    np.testing.assert_allclose(np.asarray(load_ssd(tmp_path / "model.keras", spec, 3)(image)), np.asarray(model(image)),
                               rtol=1e-5, atol=1e-5)


def test_backbone_ssd_maps_match_the_priors_its_body_is_partly_frozen_and_it_loads_back(tmp_path):
    from paz6d.pipelines import DetectSingleShot
    from paz6d.ssd.model import (BACKBONE_LAYER, backbone_variables, build_ssd, input_normalization, priors_for,
                                 save_ssd)

    model, spec = build_ssd(3, "light", 192, width=0.25, backbone=BACKBONE, frozen_stages=3)
    assert spec.feature_map_sizes == (24, 12, 6, 3, 2, 1)
    assert model.output_shape == (None, len(priors_for(spec)), 4 + 3)
    body = model.get_layer(BACKBONE_LAYER)
    trainable = {layer.name: layer.trainable for layer in body.layers if layer.weights}
    assert not trainable["stem_conv"] and not trainable["block2_dwconv"] and trainable["block3_dwconv"]
    assert not any(value for name, value in trainable.items() if name.endswith("_bn"))
    slow = {id(v) for v in backbone_variables(model)}
    assert slow and slow < {id(v) for v in model.trainable_variables}
    assert backbone_variables(build_ssd(3, "light", 128, width=0.25)[0]) == []
    whole, whole_spec = build_ssd(3, "light", 128, width=0.25, backbone=BACKBONE, any_size=True)
    assert whole(np.zeros((1, 128, 192, 3), np.float32)).shape == (1, len(priors_for(whole_spec, (128, 192))), 7)
    pixels = np.array([0, 127, 255], np.uint8)
    from paz6d.backend.image import normalize

    scaled = normalize(pixels, **input_normalization(BACKBONE))
    np.testing.assert_allclose(scaled, (pixels - 127.0) / 128.0, atol=1e-6)
    with pytest.raises(ValueError, match="backbone: only the light network"):
        build_ssd(3, "ssd300", backbone=BACKBONE)
    save_ssd(model, SSDRunDir.model_path(tmp_path))  # a run directory, read back in safe mode
    run_files.write_detector(tmp_path, "light", ["a", "b"], spec.to_dict(),
                             normalization=input_normalization(BACKBONE))
    detect = DetectSingleShot(tmp_path, score_threshold=0.0)
    image = np.random.default_rng(0).integers(0, 256, (120, 160, 3), dtype=np.uint8)
    values = detect.run_steps({"image": image}, stop="decode")
    np.testing.assert_allclose(values["input"], (values["resized"] - 127.0) / 128.0, atol=1e-5)
    np.testing.assert_allclose(values["output"], np.asarray(model(values["input"][None], training=False))[0],
                               rtol=1e-4, atol=1e-4)


def test_slow_variables_step_at_the_lower_rate():
    from paz6d.training.scaled_rates import ScaledRateAdamW, keras
    from paz6d.backend.tensorflow_guard import import_tensorflow

    tf = import_tensorflow()
    fast, slow = keras.Variable(np.ones(3, np.float32)), keras.Variable(np.ones(3, np.float32))
    optimizer = ScaledRateAdamW([slow], 0.1, learning_rate=0.01, weight_decay=0.0)
    gradient = tf.constant([1.0, -2.0, 0.5])

    @tf.function
    def step():
        optimizer.apply_gradients([(gradient, fast), (gradient, slow)])

    step()
    step()
    fast_move, slow_move = 1 - np.asarray(fast), 1 - np.asarray(slow)
    np.testing.assert_allclose(fast_move, [0.02, -0.02, 0.02], rtol=1e-4)
    np.testing.assert_allclose(slow_move, 0.1 * fast_move, rtol=1e-4)
    with pytest.raises(ValueError, match="rate_factor"):
        ScaledRateAdamW([slow], 0.0)


@pytest.mark.slow  # about a minute: data generation, tracing the backbone's gradients, 20 steps
def test_tiny_backbone_training_lowers_the_loss_and_loads_through_the_pipeline(trained, generated):
    from paz6d.backend.image import load_image
    from paz6d.pipelines import DetectSingleShot

    with (trained / "log.csv").open() as handle:
        losses = [float(row["loss"]) for row in csv.DictReader(handle)]
    assert len(losses) == 2 and losses[-1] < 0.8 * losses[0]
    detector = SSDRunDir.read_description(trained)
    np.testing.assert_allclose(detector["normalization"]["mean"], [127 / 255] * 3)
    np.testing.assert_allclose(detector["normalization"]["std"], [128 / 255] * 3)
    config = json.loads((trained / "config.json").read_text())
    assert config["settings"]["backbone"] == BACKBONE and config["settings"]["backbone_rate_factor"] == 0.1
    detect = DetectSingleShot(trained, score_threshold=0.0, max_detections=5)
    image = load_image(next((generated / "train" / "000000" / "rgb").iterdir()))
    values = detect.run_steps({"image": image})
    np.testing.assert_allclose(values["input"], (values["resized"] - 127.0) / 128.0, atol=1e-5)
    assert 1 <= len(values["detections"]) <= 5
    assert {box.class_name for box in values["detections"]} <= {"obj_000005", "obj_000008"}
    with pytest.raises(ValueError, match="backbone"):  # resuming with another body is refused
        from paz6d.ssd.train import train_ssd

        train_ssd(SSDTraining(dataset=generated, out=trained, steps=20, batch_size=4, progress=False, settings=TINY))


def test_detector_normalization_is_checked(tmp_path):
    from paz6d.ssd.model import paper_priors

    priors = paper_priors("light", 128).to_dict()
    run_files.write_detector(tmp_path, "light", ["a"], priors, normalization={"mean": [0.5] * 3, "std": [0.5] * 3})
    assert SSDRunDir.read_description(tmp_path)["normalization"] == {"mean": [0.5] * 3, "std": [0.5] * 3}
    data = json.loads((tmp_path / "detector.json").read_text())
    for bad in ({"mean": [0.5] * 3, "std": [0.0] * 3}, {"mean": [0.5] * 2, "std": [0.5] * 3}, [0.5, 0.5]):
        (tmp_path / "detector.json").write_text(json.dumps({**data, "normalization": bad}))
        with pytest.raises(ValueError, match="detector.json: normalization: expected"):
            SSDRunDir.read_description(tmp_path)
