"""KeypointNet model: spatial expectation, shapes, safe save/load round trip, corrupt files."""

import zipfile

import numpy as np
import pytest

kp = pytest.importorskip("paz6d.keypointnet.model")


def test_spatial_expectation_hand_computed():
    layer = kp.SpatialExpectation(stride=2)
    logits = np.full((1, 2, 2, 1), -1e4, dtype=np.float32)
    logits[0, 0, 1, 0] = logits[0, 1, 1, 0] = 0.0  # equal mass on the right column
    depth_maps = np.zeros((1, 2, 2, 1), dtype=np.float32)
    depth_maps[0, 0, 1, 0], depth_maps[0, 1, 1, 0] = 1.0, 3.0
    uv, depth, probabilities = (np.asarray(value) for value in layer([logits, depth_maps]))
    # stride 2: column 1 is centred at u = 2 + 0.5, rows at v = 0.5 and 2.5 -> mean v = 1.5
    np.testing.assert_allclose(uv[0, 0], [2.5, 1.5], atol=1e-6)
    assert depth[0, 0] == pytest.approx(2.0)
    np.testing.assert_allclose(probabilities[0, :, :, 0], [[0.0, 0.5], [0.0, 0.5]], atol=1e-6)


@pytest.fixture(scope="module")
def tiny_model():
    return kp.build_keypointnet(num_keypoints=5, input_size=32, filters=8, downsample=2, dilations=(1, 2))


def test_build_shapes_and_probability_maps_sum_to_one(tiny_model):
    images = np.random.default_rng(0).integers(0, 256, (2, 32, 32, 3)).astype(np.float32)
    outputs = tiny_model(images, training=False)
    assert tuple(outputs["uv"].shape) == (2, 5, 2)
    assert tuple(outputs["depth"].shape) == (2, 5)
    assert tuple(outputs["probabilities"].shape) == (2, 16, 16, 5)
    np.testing.assert_allclose(np.asarray(outputs["probabilities"]).sum(axis=(1, 2)), 1.0, rtol=1e-5)
    uv = np.asarray(outputs["uv"])
    assert np.all((uv >= 0) & (uv <= 31))
    np.testing.assert_allclose(np.asarray(outputs["depth"]), 1.3, rtol=1e-5)  # zero kernel, prior bias


@pytest.mark.parametrize("kwargs, field", [({"num_keypoints": 0}, "num_keypoints"), ({"downsample": 3}, "downsample"),
                                           ({"input_size": 30, "downsample": 4}, "input_size"),
                                           ({"dilations": ()}, "dilations"),
                                           ({"downsample": 4, "context_stride": 2}, "context_stride"),
                                           ({"downsample": 4, "context_stride": 16}, "context_stride"),
                                           ({"input_size": 36, "downsample": 4, "context_stride": 8}, "input_size")])
def test_build_rejects_bad_configuration(kwargs, field):
    with pytest.raises(ValueError, match=field):
        kp.build_keypointnet(**kwargs)


def test_context_stack_runs_coarse_and_maps_come_back_at_downsample(tmp_path):
    model = kp.build_keypointnet(num_keypoints=3, input_size=32, filters=8, downsample=2, dilations=(1, 2),
                                 context_stride=8)
    assert tuple(model.get_layer("dilated0_conv").output.shape[1:3]) == (4, 4)  # 32 / 8
    assert [layer.name for layer in model.layers if layer.name.endswith("_skip")] == ["up4_skip", "up2_skip"]
    images = np.random.default_rng(2).integers(0, 256, (2, 32, 32, 3)).astype(np.float32)
    outputs = model(images, training=False)
    assert tuple(outputs["probabilities"].shape) == (2, 16, 16, 3)
    loaded = kp.load_keypointnet(kp.save_keypointnet(model, tmp_path / "decoder.keras"))
    np.testing.assert_allclose(np.asarray(loaded(images, training=False)["uv"]), np.asarray(outputs["uv"]), atol=1e-5)


def test_pretrained_body_is_frozen_feeds_the_stack_at_stride_8_and_loads_back(tmp_path):
    from paz6d.backbones import efficientnet_lite0 as lite0

    model, forcing = kp.build_keypointnet(num_keypoints=3, input_size=64, filters=8, downsample=4, dilations=(1, 2),
                                          context_stride=8, orientation=True, backbone="efficientnet-lite0")
    names = {layer.name for layer in model.layers}
    assert "stem_conv" not in names and "down0_conv" not in names  # the own stem and strided convs are gone
    body = model.get_layer(kp.BACKBONE_LAYER)
    assert not body.trainable and not body.trainable_weights
    assert body.count_params() > 0 and forcing.get_layer(kp.BACKBONE_LAYER) is body  # one body for both passes
    assert tuple(model.get_layer("dilated0_conv").output.shape[1:3]) == (8, 8)  # 64 / 8
    assert [tuple(output.shape[1:]) for output in body.outputs] == [(16, 16, 24), (8, 8, 40)]  # strides 4, 8
    images = np.random.default_rng(4).integers(0, 256, (2, 64, 64, 3)).astype(np.float32)
    # the body reads the backbone's input scaling: the frozen features equal the feature extractor's
    extractor = lite0.build_features((64, 64, 3), frozen_stages=len(lite0.STAGES))
    stride8 = extractor(lite0.preprocess(images.astype(np.uint8)))[0]
    preprocess = model.get_layer("backbone_preprocess")
    np.testing.assert_allclose(np.asarray(body(preprocess(images))[1]), np.asarray(stride8), rtol=1e-4, atol=1e-4)
    outputs = model(images, training=False)
    assert tuple(outputs["probabilities"].shape) == (2, 16, 16, 3) and tuple(outputs["chart"].shape) == (2, 3)
    loaded = kp.load_keypointnet(kp.save_keypointnet(model, tmp_path / "lite0.keras"))
    np.testing.assert_allclose(np.asarray(loaded(images, training=False)["uv"]), np.asarray(outputs["uv"]),
                               rtol=1e-5, atol=1e-4)
    for kwargs in ({"downsample": 4, "context_stride": 4}, {"downsample": 1, "context_stride": 8}):
        with pytest.raises(ValueError, match="backbone: efficientnet-lite0 gives the maps of strides 2 to 8"):
            kp.build_keypointnet(input_size=64, backbone="efficientnet-lite0", **kwargs)
    with pytest.raises(ValueError, match="backbone: expected one of"):
        kp.build_keypointnet(backbone="resnet50")


def test_bfloat16_body_with_float32_heads_survives_save_and_load(tmp_path):
    model = kp.build_keypointnet(num_keypoints=3, input_size=32, filters=8, downsample=2, dilations=(1,),
                                 context_stride=4, compute_dtype="bfloat16")
    loaded = kp.load_keypointnet(kp.save_keypointnet(model, tmp_path / "bf16.keras"))
    for candidate in (model, loaded):
        assert candidate.get_layer("stem_conv").compute_dtype == "bfloat16"
        assert candidate.get_layer("up2_conv").compute_dtype == "bfloat16"
        assert candidate.get_layer("stem_conv").variable_dtype == "float32"
        assert candidate.get_layer("logits").compute_dtype == "float32"
        assert candidate.get_layer("expectation").compute_dtype == "float32"
    images = np.random.default_rng(3).integers(0, 256, (2, 32, 32, 3)).astype(np.float32)
    outputs = loaded(images, training=False)
    assert all(value.dtype == "float32" for value in outputs.values())
    np.testing.assert_allclose(np.asarray(outputs["probabilities"]).sum(axis=(1, 2)), 1.0, rtol=1e-5)
    with pytest.raises(ValueError, match="compute_dtype"):
        kp.build_keypointnet(compute_dtype="float16")


def test_save_load_round_trip_gives_identical_outputs(tiny_model, tmp_path):
    path = kp.save_keypointnet(tiny_model, tmp_path / "model.keras")
    loaded = kp.load_keypointnet(path)
    images = np.random.default_rng(1).integers(0, 256, (3, 32, 32, 3)).astype(np.float32)
    expected, got = tiny_model(images, training=False), loaded(images, training=False)
    for name in kp.OUTPUT_NAMES:
        np.testing.assert_allclose(np.asarray(got[name]), np.asarray(expected[name]), rtol=1e-6, atol=1e-6)
    with zipfile.ZipFile(path) as archive:  # registered layer, no Lambda / pickled code
        config = archive.read("config.json").decode()
    assert "Lambda" not in config and "paz6d>SpatialExpectation" in config


def test_load_errors_name_the_file(tmp_path):
    with pytest.raises(kp.KeypointNetError, match="not found"):
        kp.load_keypointnet(tmp_path / "missing.keras")
    corrupt = tmp_path / "corrupt.keras"
    corrupt.write_bytes(b"this is not a zip archive")
    with pytest.raises(ValueError, match="corrupt.keras"):
        kp.load_keypointnet(corrupt)
    with pytest.raises(ValueError, match=".keras"):
        kp.save_keypointnet(kp.build_keypointnet(2, 16, 4, 2, (1,)), tmp_path / "model.h5")


def test_load_rejects_a_model_that_is_not_a_keypointnet(tmp_path):
    keras = kp.keras
    inputs = keras.Input((4,))
    other = keras.Model(inputs, keras.layers.Dense(2)(inputs))
    other.save(tmp_path / "other.keras")
    with pytest.raises(kp.KeypointNetError, match="outputs"):
        kp.load_keypointnet(tmp_path / "other.keras")
