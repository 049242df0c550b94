"""AAE model builder, loss, crops and safe .keras round trips."""

from __future__ import annotations

import numpy as np
import pytest

from paz6d.aae import model as aae

TINY = dict(input_size=16, latent_size=8, filters=(4, 8), kernel_size=3)


def test_shapes_and_nested_encoder():
    model = aae.build_autoencoder(**TINY)
    assert model.input.shape[1:] == (16, 16, 3) and model.output.shape[1:] == (16, 16, 3)
    encoder = aae.encoder_of(model)
    assert encoder.output.shape[-1] == 8
    x = np.random.default_rng(0).random((2, 16, 16, 3), dtype=np.float32)
    output = np.asarray(model(x))
    assert np.all((output >= 0) & (output <= 1))  # sigmoid reconstruction


@pytest.mark.parametrize("batch_norm", [False, True])
def test_save_load_round_trip_gives_identical_outputs(tmp_path, batch_norm):
    model = aae.build_autoencoder(**TINY, batch_norm=batch_norm)
    path = aae.save_model(model, tmp_path / "model.keras")
    assert not list(tmp_path.glob("*.tmp.keras"))
    loaded = aae.load_model(path)
    x = np.random.default_rng(1).random((3, 16, 16, 3), dtype=np.float32)
    np.testing.assert_array_equal(np.asarray(loaded(x)), np.asarray(model(x)))
    np.testing.assert_array_equal(np.asarray(aae.encoder_of(loaded)(x)), np.asarray(aae.encoder_of(model)(x)))


def test_corrupt_and_missing_model_files_raise_value_error(tmp_path):
    with pytest.raises(ValueError, match="not found"):
        aae.load_model(tmp_path / "missing.keras")
    garbage = tmp_path / "garbage.keras"
    garbage.write_bytes(b"this is not a zip archive")
    with pytest.raises(ValueError, match="not a readable .keras model archive"):
        aae.load_model(garbage)
    truncated = tmp_path / "truncated.keras"
    data = aae.save_model(aae.build_autoencoder(**TINY), tmp_path / "good.keras").read_bytes()
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="truncated.keras"):
        aae.load_model(truncated)
    with pytest.raises(ValueError, match=".keras"):
        aae.save_model(aae.build_autoencoder(**TINY), tmp_path / "model.h5")


def test_bad_architectures():
    with pytest.raises(ValueError, match="input_size"):
        aae.build_encoder(input_size=20, filters=(4, 8, 8))  # 20 is not a multiple of 8
    with pytest.raises(ValueError, match="filters"):
        aae.build_encoder(filters=())
    with pytest.raises(ValueError, match="latent_size"):
        aae.build_decoder(latent_size=0)


def test_bootstrapped_loss_matches_numpy():
    rng = np.random.default_rng(2)
    target = rng.random((2, 8, 8, 3), dtype=np.float32)
    prediction = rng.random((2, 8, 8, 3), dtype=np.float32)
    errors = ((target - prediction) ** 2).sum(-1).reshape(2, -1)
    plain = float(aae.reconstruction_loss(target, prediction))
    assert plain == pytest.approx(errors.mean(), rel=1e-6)
    top = np.sort(errors, axis=1)[:, -16:]  # 25% of 64 pixels per image
    assert float(aae.reconstruction_loss(target, prediction, 0.25)) == pytest.approx(top.mean(), rel=1e-6)
    with pytest.raises(ValueError, match="bootstrap_fraction"):
        aae.reconstruction_loss(target, prediction, 0.0)


def test_crop_object_identity_and_border():
    rng = np.random.default_rng(3)
    image = rng.integers(0, 256, (60, 80, 3), dtype=np.uint8)
    # a square box, padding 1, output the same size: the crop is exactly the pixels of the box
    np.testing.assert_array_equal(aae.crop_object(image, (10, 20, 30, 40), 20, padding=1.0), image[20:40, 10:30])
    # a 20x10 box is cropped as its 20x20 square around the centre
    np.testing.assert_array_equal(aae.crop_object(image, (10, 25, 30, 35), 20, padding=1.0), image[20:40, 10:30])
    # half outside the image: zeros there
    crop = aae.crop_object(image, (-10, 0, 10, 20), 20, padding=1.0)
    assert np.all(crop[:, :10] == 0)
    np.testing.assert_array_equal(crop[:, 10:], image[0:20, 0:10])
    # shrinking (anti-aliased path) keeps the mean colour of a flat image
    flat = np.full((200, 200, 3), 77, np.uint8)
    assert np.all(aae.crop_object(flat, (20, 20, 180, 180), 16, padding=1.0) == 77)
    # RGBA crops keep their 4 channels
    assert aae.crop_object(np.dstack([image, image[..., 0]]), (10, 20, 30, 40), 8).shape == (8, 8, 4)


def test_model_input_checks():
    assert aae.to_model_input(np.full((4, 4, 3), 255, np.uint8)).shape == (1, 4, 4, 3)
    with pytest.raises(ValueError, match="uint8"):
        aae.to_model_input(np.zeros((1, 4, 4, 3), np.float32))
    with pytest.raises(ValueError, match="RGB"):
        aae.to_model_input(np.zeros((1, 4, 4, 4), np.uint8))


def test_bfloat16_body_keeps_the_code_and_reconstruction_float32(tmp_path):
    model = aae.build_autoencoder(**TINY, batch_norm=True, compute_dtype="bfloat16")
    encoder = aae.encoder_of(model)
    decoder = model.get_layer(aae.DECODER_NAME)
    assert encoder.get_layer("encoder_conv0").compute_dtype == "bfloat16"
    assert decoder.get_layer("decoder_deconv0").compute_dtype == "bfloat16"
    assert encoder.get_layer("latent").compute_dtype == "float32"
    assert decoder.get_layer("reconstruction").compute_dtype == "float32"
    assert all(weight.dtype == "float32" for weight in model.weights)
    x = np.random.default_rng(4).random((3, 16, 16, 3), dtype=np.float32)
    output, code = model(x), encoder(x)
    assert output.dtype == "float32" and code.dtype == "float32"
    reference = aae.build_autoencoder(**TINY, batch_norm=True)  # the same weights, computed in float32
    reference.set_weights(model.get_weights())
    np.testing.assert_allclose(np.asarray(code), np.asarray(aae.encoder_of(reference)(x)), rtol=0.05, atol=0.02)
    loaded = aae.load_model(aae.save_model(model, tmp_path / "bf16.keras"))
    assert aae.encoder_of(loaded).get_layer("encoder_conv0").compute_dtype == "bfloat16"
    np.testing.assert_array_equal(np.asarray(loaded(x)), np.asarray(output))
    with pytest.raises(ValueError, match="compute_dtype: expected one of"):
        aae.build_encoder(**TINY, compute_dtype="float16")


def test_pretrained_encoder_reads_the_frozen_imagenet_stride_16_map_of_the_upsampled_crop(tmp_path):
    """The encoder's body equals EfficientNet-Lite0's stride-16 features of the crop at twice its size
    (resized and scaled to the network's range outside the model, as an oracle), stays frozen, and the
    whole autoencoder round-trips through .keras in safe mode."""
    import tensorflow as tf

    from paz6d.backbones import efficientnet_lite0 as lite0

    model = aae.build_autoencoder(32, 8, (4, 8), 3, backbone="efficientnet-lite0")
    encoder = aae.encoder_of(model)
    assert encoder.output.shape[-1] == 8
    body = encoder.get_layer("encoder_backbone_stride16")
    assert not body.trainable_weights and body.output.shape[1:] == (4, 4, 112)  # 64 px / 16, 112 channels
    trainable = {weight.path.split("/")[0] for weight in model.trainable_weights}
    assert not any(name.startswith(("stem", "block")) for name in trainable)
    crops = np.random.default_rng(2).random((2, 32, 32, 3), dtype=np.float32)
    upsampled = tf.image.resize(crops * 255.0, (64, 64), method="bilinear").numpy()
    expected = lite0.build_features((64, 64, 3))(lite0.preprocess(upsampled))[1]
    inside = tf.keras.Model(encoder.input, encoder.get_layer("encoder_flatten").input)
    np.testing.assert_allclose(np.asarray(inside(crops)), np.asarray(expected), atol=2e-4)
    loaded = aae.load_model(aae.save_model(model, tmp_path / "model.keras"))
    np.testing.assert_array_equal(np.asarray(loaded(crops)), np.asarray(model(crops)))
    with pytest.raises(ValueError, match="backbone: expected one of"):
        aae.build_encoder(**TINY, backbone="resnet50")
