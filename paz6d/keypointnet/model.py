"""KeypointNet: ordered 2D keypoints + depth from one object crop, and the paper's losses.

Suwajanakorn et al., "Discovery of Latent 3D Keypoints via End-to-end Geometric Reasoning"
(NeurIPS 2018). A fully convolutional network turns an RGB crop ``(S, S, 3)`` into ``N``
probability maps ``g_i`` (spatial softmax) and ``N`` depth maps ``d_i``; keypoint ``i`` is the
expectation ``[u_i, v_i] = sum g_i(u, v) [u, v]`` and ``z_i = sum g_i(u, v) d_i(u, v)``.

Units: ``uv`` are pixels of the input crop (OpenCV pixel-centre convention: column ``j`` is at
``u = j``). ``depth`` is a dimensionless code ``z_hat``; callers turn it into metres with
:func:`metres_from_depth_code` (``z = z_hat * depth_scale``, ``depth_scale = diameter * fx_crop / S``,
which makes ``z_hat`` about constant for box-centred crops of any size).

Losses (batch-mean scalars; coordinates in any consistent unit, e.g. pixels/``S``):

- :func:`consistency_loss` — multi-view consistency of 2D keypoints given the relative pose,
- :func:`relative_pose_loss` — angle between the Procrustes rotation and the true one,
- :func:`separation_loss` — hinge pushing 3D keypoints at least ``delta`` apart,
- :func:`silhouette_loss` — probability mass inside the object mask,
- :func:`variance_loss` — spread of each probability map about its keypoint,
- :func:`heatmap_loss` / :func:`coordinate_loss` — the supervised alternative.

Models save as ``.keras`` with only registered layers (no ``Lambda``), so loading runs with
``safe_mode=True``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from paz6d.backbones import check_backbone
from paz6d.backend.files import save_keras_model_atomically
from paz6d.backend.tensorflow_guard import (compiled_inference, import_keras, import_tensorflow, load_keras_model,
                                            output_names)
from paz6d.keypointnet.config import check_backbone_strides
from paz6d.training.precision import body_policy

tf = import_tensorflow()
keras = import_keras()

PACKAGE = "paz6d"
OUTPUT_NAMES = ("uv", "depth", "probabilities")
ORIENTATION_OUTPUTS = ("chart_logits", "chart")
#: The pretrained backbone's maps a KeypointNet on it reads, by stride: EfficientNet-Lite0's stage ends (16, 24
#: and 40 channels).
BACKBONE_SKIPS = {2: "block0_out", 4: "block2_out", 8: "block4_out"}
#: Name of the frozen backbone's nested model.
BACKBONE_LAYER = "keypointnet_backbone"


class KeypointNetError(ValueError):
    """A KeypointNet model file or configuration is unusable."""


def cell_centres(height: int, width: int, stride: int) -> np.ndarray:
    """Pixel coordinates ``(height, width, 2)`` of the centres of a stride-``stride`` feature grid.

    Feature cell ``(row, col)`` covers input pixels ``[col*stride, (col+1)*stride)``; with the
    pixel-centre convention its centre is at ``u = col*stride + (stride - 1) / 2``.
    """
    if height <= 0 or width <= 0 or stride <= 0:
        raise ValueError(f"height/width/stride: expected positive integers, got {height}, {width}, {stride}")
    offset = (stride - 1) / 2.0
    u = np.arange(width, dtype=np.float32) * stride + offset
    v = np.arange(height, dtype=np.float32) * stride + offset
    grid_u, grid_v = np.meshgrid(u, v)
    return np.stack([grid_u, grid_v], axis=-1)


@keras.saving.register_keras_serializable(package=PACKAGE)
class SpatialExpectation(keras.layers.Layer):
    """Spatial softmax + expectations: ``(logits, depth_maps)`` to ``(uv, depth, probabilities)``.

    Inputs are ``(B, h, w, N)`` each; outputs ``uv (B, N, 2)`` in input pixels, ``depth (B, N)``
    and ``probabilities (B, h, w, N)`` (each map sums to 1).

    Args:
        stride: input pixels per feature cell.
    """

    def __init__(self, stride: int = 1, **kwargs):
        super().__init__(**kwargs)
        self.stride = int(stride)

    def call(self, inputs):
        logits, depth_maps = inputs
        shape = tf.shape(logits)
        batch, height, width, count = shape[0], shape[1], shape[2], shape[3]
        flat = tf.reshape(tf.transpose(logits, [0, 3, 1, 2]), [batch, count, height * width])
        probabilities_flat = tf.nn.softmax(flat, axis=-1)
        offset = (self.stride - 1) / 2.0
        u = tf.cast(tf.range(width), logits.dtype) * self.stride + offset
        v = tf.cast(tf.range(height), logits.dtype) * self.stride + offset
        grid_u, grid_v = tf.meshgrid(u, v)
        grid = tf.stack([tf.reshape(grid_u, [-1]), tf.reshape(grid_v, [-1])], axis=-1)
        uv = tf.einsum("bnp,pc->bnc", probabilities_flat, grid)
        depth_flat = tf.reshape(tf.transpose(depth_maps, [0, 3, 1, 2]), [batch, count, height * width])
        depth = tf.reduce_sum(probabilities_flat * depth_flat, axis=-1)
        probabilities = tf.transpose(tf.reshape(probabilities_flat, [batch, count, height, width]), [0, 2, 3, 1])
        return uv, depth, probabilities

    def compute_output_shape(self, input_shape):
        batch, height, width, count = input_shape[0]
        return (batch, count, 2), (batch, count), (batch, height, width, count)

    def get_config(self):
        return {**super().get_config(), "stride": self.stride}


@keras.saving.register_keras_serializable(package=PACKAGE)
class ChartCondition(keras.layers.Layer):
    """Conditions features on an orientation chart (:mod:`paz6d.keypointnet.orientation`).

    Inputs ``[features (B, h, w, C), chart_logits (B, 3)]`` or, to force the chart in training,
    ``[features, chart_logits, chart (B, 3) one-hot]``. The chart used is the forced one, else the
    predicted ``argmax`` (no gradient flows through the choice); a learned vector per chart is added to
    every feature cell. Outputs ``(conditioned features, chart one-hot (B, 3) float32)``.
    """

    def build(self, input_shape):
        self.embedding = self.add_weight(shape=(int(input_shape[1][-1]), int(input_shape[0][-1])),
                                         initializer="zeros", name="embedding")

    def call(self, inputs):
        features, logits = inputs[0], inputs[1]
        if len(inputs) == 3:
            chart = tf.cast(inputs[2], tf.float32)
        else:
            chart = tf.one_hot(tf.argmax(logits, axis=-1), tf.shape(logits)[-1], dtype=tf.float32)
        chart = tf.stop_gradient(chart)
        offset = tf.matmul(chart, tf.cast(self.embedding, tf.float32))
        return features + tf.cast(offset, features.dtype)[:, None, None, :], chart

    def compute_output_shape(self, input_shape):
        return input_shape[0], input_shape[1]


def build_keypointnet(num_keypoints: int = 10, input_size: int = 128, filters: int = 32,
                      downsample: int = 4, dilations: tuple[int, ...] = (1, 2, 4, 8, 1, 2, 4),
                      depth_prior: float = 1.3, context_stride: int | None = None, compute_dtype: str = "float32",
                      orientation: bool = False, backbone: str = "none", name: str = "keypointnet"):
    """Builds the KeypointNet Keras model.

    Args:
        num_keypoints: ``N`` ordered keypoints.
        input_size: crop side ``S`` in pixels; inputs are ``(B, S, S, 3)`` RGB values 0..255.
        filters: channels of every convolution.
        downsample: stride of the probability maps (1, 2, 4 or 8): maps are ``S / downsample`` cells
            wide. Sub-cell precision comes from the expectation.
        dilations: dilation rate of each 3×3 convolution of the dilated (context) stack.
        depth_prior: initial value of the depth code ``z_hat`` (about the crop margin factor).
        context_stride: stride at which the dilated stack runs (default ``downsample``; up to 8). When
            coarser than ``downsample``, its output is brought back to ``downsample`` level by level: ×2
            bilinear upsampling, plus the stem's features of that level, then a 3×3 convolution (a
            light U-Net decoder). Finer maps for little more compute than the coarse stack.
        compute_dtype: ``"float32"`` or ``"bfloat16"``: the convolutional body computes in bfloat16
            with float32 weights (Keras ``mixed_bfloat16``; faster on CPUs with native bf16 such as
            AVX512-BF16/AMX, see :mod:`paz6d.training.precision`); the 1×1 heads and the spatial softmax and
            expectation always run in float32, so keypoints keep sub-pixel resolution.
        orientation: add the orientation network for a 2-fold symmetric object
            (:mod:`paz6d.keypointnet.orientation`): three strided convolutions on the stem's features,
            pooled, predict ``chart_logits (B, 3)``; the chosen ``chart (B, 3)`` conditions the dilated
            stack (:class:`ChartCondition`).
        backbone: ``"efficientnet-lite0"``: the stem and the strided convolutions are the frozen ImageNet
            EfficientNet-Lite0 (:mod:`paz6d.backbones`) instead: its maps of the strides from ``downsample``
            to 8 (:data:`BACKBONE_SKIPS`), each through a 3×3 convolution to ``filters`` channels, feed the
            dilated stack (stride 8) and the decoder's skips. Needs ``context_stride`` 8 and ``downsample``
            of at least 2.
    Returns:
        ``keras.Model`` with outputs ``{"uv": (B, N, 2), "depth": (B, N), "probabilities": (B, h, w, N)}``.
        With ``orientation``: ``(model, forcing)``, ``model`` adding outputs ``"chart_logits"`` and
        ``"chart"``, and ``forcing`` the same network (shared layers) with inputs ``[image, chart]``
        whose ``chart (B, 3)`` one-hot replaces the predicted chart (for training).
    """
    context_stride = downsample if context_stride is None else int(context_stride)
    check_backbone(backbone)
    if num_keypoints < 1:
        raise ValueError(f"num_keypoints: expected a positive integer, got {num_keypoints}")
    if downsample not in (1, 2, 4, 8):
        raise ValueError(f"downsample: expected 1, 2, 4 or 8, got {downsample}")
    if context_stride not in (1, 2, 4, 8) or context_stride < downsample:
        raise ValueError(f"context_stride: expected 1, 2, 4 or 8 and >= downsample={downsample}, got {context_stride}")
    if input_size < 8 or input_size % context_stride:
        raise ValueError(f"input_size: expected a multiple of {context_stride} (the coarsest stride) and >= 8, "
                         f"got {input_size}")
    if filters < 1 or not dilations or any(int(rate) < 1 for rate in dilations):
        raise ValueError(f"filters/dilations: expected filters >= 1 and positive dilation rates, "
                         f"got {filters}, {dilations}")
    check_backbone_strides(backbone, context_stride, downsample)
    body = body_policy(compute_dtype)
    layers = keras.layers
    made = {}

    def layer(name, make):
        """The layer called ``name``, made once (a second forward pass shares it)."""
        if name not in made:
            made[name] = make()
        return made[name]

    def conv_bn_relu(x, name, stride=1, rate=1):
        x = layer(f"{name}_conv", lambda: layers.Conv2D(filters, 3, strides=stride, dilation_rate=rate, padding="same",
                                                        use_bias=False, name=f"{name}_conv", dtype=body))(x)
        x = layer(f"{name}_bn", lambda: layers.BatchNormalization(name=f"{name}_bn", dtype=body))(x)
        return layer(f"{name}_relu", lambda: layers.ReLU(name=f"{name}_relu", dtype=body))(x)

    def own_body(image):
        """The stem and the strided convolutions: ``(map at context_stride, {stride: skip map})``."""
        x = layer("scale", lambda: layers.Rescaling(1.0 / 127.5, offset=-1.0, name="scale", dtype=body))(image)
        stride = min(context_stride, 2)
        x = conv_bn_relu(x, "stem", stride)
        skips = {stride: x}
        for level in range(int(math.log2(context_stride // stride))):
            x = conv_bn_relu(x, f"down{level}", 2)
            stride *= 2
            skips[stride] = x
        return x, skips

    def pretrained_body(image):
        """The frozen backbone's maps of strides ``downsample`` to 8, each projected to ``filters`` channels."""
        from paz6d.backbones import efficientnet_lite0 as lite0

        strides = [stride for stride in sorted(BACKBONE_SKIPS) if stride >= downsample]

        def make():
            features = lite0.build_features((input_size, input_size, 3), frozen_stages=len(lite0.STAGES))
            maps = [features.get_layer(BACKBONE_SKIPS[stride]).output for stride in strides]
            frozen = keras.Model(features.input, maps, name=BACKBONE_LAYER)
            frozen.trainable = False
            return frozen

        x = layer("backbone_preprocess", lambda: lite0.preprocess_layer("backbone_preprocess"))(image)
        maps = layer(BACKBONE_LAYER, make)(x, training=False)
        skips = {stride: conv_bn_relu(feature, f"project{stride}") for stride, feature in zip(strides, maps)}
        return skips[8], skips

    def forward(image, forced_chart=None):
        x, skips = own_body(image) if backbone == "none" else pretrained_body(image)
        stride = context_stride
        chart_outputs = {}
        if orientation:
            o = skips[min(skips)]
            for level in range(3):
                o = conv_bn_relu(o, f"orient{level}", 2)
            o = layer("orient_pool", lambda: layers.GlobalAveragePooling2D(name="orient_pool", dtype=body))(o)
            chart_logits = layer("chart_logits", lambda: layers.Dense(3, name="chart_logits", dtype="float32"))(o)
        if orientation:
            condition = layer("chart", lambda: ChartCondition(name="chart", dtype=body))
            x, chart = condition([x, chart_logits] if forced_chart is None else [x, chart_logits, forced_chart])
            chart_outputs = {"chart_logits": chart_logits, "chart": chart}
        for index, rate in enumerate(dilations):
            add = layer(f"dilated{index}_add", lambda: layers.Add(name=f"dilated{index}_add", dtype=body))
            x = add([x, conv_bn_relu(x, f"dilated{index}", rate=int(rate))])
        while stride > downsample:
            stride //= 2
            x = layer(f"up{stride}", lambda: layers.UpSampling2D(2, interpolation="bilinear", name=f"up{stride}",
                                                                 dtype=body))(x)
            add = layer(f"up{stride}_skip", lambda: layers.Add(name=f"up{stride}_skip", dtype=body))
            x = conv_bn_relu(add([x, skips[stride]]), f"up{stride}")
        logits = layer("logits", lambda: layers.Conv2D(num_keypoints, 1, name="logits", dtype="float32"))(x)
        depth_maps = layer("depth_maps", lambda: layers.Conv2D(
            num_keypoints, 1, name="depth_maps", kernel_initializer="zeros",
            bias_initializer=keras.initializers.Constant(depth_prior), dtype="float32"))(x)
        expectation = layer("expectation", lambda: SpatialExpectation(downsample, name="expectation", dtype="float32"))
        uv, depth, probabilities = expectation([logits, depth_maps])
        return {"uv": uv, "depth": depth, "probabilities": probabilities, **chart_outputs}

    image = keras.Input((input_size, input_size, 3), name="image")
    model = keras.Model(image, forward(image), name=name)
    if not orientation:
        return model
    chart = keras.Input((3,), name="forced_chart")
    forcing = keras.Model([image, chart], forward(image, chart), name=f"{name}_chart_forced")
    return model, forcing


def has_orientation(model) -> bool:
    """Whether ``model`` carries the orientation network (outputs ``chart_logits`` and ``chart``)."""
    return set(ORIENTATION_OUTPUTS) <= output_names(model)


def save_keypointnet(model, path: str | Path) -> Path:
    """Saves ``model`` to a ``.keras`` file (written to a temporary file, then renamed)."""
    return save_keras_model_atomically(model, path)


def load_keypointnet(path: str | Path):
    """Loads a model saved by :func:`save_keypointnet` in Keras safe mode (no code execution).

    Raises:
        KeypointNetError: missing, corrupt or non-KeypointNet file (message names the file).
    """
    return load_keras_model(path, KeypointNetError, outputs=(OUTPUT_NAMES, OUTPUT_NAMES + ORIENTATION_OUTPUTS),
                            kind="a KeypointNet")


def inference_function(model):
    """Compiled ``images (B, S, S, 3) float32 -> {"uv", "depth", "probabilities"}`` for inference
    (one ``tf.function`` trace for any batch size; several times faster than eager calls)."""
    return compiled_inference(model)


# --------------------------------------------------------------------------- geometry (batched TF)

def metres_from_depth_code(depth_code, diameter: float, K, input_size: int):
    """Depth code ``z_hat (B, N)`` to metres: ``z = z_hat * diameter * K[:, 0, 0] / input_size``.

    ``K (B, 3, 3)`` are the crops' intrinsics (pixels of the ``input_size`` crop).
    """
    K = tf.convert_to_tensor(K, tf.float32)
    return tf.convert_to_tensor(depth_code, tf.float32) * (diameter / input_size) * K[:, 0:1, 0]


def unproject(uv, depth, K):
    """Pixels ``(B, N, 2)`` at depths ``(B, N)`` through intrinsics ``(B, 3, 3)`` to camera points ``(B, N, 3)``."""
    uv = tf.convert_to_tensor(uv, tf.float32)
    depth = tf.convert_to_tensor(depth, tf.float32)
    K = tf.convert_to_tensor(K, tf.float32)
    fx, fy, cx, cy, skew = K[:, 0:1, 0], K[:, 1:2, 1], K[:, 0:1, 2], K[:, 1:2, 2], K[:, 0:1, 1]
    y = (uv[..., 1] - cy) / fy
    x = (uv[..., 0] - cx - skew * y) / fx
    return tf.stack([x * depth, y * depth, depth], axis=-1)


def project(points, K):
    """Camera points ``(B, N, 3)`` through intrinsics ``(B, 3, 3)`` to pixels ``(B, N, 2)``.

    Depths are clamped to at least 1e-6 so a bad prediction cannot divide by zero.
    """
    points = tf.convert_to_tensor(points, tf.float32)
    K = tf.convert_to_tensor(K, tf.float32)
    z = tf.maximum(points[..., 2], 1e-6)
    x, y = points[..., 0] / z, points[..., 1] / z
    u = K[:, 0:1, 0] * x + K[:, 0:1, 1] * y + K[:, 0:1, 2]
    v = K[:, 1:2, 1] * y + K[:, 1:2, 2]
    return tf.stack([u, v], axis=-1)


def transform_points(T, points):
    """Applies ``(B, 4, 4)`` rigid transforms to ``(B, N, 3)`` points."""
    T = tf.convert_to_tensor(T, tf.float32)
    points = tf.convert_to_tensor(points, tf.float32)
    return tf.einsum("bij,bnj->bni", T[:, :3, :3], points) + T[:, None, :3, 3]


def invert_transforms(T):
    """Inverse of ``(B, 4, 4)`` rigid transforms."""
    T = tf.convert_to_tensor(T, tf.float32)
    rotation_t = tf.transpose(T[:, :3, :3], [0, 2, 1])
    translation = -tf.einsum("bij,bj->bi", rotation_t, T[:, :3, 3])
    top = tf.concat([rotation_t, translation[:, :, None]], axis=-1)
    bottom = tf.tile(tf.constant([[[0.0, 0.0, 0.0, 1.0]]]), [tf.shape(T)[0], 1, 1])
    return tf.concat([top, bottom], axis=1)


def procrustes_rotation(points_a, points_b):
    """Rotation ``(B, 3, 3)`` best aligning centred ``points_a (B, N, 3)`` onto centred ``points_b``.

    Minimises ``sum_i ||R (a_i - mean a) - (b_i - mean b)||^2`` (Kabsch, reflection-corrected).
    """
    a = points_a - tf.reduce_mean(points_a, axis=1, keepdims=True)
    b = points_b - tf.reduce_mean(points_b, axis=1, keepdims=True)
    covariance = tf.einsum("bni,bnj->bij", a, b)
    _, u, v = tf.linalg.svd(covariance)
    sign = tf.sign(tf.linalg.det(tf.einsum("bij,bkj->bik", v, u)))
    sign = tf.where(sign == 0, tf.ones_like(sign), sign)
    correction = tf.linalg.diag(tf.stack([tf.ones_like(sign), tf.ones_like(sign), sign], axis=-1))
    return tf.einsum("bij,bjk,blk->bil", v, correction, u)


# --------------------------------------------------------------------------- discovery losses

def consistency_loss(uv_a, depth_a, uv_b, depth_b, K_a, K_b, T_a2b):
    """Multi-view consistency (paper eq. 1): mean over the batch of

    ``1/(2N) sum_i ||pi_b(T_a2b pi_a^-1(uv_a_i, z_a_i)) - uv_b_i||^2 + ||pi_a(T_b2a pi_b^-1(...)) - uv_a_i||^2``.

    Args:
        uv_a, uv_b: ``(B, N, 2)`` keypoints in views A and B (pixels of each view's ``K``).
        depth_a, depth_b: ``(B, N)`` keypoint depths (same length unit as ``T_a2b``).
        K_a, K_b: ``(B, 3, 3)`` intrinsics; T_a2b: ``(B, 4, 4)`` maps camera A to camera B points.
    """
    T_b2a = invert_transforms(T_a2b)
    a_in_b = project(transform_points(T_a2b, unproject(uv_a, depth_a, K_a)), K_b)
    b_in_a = project(transform_points(T_b2a, unproject(uv_b, depth_b, K_b)), K_a)
    squared = (tf.reduce_sum(tf.square(a_in_b - uv_b), axis=-1) +
               tf.reduce_sum(tf.square(b_in_a - uv_a), axis=-1))
    return tf.reduce_mean(tf.reduce_sum(squared, axis=-1) / (2.0 * tf.cast(tf.shape(squared)[-1], tf.float32)))


def relative_pose_loss(points_a, points_b, R_a2b):
    """Relative pose loss (paper eq. 2): mean of ``2 arcsin(||R_hat - R||_F / (2 sqrt 2))``, i.e. the
    angle (radians) between the Procrustes estimate ``R_hat`` from ``(B, N, 3)`` keypoints seen in
    cameras A and B and the true rotation ``R_a2b (B, 3, 3)``."""
    R_hat = procrustes_rotation(tf.convert_to_tensor(points_a, tf.float32), tf.convert_to_tensor(points_b, tf.float32))
    frobenius = tf.sqrt(tf.reduce_sum(tf.square(R_hat - tf.convert_to_tensor(R_a2b, tf.float32)), axis=[1, 2]) + 1e-12)
    return tf.reduce_mean(2.0 * tf.asin(tf.clip_by_value(frobenius / (2.0 * math.sqrt(2.0)), 0.0, 1.0 - 1e-6)))


def separation_loss(points, delta: float):
    """Separation loss (paper eq. 3): mean over the batch of
    ``1/N^2 sum_{i != j} max(0, delta^2 - ||X_i - X_j||^2)`` for ``(B, N, D)`` points (3D keypoints,
    or 2D image keypoints)."""
    points = tf.convert_to_tensor(points, tf.float32)
    difference = points[:, :, None, :] - points[:, None, :, :]
    squared = tf.reduce_sum(tf.square(difference), axis=-1)
    count = tf.shape(points)[1]
    off_diagonal = 1.0 - tf.eye(count, dtype=tf.float32)
    hinge = tf.maximum(0.0, delta ** 2 - squared) * off_diagonal
    return tf.reduce_mean(tf.reduce_sum(hinge, axis=[1, 2]) / tf.cast(count * count, tf.float32))


def silhouette_loss(probabilities, mask):
    """Silhouette loss (paper eq. 4): mean over the batch of ``1/N sum_i -log sum_uv b(u,v) g_i(u,v)``.

    Args:
        probabilities: ``(B, h, w, N)`` maps summing to 1.
        mask: ``(B, h, w)`` object occupancy in [0, 1] at the maps' resolution.
    """
    probabilities = tf.convert_to_tensor(probabilities, tf.float32)
    mask = tf.convert_to_tensor(mask, tf.float32)
    inside = tf.reduce_sum(probabilities * mask[..., None], axis=[1, 2])
    return tf.reduce_mean(-tf.math.log(inside + 1e-8))


def variance_loss(probabilities, uv, grid):
    """Variance loss (paper eq. 5): mean over batch and keypoints of ``sum_uv g_i ||[u, v] - uv_i||^2``.

    Args:
        probabilities: ``(B, h, w, N)``; uv: ``(B, N, 2)``; grid: ``(h, w, 2)`` cell centres in the
            unit of ``uv`` (see :func:`cell_centres`).
    """
    probabilities = tf.convert_to_tensor(probabilities, tf.float32)
    grid = tf.convert_to_tensor(grid, tf.float32)
    uv = tf.convert_to_tensor(uv, tf.float32)
    squared = tf.reduce_sum(tf.square(grid[None, :, :, None, :] - uv[:, None, None, :, :]), axis=-1)
    return tf.reduce_mean(tf.reduce_sum(probabilities * squared, axis=[1, 2]))


# --------------------------------------------------------------------------- supervised losses

def gaussian_heatmaps(uv, grid, sigma: float):
    """Normalised Gaussian targets ``(B, h, w, N)`` centred at ``uv (B, N, 2)`` on ``grid (h, w, 2)``.

    ``sigma`` is in the unit of ``uv``; each map sums to 1 (keypoints outside the grid still get a
    normalised map peaked at the nearest border cells).
    """
    uv = tf.convert_to_tensor(uv, tf.float32)
    grid = tf.convert_to_tensor(grid, tf.float32)
    squared = tf.reduce_sum(tf.square(grid[None, :, :, None, :] - uv[:, None, None, :, :]), axis=-1)
    logits = -squared / (2.0 * sigma ** 2)
    shape = tf.shape(logits)
    flat = tf.reshape(tf.transpose(logits, [0, 3, 1, 2]), [shape[0], shape[3], -1])
    maps = tf.reshape(tf.nn.softmax(flat, axis=-1), [shape[0], shape[3], shape[1], shape[2]])
    return tf.transpose(maps, [0, 2, 3, 1])


def heatmap_loss(probabilities, targets):
    """Cross-entropy ``-sum_uv t log g`` between target maps and predicted maps, both ``(B, h, w, N)``,
    averaged over batch and keypoints."""
    probabilities = tf.convert_to_tensor(probabilities, tf.float32)
    targets = tf.convert_to_tensor(targets, tf.float32)
    return tf.reduce_mean(-tf.reduce_sum(targets * tf.math.log(probabilities + 1e-8), axis=[1, 2]))


def coordinate_loss(uv, target_uv, weights=None):
    """Mean Euclidean distance between ``(B, N, 2)`` keypoints and targets, optionally weighted ``(B, N)``."""
    distance = tf.sqrt(tf.reduce_sum(tf.square(tf.convert_to_tensor(uv, tf.float32) -
                                               tf.convert_to_tensor(target_uv, tf.float32)), axis=-1) + 1e-12)
    if weights is None:
        return tf.reduce_mean(distance)
    weights = tf.convert_to_tensor(weights, tf.float32)
    return tf.reduce_sum(distance * weights) / tf.maximum(tf.reduce_sum(weights), 1e-8)
