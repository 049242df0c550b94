"""Probabilistic keypoints: KeypointNet (supervised, farthest-point keypoints) with a head that predicts a
2D Gaussian per keypoint, and the Gaussian negative log-likelihood.

The mean of keypoint ``i`` is KeypointNet's spatial expectation ``uv_i`` (crop pixels). Its covariance is
``Σ_i = L_i L_iᵀ`` with a lower-triangular Cholesky factor
``L_i = [[softplus(a_i) + ε, 0], [b_i, softplus(c_i) + ε]]`` (crop pixels, positive diagonal). The three
numbers ``(a_i, b_i, c_i)`` come from a 1×1 convolution of the network's last feature map, averaged
under keypoint ``i``'s probability map (gradients do not flow back into the map through this average:
the maps are trained by their own losses and the NLL's mean term).

Loss (:func:`gaussian_nll`): ``−log N(x | μ, Σ) = ½ ‖L⁻¹ (x − μ)‖² + log L₁₁ + log L₂₂ + log 2π``.

Models save as ``.keras`` with registered layers only; loading runs in Keras safe mode.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from paz6d.backend.files import save_keras_model_atomically
from paz6d.backend.tensorflow_guard import compiled_inference, load_keras_model
from paz6d.keypointnet.model import build_keypointnet, keras, tf

PACKAGE = "paz6d"
OUTPUT_NAMES = ("uv", "depth", "probabilities", "cholesky")
MIN_SIGMA = 0.05  # crop pixels: ε added to the Cholesky diagonal
INITIAL_SIGMA = 3.0  # crop pixels: the diagonal at initialisation


class ProbabilisticKeypointsError(ValueError):
    """A probabilistic-keypoint model file or configuration is unusable."""


def inverse_softplus(value: float) -> float:
    """``x`` with ``softplus(x) = value`` (``value > 0``)."""
    return float(value + math.log(-math.expm1(-value)))


@keras.saving.register_keras_serializable(package=PACKAGE)
class CholeskyFromMaps(keras.layers.Layer):
    """``[probabilities (B, h, w, N), parameter maps (B, h, w, 3N)] -> cholesky (B, N, 2, 2)``.

    Each keypoint's ``(a, b, c)`` is its parameter maps averaged under its probability map (held
    fixed), then ``L = [[softplus(a) + min_sigma, 0], [b, softplus(c) + min_sigma]]`` in crop pixels.
    """

    def __init__(self, min_sigma: float = MIN_SIGMA, **kwargs):
        super().__init__(**kwargs)
        if not float(min_sigma) >= 0:
            raise ValueError(f"min_sigma: expected a non-negative number of pixels, got {min_sigma}")
        self.min_sigma = float(min_sigma)

    def call(self, inputs):
        probabilities, maps = inputs
        probabilities = tf.stop_gradient(tf.cast(probabilities, tf.float32))
        shape = tf.shape(probabilities)
        maps = tf.reshape(tf.cast(maps, tf.float32), [shape[0], shape[1], shape[2], shape[3], 3])
        # a sum of products rather than tf.einsum, which the TFLite converter lowers wrongly (paz6d export)
        parameters = tf.reduce_sum(probabilities[..., None] * maps, axis=[1, 2])
        diagonal_1 = tf.nn.softplus(parameters[..., 0]) + self.min_sigma
        diagonal_2 = tf.nn.softplus(parameters[..., 2]) + self.min_sigma
        zero = tf.zeros_like(diagonal_1)
        rows = [tf.stack([diagonal_1, zero], axis=-1), tf.stack([parameters[..., 1], diagonal_2], axis=-1)]
        return tf.stack(rows, axis=-2)

    def compute_output_shape(self, input_shape):
        batch, _, _, count = input_shape[0]
        return batch, count, 2, 2

    def get_config(self):
        return {**super().get_config(), "min_sigma": self.min_sigma}


def build_probabilistic_keypointnet(num_keypoints: int = 16, input_size: int = 128, filters: int = 48,
                                    downsample: int = 4, dilations: tuple[int, ...] = (1, 2, 4, 1, 2, 4),
                                    context_stride: int | None = 8, compute_dtype: str = "float32",
                                    initial_sigma: float = INITIAL_SIGMA, name: str = "probabilistic_keypointnet"):
    """KeypointNet (:func:`paz6d.keypointnet.model.build_keypointnet`, same arguments) plus the Gaussian head.

    Returns:
        ``keras.Model`` with outputs ``{"uv": (B, N, 2), "depth": (B, N), "probabilities": (B, h, w, N),
        "cholesky": (B, N, 2, 2)}`` (crop pixels; ``Σ = L Lᵀ``, see :func:`covariance_from_cholesky`).
    """
    if not initial_sigma > MIN_SIGMA:
        raise ProbabilisticKeypointsError(f"initial_sigma: expected more than {MIN_SIGMA} pixels, got {initial_sigma}")
    base = build_keypointnet(num_keypoints, input_size, filters, downsample, tuple(dilations),
                             context_stride=context_stride, compute_dtype=compute_dtype)
    features = base.get_layer("logits").input
    start = inverse_softplus(initial_sigma - MIN_SIGMA)
    bias = np.tile([start, 0.0, start], num_keypoints).astype(np.float32)
    maps = keras.layers.Conv2D(3 * num_keypoints, 1, name="cholesky_maps", dtype="float32",
                               kernel_initializer=keras.initializers.RandomNormal(stddev=1e-3),
                               bias_initializer=keras.initializers.Constant(bias))(features)
    cholesky = CholeskyFromMaps(MIN_SIGMA, name="cholesky", dtype="float32")([base.output["probabilities"], maps])
    outputs = {**base.output, "cholesky": cholesky}
    return keras.Model(base.input, outputs, name=name)


def covariance_from_cholesky(cholesky):
    """``Σ = L Lᵀ`` for ``(..., 2, 2)`` Cholesky factors (numpy or TF in, same kind out)."""
    if isinstance(cholesky, np.ndarray):
        return cholesky @ np.swapaxes(cholesky, -1, -2)
    return tf.linalg.matmul(cholesky, cholesky, transpose_b=True)


def gaussian_nll_terms(uv, cholesky, target_uv):
    """Per-keypoint negative log-likelihood ``(B, N)`` of ``target_uv`` under ``N(uv, L Lᵀ)``.

    ``½ ‖L⁻¹ r‖² + log L₁₁ + log L₂₂ + log 2π`` with ``r = target − uv`` (solved by forward
    substitution: ``e₁ = r₁ / L₁₁``, ``e₂ = (r₂ − L₂₁ e₁) / L₂₂``).
    """
    uv = tf.convert_to_tensor(uv, tf.float32)
    cholesky = tf.convert_to_tensor(cholesky, tf.float32)
    residual = tf.convert_to_tensor(target_uv, tf.float32) - uv
    l11, l21, l22 = cholesky[..., 0, 0], cholesky[..., 1, 0], cholesky[..., 1, 1]
    e1 = residual[..., 0] / l11
    e2 = (residual[..., 1] - l21 * e1) / l22
    return 0.5 * (e1 * e1 + e2 * e2) + tf.math.log(l11) + tf.math.log(l22) + math.log(2.0 * math.pi)


def gaussian_nll(uv, cholesky, target_uv, weights=None):
    """Mean (optionally ``weights (B, N)``-weighted) of :func:`gaussian_nll_terms`."""
    terms = gaussian_nll_terms(uv, cholesky, target_uv)
    if weights is None:
        return tf.reduce_mean(terms)
    weights = tf.convert_to_tensor(weights, tf.float32)
    return tf.reduce_sum(terms * weights) / tf.maximum(tf.reduce_sum(weights), 1e-8)


def save_model(model, path: str | Path) -> Path:
    """Saves ``model`` to a ``.keras`` file (temporary file, then rename)."""
    return save_keras_model_atomically(model, path)


def load_model(path: str | Path):
    """Loads a model saved by :func:`save_model` in Keras safe mode.

    Raises:
        ProbabilisticKeypointsError: missing, corrupt or foreign file (the message names the file).
    """
    return load_keras_model(path, ProbabilisticKeypointsError, outputs=(OUTPUT_NAMES,),
                            kind="a probabilistic KeypointNet")


def inference_function(model):
    """Compiled ``images (B, S, S, 3) float32 -> outputs`` (one trace for any batch size)."""
    return compiled_inference(model)
