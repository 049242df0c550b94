"""Spatial transformer networks (Jaderberg et al., "Spatial Transformer Networks", NeurIPS 2015).

A localisation network looks at the input and predicts an affine transform ``theta (B, 2, 3)``; a
differentiable bilinear sampler (:class:`BilinearSampler`) resamples the input on the transformed
grid, and a classifier sees the resampled crop. Gradients reach ``theta`` (through the bilinear
weights) and the image.

Coordinates: ``theta`` maps *normalised output* coordinates to *normalised input* coordinates,
``[x_s, y_s] = theta @ [x_t, y_t, 1]``, where ``-1``/``+1`` are the outer edges of the first/last
pixel (PyTorch's ``align_corners=False``): pixel column ``j`` of a ``W``-wide image has its centre at
``x = (2 j + 1) / W - 1``. The identity ``[[1, 0, 0], [0, 1, 0]]`` with an output of the input's size
returns the input exactly; ``x_s = x_t + t`` shifts the content by ``-t W / 2`` pixels.

Padding: ``"zeros"`` (neighbours outside the image count as 0, as OpenCV ``BORDER_CONSTANT``) or
``"border"`` (neighbour indices clamped to the image, as ``BORDER_REPLICATE``).

Models save as ``.keras`` with only registered layers (no ``Lambda``); loading runs with ``safe_mode=True``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from paz6d.backend.files import save_keras_model_atomically
from paz6d.backend.tensorflow_guard import (compiled_inference, import_keras, import_tensorflow, load_keras_model)
from paz6d.stn.config import PADDINGS

tf = import_tensorflow()
keras = import_keras()

PACKAGE = "paz6d"
IDENTITY = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], np.float32)
#: Output names of a classifier with the transformer (without it: only the first two).
OUTPUT_NAMES = ("logits", "probabilities", "theta", "crop")


class STNModelError(ValueError):
    """A spatial-transformer model file or configuration is unusable."""


def affine_grid(theta, height: int, width: int):
    """Normalised input coordinates ``(B, height, width, 2)`` (x, y) of every output pixel centre.

    Args:
        theta: ``(B, 2, 3)`` affine maps from normalised output to normalised input coordinates.
        height, width: output size in pixels.
    """
    theta = tf.convert_to_tensor(theta)
    dtype = theta.dtype
    x = (2.0 * tf.range(width, dtype=dtype) + 1.0) / tf.cast(width, dtype) - 1.0
    y = (2.0 * tf.range(height, dtype=dtype) + 1.0) / tf.cast(height, dtype) - 1.0
    grid_x, grid_y = tf.meshgrid(x, y)
    homogeneous = tf.stack([grid_x, grid_y, tf.ones_like(grid_x)], axis=-1)  # (h, w, 3)
    return tf.einsum("bij,hwj->bhwi", theta, homogeneous)


def bilinear_sample(images, coordinates, padding: str = "zeros"):
    """Samples ``images (B, H, W, C)`` at normalised ``coordinates (B, h, w, 2)`` (x, y) bilinearly.

    Returns ``(B, h, w, C)`` in the images' dtype; see the module docstring for the coordinate and
    padding conventions.
    """
    if padding not in PADDINGS:
        raise ValueError(f"padding: expected one of {PADDINGS}, got {padding!r}")
    images = tf.convert_to_tensor(images)
    coordinates = tf.cast(coordinates, images.dtype)
    shape = tf.shape(images)
    height, width = shape[1], shape[2]
    dtype = images.dtype
    # normalised -> pixel coordinates (pixel centres at integers)
    x = ((coordinates[..., 0] + 1.0) * tf.cast(width, dtype) - 1.0) / 2.0
    y = ((coordinates[..., 1] + 1.0) * tf.cast(height, dtype) - 1.0) / 2.0
    x0, y0 = tf.floor(x), tf.floor(y)
    weight_x1, weight_y1 = x - x0, y - y0
    weight_x0, weight_y0 = 1.0 - weight_x1, 1.0 - weight_y1
    x0, y0 = tf.cast(x0, tf.int32), tf.cast(y0, tf.int32)
    result = 0.0
    for dx, weight_x in ((0, weight_x0), (1, weight_x1)):
        for dy, weight_y in ((0, weight_y0), (1, weight_y1)):
            column, row = x0 + dx, y0 + dy
            inside = (column >= 0) & (column < width) & (row >= 0) & (row < height)
            column = tf.clip_by_value(column, 0, width - 1)
            row = tf.clip_by_value(row, 0, height - 1)
            values = tf.gather_nd(images, tf.stack([row, column], axis=-1), batch_dims=1)  # (B, h, w, C)
            weight = weight_x * weight_y
            if padding == "zeros":
                weight = weight * tf.cast(inside, dtype)
            result = result + values * weight[..., None]
    return result


def affine_sample(images, theta, size: tuple[int, int] | None = None, padding: str = "zeros"):
    """``images (B, H, W, C)`` resampled through ``theta (B, 2, 3)`` to ``size = (height, width)``
    (default: the input size)."""
    images = tf.convert_to_tensor(images)
    if size is None:
        shape = tf.shape(images)
        size = (shape[1], shape[2])
    return bilinear_sample(images, affine_grid(tf.cast(theta, images.dtype), size[0], size[1]), padding)


def theta_to_pixel_matrix(theta, input_size: tuple[int, int], output_size: tuple[int, int]) -> np.ndarray:
    """The ``(2, 3)`` map from output *pixel* to input *pixel* coordinates equal to ``theta`` (numpy),
    e.g. for ``cv2.warpAffine(..., flags=cv2.WARP_INVERSE_MAP)``.

    Args:
        theta: ``(2, 3)`` normalised map; input_size, output_size: ``(height, width)`` pixels.
    """
    theta = np.asarray(theta, dtype=np.float64).reshape(2, 3)
    (in_h, in_w), (out_h, out_w) = input_size, output_size
    # pixel -> normalised: x = (2 j + 1) / W - 1 = A_out @ [j, i, 1]; normalised -> pixel: j = ((x + 1) W - 1) / 2
    to_normalised = np.array([[2.0 / out_w, 0.0, 1.0 / out_w - 1.0], [0.0, 2.0 / out_h, 1.0 / out_h - 1.0],
                              [0.0, 0.0, 1.0]])
    to_pixels = np.array([[in_w / 2.0, 0.0, (in_w - 1.0) / 2.0], [0.0, in_h / 2.0, (in_h - 1.0) / 2.0]])
    return to_pixels @ np.vstack([theta, [0.0, 0.0, 1.0]]) @ to_normalised


@keras.saving.register_keras_serializable(package=PACKAGE)
class BilinearSampler(keras.layers.Layer):
    """``[images (B, H, W, C), theta (B, 2, 3)] -> (B, height, width, C)``: the differentiable sampler.

    Args:
        output_size: ``(height, width)`` of the output in pixels (default: the input's).
        padding: ``"zeros"`` or ``"border"``.
    """

    def __init__(self, output_size: tuple[int, int] | None = None, padding: str = "zeros", **kwargs):
        super().__init__(**kwargs)
        if padding not in PADDINGS:
            raise ValueError(f"padding: expected one of {PADDINGS}, got {padding!r}")
        if output_size is not None:
            output_size = tuple(int(side) for side in output_size)
            if len(output_size) != 2 or min(output_size) < 1:
                raise ValueError(f"output_size: expected (height, width) positive pixels, got {output_size}")
        self.output_size, self.padding = output_size, padding

    def call(self, inputs):
        images, theta = inputs
        return affine_sample(images, theta, self.output_size, self.padding)

    def compute_output_shape(self, input_shape):
        (batch, height, width, channels), _ = input_shape
        if self.output_size is not None:
            height, width = self.output_size
        return batch, height, width, channels

    def get_config(self):
        return {**super().get_config(), "output_size": self.output_size, "padding": self.padding}


@keras.saving.register_keras_serializable(package=PACKAGE)
class AffineFromParameters(keras.layers.Layer):
    """``(B, 6) -> theta (B, 2, 3) = identity + scale * parameters``.

    With a zero-initialised layer before it the transformer starts as the identity; ``scale`` < 1
    slows the transform's updates relative to the rest of the network (the usual lower learning
    rate of the localisation head, for Adam-like optimisers).
    """

    def __init__(self, scale: float = 1.0, **kwargs):
        super().__init__(**kwargs)
        if not float(scale) > 0:
            raise ValueError(f"scale: expected a positive factor, got {scale}")
        self.scale = float(scale)

    def call(self, parameters):
        identity = tf.constant(IDENTITY.reshape(1, 6), dtype=parameters.dtype)
        return tf.reshape(identity + self.scale * parameters, [-1, 2, 3])

    def compute_output_shape(self, input_shape):
        return input_shape[0], 2, 3

    def get_config(self):
        return {**super().get_config(), "scale": self.scale}


def localisation_network(inputs, filters: int = 20, hidden: int = 50, theta_scale: float = 0.1, name: str = "loc"):
    """The localisation network on ``inputs (B, H, W, C)``: max-pool ×2, two 5×5 conv + ×2 pool
    stages, a dense layer and a zero-initialised 6-unit head, so ``theta`` starts at the identity.
    Returns the ``theta (B, 2, 3)`` tensor."""
    layers = keras.layers
    x = layers.MaxPooling2D(2, name=f"{name}_pool0")(inputs)
    for index in (1, 2):
        x = layers.Conv2D(filters, 5, padding="same", activation="relu", name=f"{name}_conv{index}")(x)
        x = layers.MaxPooling2D(2, name=f"{name}_pool{index}")(x)
    x = layers.Flatten(name=f"{name}_flatten")(x)
    x = layers.Dense(hidden, activation="relu", name=f"{name}_dense")(x)
    parameters = layers.Dense(6, kernel_initializer="zeros", bias_initializer="zeros", name=f"{name}_parameters")(x)
    return AffineFromParameters(theta_scale, name="theta")(parameters)


def build_classifier(num_classes: int = 10, input_size: int = 48, transformer: bool = True,
                     crop_size: int | None = None, filters: int = 32, padding: str = "zeros",
                     theta_scale: float = 0.1, name: str | None = None):
    """A small CNN classifier of grey images, with or without a spatial transformer in front.

    Args:
        num_classes: ``C`` classes.
        input_size: side ``S`` of the square grey input ``(B, S, S, 1)``, values in [0, 1].
        transformer: put a localisation network + :class:`BilinearSampler` before the classifier.
        crop_size: side of the transformer's output (default ``S``: the classifier is then the same
            network with and without the transformer).
        filters: channels of the first convolution (doubled in the later ones).
        padding: the sampler's padding.
        theta_scale: see :class:`AffineFromParameters`.
    Returns:
        ``keras.Model`` with outputs ``{"logits": (B, C), "probabilities": (B, C)}`` and, with the
        transformer, ``"theta": (B, 2, 3)`` and ``"crop": (B, crop, crop, 1)``.
    """
    if int(num_classes) < 2:
        raise STNModelError(f"num_classes: expected at least 2 classes, got {num_classes}")
    crop_size = int(input_size if crop_size is None else crop_size)
    if int(input_size) < 16 or crop_size < 16:
        raise STNModelError(f"input_size/crop_size: expected at least 16 pixels, got {input_size}, {crop_size}")
    if int(filters) < 1:
        raise STNModelError(f"filters: expected a positive number of channels, got {filters}")
    if padding not in PADDINGS:
        raise STNModelError(f"padding: expected one of {PADDINGS}, got {padding!r}")
    layers = keras.layers
    inputs = keras.Input((input_size, input_size, 1), name="image")
    outputs = {}
    x = inputs
    if transformer:
        theta = localisation_network(inputs, theta_scale=theta_scale)
        x = BilinearSampler((crop_size, crop_size), padding, name="sampler")([inputs, theta])
        outputs.update(theta=theta, crop=x)
    x = layers.Rescaling(2.0, offset=-1.0, name="scale")(x)  # [0, 1] -> [-1, 1] (after the zero padding)
    for index, width in enumerate((filters, 2 * filters, 2 * filters)):
        x = layers.Conv2D(width, 3, padding="same", activation="relu", name=f"conv{index}")(x)
        x = layers.MaxPooling2D(2, name=f"pool{index}")(x)
    x = layers.Flatten(name="flatten")(x)
    x = layers.Dense(128, activation="relu", name="dense")(x)
    logits = layers.Dense(num_classes, name="logits")(x)
    outputs = {"logits": logits, "probabilities": layers.Softmax(name="probabilities")(logits), **outputs}
    default = "stn_classifier" if transformer else "cnn_classifier"
    return keras.Model(inputs, outputs, name=name or default)


def has_transformer(model) -> bool:
    """Whether ``model`` (from :func:`build_classifier`) has the transformer (a ``"crop"`` output)."""
    return isinstance(model.output, dict) and "crop" in model.output


def save_classifier(model, path: str | Path) -> Path:
    """Saves ``model`` to a ``.keras`` file (temporary file, then rename)."""
    return save_keras_model_atomically(model, path)


def load_classifier(path: str | Path):
    """Loads a model saved by :func:`save_classifier` in Keras safe mode.

    Raises:
        STNModelError: missing, corrupt or foreign file (the message names the file).
    """
    return load_keras_model(path, STNModelError, outputs=(OUTPUT_NAMES, OUTPUT_NAMES[:2]), kind="a classifier")


def inference_function(model):
    """Compiled ``images (B, S, S, 1) float32 -> outputs`` (one trace for any batch size)."""
    return compiled_inference(model)
