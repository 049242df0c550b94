"""Augmented Autoencoder (Sundermeyer et al., ECCV 2018): convolutional encoder-decoder for implicit 3D orientation.

The encoder maps an object crop ``(S, S, 3)`` (float32 RGB in [0, 1]) to a latent code; the decoder
reconstructs the clean rendering of the object from it. Trained to undo augmentations (background,
occluders, colour/light jitter, crop shift), the code depends on the object's orientation only and
indexes a codebook of orientations (:mod:`paz6d.aae.codebook`).

Crops are squares of side ``padding * max(box width, box height)`` centred on the object's 2D box
(:func:`crop_object`); the same function makes training, codebook and test crops.

Models are saved in the native ``.keras`` format and loaded with ``safe_mode=True``: only standard Keras
layers are used, so loading never executes arbitrary code. TensorFlow is imported through
:func:`paz6d.backend.tensorflow_guard.import_keras` when a function here first needs it.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from paz6d.backbones import check_backbone
from paz6d.backend.square_crop import crop_square, square_window
from paz6d.backend.files import save_keras_model_atomically
from paz6d.backend.tensorflow_guard import import_keras, load_keras_model
from paz6d.training.precision import body_policy

ENCODER_NAME = "encoder"
#: The EfficientNet-Lite0 map a pretrained encoder reads (:data:`paz6d.backbones.efficientnet_lite0.FEATURES`).
STRIDE_16_FEATURES = "block10_out"
DECODER_NAME = "decoder"


def _check_architecture(input_size: int, latent_size: int, filters: Sequence[int], kernel_size: int) -> None:
    if not filters or any(int(f) <= 0 for f in filters):
        raise ValueError(f"filters: expected a non-empty list of positive channel counts, got {list(filters)}")
    stride_product = 2 ** len(filters)
    if int(input_size) <= 0 or input_size % stride_product:
        raise ValueError(f"input_size: expected a positive multiple of 2**len(filters) = {stride_product}, "
                         f"got {input_size}")
    if int(latent_size) <= 0:
        raise ValueError(f"latent_size: expected a positive integer, got {latent_size}")
    if int(kernel_size) <= 0:
        raise ValueError(f"kernel_size: expected a positive integer, got {kernel_size}")


def _activate(keras, x, batch_norm: bool, name: str, body: str):
    """ReLU, preceded by batch normalisation when ``batch_norm`` (dtype policy ``body``)."""
    if batch_norm:
        x = keras.layers.BatchNormalization(name=f"{name}_bn", dtype=body)(x)
    return keras.layers.ReLU(name=f"{name}_relu", dtype=body)(x)


def build_encoder(input_size: int = 64, latent_size: int = 64, filters: Sequence[int] = (32, 64, 64, 128),
                  kernel_size: int = 5, batch_norm: bool = False, compute_dtype: str = "float32",
                  backbone: str = "none"):
    """Encoder ``(B, S, S, 3) -> (B, latent_size)``: strided convolutions (ReLU, optional batch
    normalisation), then a linear dense layer.

    The paper's architecture is ``input_size=128, latent_size=128, filters=(128, 256, 256, 512)``, 5×5 kernels.
    With ``compute_dtype="bfloat16"`` the convolutions compute in bfloat16 (float32 weights); the latent
    code, which the codebook compares by cosine similarity, is always float32.

    With ``backbone="efficientnet-lite0"`` the convolutions are the ImageNet EfficientNet-Lite0 instead
    (:mod:`paz6d.backbones`): the crop is resized to ``2 S`` (bilinear), scaled to the network's input range
    and read up to its stride-16 map (``S / 8`` squared positions, 112 channels), which stays frozen
    (float32, ImageNet batch-norm statistics); only the dense layer to the code trains. ``filters``,
    ``kernel_size`` and ``batch_norm`` then shape the decoder only.
    """
    _check_architecture(input_size, latent_size, filters, kernel_size)
    check_backbone(backbone)
    keras = import_keras()
    inputs = keras.Input((input_size, input_size, 3), name="crop")
    if backbone == "none":
        body = body_policy(compute_dtype)
        x = inputs
        for index, channels in enumerate(filters):
            x = keras.layers.Conv2D(int(channels), kernel_size, strides=2, padding="same", use_bias=not batch_norm,
                                    name=f"encoder_conv{index}", dtype=body)(x)
            x = _activate(keras, x, batch_norm, f"encoder_conv{index}", body)
    else:
        x = _pretrained_features(keras, inputs, int(input_size))
        body = "float32"
    x = keras.layers.Flatten(name="encoder_flatten", dtype=body)(x)
    code = keras.layers.Dense(int(latent_size), name="latent", dtype="float32")(x)
    return keras.Model(inputs, code, name=ENCODER_NAME)


def _pretrained_features(keras, crops, input_size: int):
    """The frozen EfficientNet-Lite0 stride-16 map of ``crops`` (RGB in [0, 1]) read at twice their size."""
    from paz6d.backbones import efficientnet_lite0 as lite0

    side = 2 * input_size
    x = keras.layers.Resizing(side, side, interpolation="bilinear", name="encoder_upsample")(crops)
    x = lite0.preprocess_layer("encoder_preprocess", pixel_max=1.0)(x)
    features = lite0.build_features((side, side, 3), frozen_stages=len(lite0.STAGES), name="encoder_backbone")
    stride_16 = [name for name, stride, _ in lite0.FEATURES].index(STRIDE_16_FEATURES)
    body = keras.Model(features.input, features.outputs[stride_16], name="encoder_backbone_stride16")
    body.trainable = False
    return body(x, training=False)


def build_decoder(input_size: int = 64, latent_size: int = 64, filters: Sequence[int] = (32, 64, 64, 128),
                  kernel_size: int = 5, batch_norm: bool = False, compute_dtype: str = "float32"):
    """Decoder ``(B, latent_size) -> (B, S, S, 3)`` in [0, 1]: dense layer, then strided transposed
    convolutions mirroring the encoder, sigmoid output (always float32, as the loss)."""
    _check_architecture(input_size, latent_size, filters, kernel_size)
    body = body_policy(compute_dtype)
    keras = import_keras()
    side = input_size // 2 ** len(filters)
    code = keras.Input((int(latent_size),), name="code")
    x = keras.layers.Dense(side * side * int(filters[-1]), use_bias=not batch_norm, name="decoder_dense",
                           dtype=body)(code)
    x = _activate(keras, x, batch_norm, "decoder_dense", body)
    x = keras.layers.Reshape((side, side, int(filters[-1])), name="decoder_reshape", dtype=body)(x)
    for index, channels in enumerate(list(filters[:-1])[::-1]):
        x = keras.layers.Conv2DTranspose(int(channels), kernel_size, strides=2, padding="same",
                                         use_bias=not batch_norm, name=f"decoder_deconv{index}", dtype=body)(x)
        x = _activate(keras, x, batch_norm, f"decoder_deconv{index}", body)
    image = keras.layers.Conv2DTranspose(3, kernel_size, strides=2, padding="same", activation="sigmoid",
                                         name="reconstruction", dtype="float32")(x)
    return keras.Model(code, image, name=DECODER_NAME)


def build_autoencoder(input_size: int = 64, latent_size: int = 64, filters: Sequence[int] = (32, 64, 64, 128),
                      kernel_size: int = 5, batch_norm: bool = False, compute_dtype: str = "float32",
                      backbone: str = "none"):
    """Autoencoder ``(B, S, S, 3) -> (B, S, S, 3)`` made of the nested models ``encoder`` and ``decoder``
    (reach them with :func:`encoder_of` / ``model.get_layer("decoder")``); ``compute_dtype`` as in
    :func:`build_encoder` (and ``backbone``, the encoder's body)."""
    keras = import_keras()
    encoder = build_encoder(input_size, latent_size, filters, kernel_size, batch_norm, compute_dtype, backbone)
    decoder = build_decoder(input_size, latent_size, filters, kernel_size, batch_norm, compute_dtype)
    inputs = keras.Input((input_size, input_size, 3), name="augmented_crop")
    return keras.Model(inputs, decoder(encoder(inputs)), name="augmented_autoencoder")


def encoder_of(autoencoder):
    """The nested encoder model of an autoencoder built by :func:`build_autoencoder`."""
    try:
        return autoencoder.get_layer(ENCODER_NAME)
    except ValueError as error:
        raise ValueError(f"autoencoder: has no nested model named {ENCODER_NAME!r}") from error


def encode_function(encoder):
    """``encoder`` as a compiled function ``(B, S, S, 3) float32 -> (B, L)`` numpy codes (one
    ``tf.function`` trace serves every batch size; several times faster than eager calls for one crop)."""
    from paz6d.backend.tensorflow_guard import import_tensorflow

    tf = import_tensorflow()
    size = encoder.input.shape[1]
    compiled = tf.function(lambda x: encoder(x, training=False),
                           input_signature=[tf.TensorSpec((None, size, size, 3), tf.float32)])
    return lambda inputs: compiled(tf.convert_to_tensor(inputs, dtype=tf.float32)).numpy()


def reconstruction_loss(target, prediction, bootstrap_fraction: float = 1.0):
    """Per-batch mean squared error; with ``bootstrap_fraction < 1`` the paper's bootstrapped L2:
    per image, only the largest ``bootstrap_fraction`` of the pixel errors count (paper: 1/4).

    Args:
        target: ``(B, S, S, 3)`` clean crops in [0, 1].
        prediction: ``(B, S, S, 3)`` reconstructions.
        bootstrap_fraction: fraction of pixels (0, 1] kept per image.

    Returns:
        Scalar tensor.
    """
    if not 0.0 < bootstrap_fraction <= 1.0:
        raise ValueError(f"bootstrap_fraction: expected a value in (0, 1], got {bootstrap_fraction}")
    keras = import_keras()
    ops = keras.ops
    pixel_errors = ops.sum(ops.square(target - prediction), axis=-1)  # (B, S, S)
    if bootstrap_fraction >= 1.0:
        return ops.mean(pixel_errors)
    pixels = int(np.prod(pixel_errors.shape[1:]))
    flat = ops.reshape(pixel_errors, (-1, pixels))
    keep = max(1, int(round(bootstrap_fraction * pixels)))
    largest, _ = ops.top_k(flat, k=keep, sorted=False)
    return ops.mean(largest)


def to_model_input(crops) -> np.ndarray:
    """``uint8`` crops ``(B, S, S, 3)`` (or one ``(S, S, 3)``) to float32 in [0, 1] with a batch axis."""
    crops = np.asarray(crops)
    if crops.dtype != np.uint8:
        raise ValueError(f"crops: expected uint8 RGB crops, got dtype {crops.dtype}")
    if crops.ndim == 3:
        crops = crops[None]
    if crops.ndim != 4 or crops.shape[-1] != 3:
        raise ValueError(f"crops: expected shape (B, S, S, 3) RGB, got {crops.shape}")
    return crops.astype(np.float32) / 255.0


def save_model(model, path: str | Path) -> Path:
    """Saves ``model`` in the native ``.keras`` format (temp file, then atomic rename)."""
    return save_keras_model_atomically(model, path)


def load_model(path: str | Path):
    """Loads a ``.keras`` autoencoder with ``safe_mode=True`` (no Lambda layers, no pickled code).

    Raises:
        ValueError: the file is missing, not a ``.keras`` archive, or not a model Keras can rebuild.
    """
    return load_keras_model(path)


def crop_object(image: np.ndarray, box, size: int, padding: float = 1.2) -> np.ndarray:
    """Square crop around ``box`` resized to ``(size, size[, C])``, zero outside the image.

    The window is :func:`paz6d.backend.square_crop.square_window` (side ``padding * max(w, h)``, integer
    corner) resampled by :func:`paz6d.backend.square_crop.crop_square`: the same crops ``paz6d generate
    --crop-size`` writes (its margin is also 1.2).

    Args:
        image: ``(H, W, C)`` uint8 (RGB, or RGB + alpha).
        box: ``(x_min, y_min, x_max, y_max)`` pixels, box convention (pixel ``i`` covers ``[i, i+1)``).
        size: output side in pixels.
        padding: crop side / longest box side.
    """
    return crop_square(image, square_window(box, padding), size)
