"""A small HRNet (Sun et al., "Deep High-Resolution Representation Learning for Human Pose Estimation",
CVPR 2019) for keypoint heatmaps of one object crop.

Layout (``B`` branches, ``widths[i]`` channels at stride ``4 · 2^i``)::

    crop (S, S, 3) ─ stem: 3×3/2, 3×3/2 convolutions + ``stem_blocks`` residual blocks (stride 4)
      stage 1 ─ transition: branch 0 (3×3 conv to widths[0]) + branch 1 (3×3/2 conv)
      stage k = 2..B: ``stage_modules[k-2]`` exchange modules over k branches, each module:
          every branch: ``blocks`` basic residual blocks (two 3×3 convolutions)
          fusion: branch i receives the sum of all branches brought to its resolution and width
                  (j > i: 1×1 conv + BN, bilinear ×2^(j-i) upsampling; j < i: (i-j) 3×3/2 convs + BN),
                  then ReLU
        then (k < B) a new branch: 3×3/2 conv of the coarsest branch
      head: 1×1 conv of branch 0 → N heatmaps (S/4 × S/4)

The last module of the last stage only fuses into branch 0 (the head's input), as HRNet's pose network.
Inputs are RGB values 0..255; outputs ``{"heatmaps": (B, S/4, S/4, N)}`` float32 — logits of a spatial
softmax or Gaussians of peak 1, depending on the training loss (:mod:`paz6d.hrnet.heatmaps`). Only
built-in Keras layers: models load with ``safe_mode=True``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from paz6d.backend.files import save_keras_model_atomically
from paz6d.backend.tensorflow_guard import (compiled_inference, import_keras, import_tensorflow, load_keras_model)
from paz6d.hrnet.config import STRIDE
from paz6d.training.precision import body_policy

tf = import_tensorflow()
keras = import_keras()

OUTPUT_NAME = "heatmaps"


class HRNetError(ValueError):
    """An HRNet model file or configuration is unusable."""


def _check_arguments(num_keypoints: int, input_size: int, widths: Sequence[int], stage_modules: Sequence[int],
                     blocks: int, stem_width: int, stem_blocks: int, compute_dtype: str) -> None:
    if num_keypoints < 1:
        raise ValueError(f"num_keypoints: expected a positive integer, got {num_keypoints}")
    if len(widths) < 2 or any(int(width) < 1 for width in widths):
        raise ValueError(f"widths: expected at least 2 positive channel counts (one per branch), got {tuple(widths)}")
    if len(stage_modules) != len(widths) - 1 or any(int(count) < 1 for count in stage_modules):
        raise ValueError(f"stage_modules: expected {len(widths) - 1} positive module counts (stages 2..{len(widths)}) "
                         f"for {len(widths)} branches, got {tuple(stage_modules)}")
    coarsest = STRIDE * 2 ** (len(widths) - 1)
    if input_size < coarsest or input_size % coarsest:
        raise ValueError(f"input_size: expected a multiple of {coarsest} (the coarsest branch's stride), got "
                         f"{input_size}")
    body_policy(compute_dtype)  # checks it
    if blocks < 1 or stem_width < 1 or stem_blocks < 0:
        raise ValueError(f"blocks/stem_width/stem_blocks: expected >= 1, >= 1, >= 0, got {blocks}, {stem_width}, "
                         f"{stem_blocks}")


def build_hrnet(num_keypoints: int, input_size: int = 128, widths: Sequence[int] = (24, 48, 96),
                stage_modules: Sequence[int] = (1, 2), blocks: int = 1, stem_width: int = 32, stem_blocks: int = 1,
                compute_dtype: str = "float32", name: str = "hrnet"):
    """Builds the HRNet Keras model (see the module docstring for the layout).

    Args:
        num_keypoints: ``N`` heatmaps.
        input_size: crop side ``S`` (a multiple of the coarsest branch's stride ``4 · 2^(B-1)``).
        widths: channels of each branch, highest resolution first (``B = len(widths) >= 2`` branches).
        stage_modules: exchange modules of stages 2..B (``B - 1`` counts).
        blocks: basic residual blocks per branch in each module.
        stem_width, stem_blocks: channels and residual blocks of the stride-4 stem.
        compute_dtype: ``"float32"`` or ``"bfloat16"`` (the body computes in bfloat16 with float32 weights;
            the head is float32).
    Returns:
        ``keras.Model``: ``(B, S, S, 3)`` → ``{"heatmaps": (B, S/4, S/4, N)}``. Layer names:
        ``stage{k}_module{m}_fuse{i}`` is branch ``i``'s output of module ``m`` of stage ``k``.
    """
    _check_arguments(num_keypoints, input_size, widths, stage_modules, blocks, stem_width, stem_blocks, compute_dtype)
    widths = [int(width) for width in widths]
    body = body_policy(compute_dtype)
    layers = keras.layers

    def conv_bn(x, filters, name, kernel=3, stride=1, relu=True):
        x = layers.Conv2D(filters, kernel, strides=stride, padding="same", use_bias=False, name=f"{name}_conv",
                          dtype=body)(x)
        x = layers.BatchNormalization(name=f"{name}_bn", dtype=body)(x)
        return layers.ReLU(name=f"{name}_relu", dtype=body)(x) if relu else x

    def basic_block(x, filters, name):
        y = conv_bn(x, filters, f"{name}_a")
        y = conv_bn(y, filters, f"{name}_b", relu=False)
        shortcut = x if x.shape[-1] == filters else conv_bn(x, filters, f"{name}_proj", kernel=1, relu=False)
        return layers.ReLU(name=f"{name}_out", dtype=body)(layers.Add(name=f"{name}_add", dtype=body)([y, shortcut]))

    def fuse(branches, outputs, name):
        fused = []
        for i in range(outputs):
            terms = []
            for j, x in enumerate(branches):
                if j == i:
                    terms.append(x)
                elif j > i:
                    y = conv_bn(x, widths[i], f"{name}_{j}to{i}", kernel=1, relu=False)
                    terms.append(layers.UpSampling2D(2 ** (j - i), interpolation="bilinear", name=f"{name}_{j}to{i}_up",
                                                     dtype=body)(y))
                else:
                    y = x
                    for step in range(i - j):
                        last = step == i - j - 1
                        y = conv_bn(y, widths[i] if last else widths[j], f"{name}_{j}to{i}_down{step}", stride=2,
                                    relu=not last)
                    terms.append(y)
            total = layers.Add(name=f"{name}{i}_sum", dtype=body)(terms)
            fused.append(layers.ReLU(name=f"{name}{i}", dtype=body)(total))
        return fused

    inputs = keras.Input((input_size, input_size, 3), name="image")
    x = layers.Rescaling(1.0 / 127.5, offset=-1.0, name="scale", dtype=body)(inputs)
    x = conv_bn(x, stem_width, "stem1", stride=2)
    x = conv_bn(x, stem_width, "stem2", stride=2)
    for index in range(stem_blocks):
        x = basic_block(x, stem_width, f"stem_block{index}")
    branches = [x if stem_width == widths[0] else conv_bn(x, widths[0], "transition1_0"),
                conv_bn(x, widths[1], "transition1_1", stride=2)]
    for stage, modules in enumerate(stage_modules, start=2):
        for module in range(modules):
            name = f"stage{stage}_module{module}"
            branches = [_repeat(basic_block, branch, widths[i], blocks, f"{name}_branch{i}")
                        for i, branch in enumerate(branches)]
            last = stage == len(widths) and module == modules - 1
            branches = fuse(branches, 1 if last else len(branches), f"{name}_fuse")
        if stage < len(widths):
            branches.append(conv_bn(branches[-1], widths[stage], f"transition{stage}_{stage}", stride=2))
    heatmaps = layers.Conv2D(num_keypoints, 1, name="heatmaps", dtype="float32")(branches[0])
    return keras.Model(inputs, {OUTPUT_NAME: heatmaps}, name=name)


def _repeat(block, x, filters: int, count: int, name: str):
    for index in range(count):
        x = block(x, filters, f"{name}_block{index}")
    return x


def save_hrnet(model, path: str | Path) -> Path:
    """Saves ``model`` to a ``.keras`` file (temporary file, then rename)."""
    return save_keras_model_atomically(model, path)


def load_hrnet(path: str | Path):
    """Loads a model saved by :func:`save_hrnet` in Keras safe mode (no code execution).

    Raises:
        HRNetError: missing, corrupt or non-HRNet file (the message names the file).
    """
    return load_keras_model(path, HRNetError, outputs=((OUTPUT_NAME,),), kind="an HRNet")


def inference_function(model):
    """Compiled ``images (B, S, S, 3) float32 (0..255) -> heatmaps (B, S/4, S/4, N)`` numpy-ready tensor
    (one ``tf.function`` trace for any batch size)."""
    return compiled_inference(model, OUTPUT_NAME)


# --------------------------------------------------------------------------- losses (batched TF)

def gaussian_targets(uv, height: int, width: int, stride: int, sigma: float):
    """Gaussians of peak 1 ``(B, height, width, N)`` at keypoints ``uv (B, N, 2)`` (crop pixels); ``sigma``
    in heatmap cells (TensorFlow twin of :func:`paz6d.hrnet.heatmaps.gaussian_heatmaps`)."""
    uv = tf.convert_to_tensor(uv, tf.float32)
    u = tf.range(width, dtype=tf.float32) * stride + (stride - 1) / 2.0
    v = tf.range(height, dtype=tf.float32) * stride + (stride - 1) / 2.0
    du = (u[None, None, :, None] - uv[:, None, None, :, 0]) / stride
    dv = (v[None, :, None, None] - uv[:, None, None, :, 1]) / stride
    return tf.exp(-(tf.square(du) + tf.square(dv)) / (2.0 * sigma ** 2))


def softmax_heatmap_loss(logits, targets):
    """Cross-entropy ``-Σ t log softmax(logits)`` over each map, targets normalised to sum 1; mean over
    batch and keypoints. Both ``(B, h, w, N)``."""
    logits = tf.cast(logits, tf.float32)
    shape = tf.shape(logits)
    flat_logits = tf.reshape(tf.transpose(logits, [0, 3, 1, 2]), [shape[0], shape[3], -1])
    flat_targets = tf.reshape(tf.transpose(tf.convert_to_tensor(targets, tf.float32), [0, 3, 1, 2]),
                              [shape[0], shape[3], -1])
    flat_targets = flat_targets / tf.maximum(tf.reduce_sum(flat_targets, axis=-1, keepdims=True), 1e-12)
    return tf.reduce_mean(-tf.reduce_sum(flat_targets * tf.nn.log_softmax(flat_logits, axis=-1), axis=-1))


def mse_heatmap_loss(heatmaps, targets):
    """HRNet's loss: mean squared error between ``(B, h, w, N)`` maps and peak-1 Gaussians, × 1000 (so
    that logged values are readable; Adam is invariant to the scale)."""
    difference = tf.cast(heatmaps, tf.float32) - tf.convert_to_tensor(targets, tf.float32)
    return 1000.0 * tf.reduce_mean(tf.square(difference))


def argmax_keypoints(heatmaps, stride: int):
    """Centres ``(B, N, 2)`` (crop pixels) of each map's largest cell (for training logs)."""
    heatmaps = tf.cast(heatmaps, tf.float32)
    shape = tf.shape(heatmaps)
    flat = tf.reshape(tf.transpose(heatmaps, [0, 3, 1, 2]), [shape[0], shape[3], -1])
    index = tf.argmax(flat, axis=-1, output_type=tf.int32)
    rows, columns = index // shape[2], index % shape[2]
    centre = (stride - 1) / 2.0
    return tf.stack([tf.cast(columns, tf.float32) * stride + centre, tf.cast(rows, tf.float32) * stride + centre],
                    axis=-1)
