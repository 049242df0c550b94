"""A small U-Net mask head: a square crop around a detection box -> one mask logit map per class.

Layout (``L = len(widths)`` levels)::

    crop (S, S, 3), RGB 0..255 -> rescaled to [-1, 1]
      encoder level i: two 3x3 conv + BN + ReLU (widths[i] channels), then 2x2 max-pool
      bottleneck: two 3x3 conv (2 * widths[-1])
      decoder level i (coarse to fine): x2 bilinear upsampling, concatenation with encoder level i, two 3x3 conv
      head: 1x1 conv -> C logits per pixel (one per class, as Mask R-CNN's class-conditioned masks)

Output ``(B, S, S, C)`` float32 logits at the crop's resolution; the detected class picks the channel
(:func:`pick_class`). Only built-in Keras layers, so models load with ``safe_mode=True``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from paz6d.backend.files import save_keras_model_atomically
from paz6d.backend.tensorflow_guard import import_keras, import_tensorflow, load_keras_model

tf = import_tensorflow()
keras = import_keras()


class SegmentationModelError(ValueError):
    """A mask-head model file is unusable."""


def _block(x, width: int, name: str):
    for index in (1, 2):
        x = keras.layers.Conv2D(width, 3, padding="same", use_bias=False, name=f"{name}_conv{index}")(x)
        x = keras.layers.BatchNormalization(name=f"{name}_bn{index}")(x)
        x = keras.layers.ReLU(name=f"{name}_relu{index}")(x)
    return x


def build_segmenter(num_classes: int, input_size: int = 64, widths: Sequence[int] = (16, 32, 64),
                    name: str = "mask_head"):
    """Builds the U-Net (module docstring).

    Args:
        num_classes: ``C`` output channels (1: class-agnostic masks).
        input_size: crop side ``S`` in pixels, a multiple of ``2 ** len(widths)``.
        widths: channels of the encoder levels, finest first.
    Returns:
        ``keras.Model``: ``(B, S, S, 3)`` float32 0..255 -> ``(B, S, S, C)`` logits.
    """
    widths = [int(width) for width in widths]
    if int(num_classes) < 1:
        raise ValueError(f"num_classes: expected a positive integer, got {num_classes}")
    if not widths or any(width < 1 for width in widths):
        raise ValueError(f"widths: expected positive channel counts, got {widths}")
    if int(input_size) <= 0 or int(input_size) % 2 ** len(widths):
        raise ValueError(f"input_size: expected a positive multiple of {2 ** len(widths)}, got {input_size}")
    inputs = keras.Input((input_size, input_size, 3), name="crops")
    x = keras.layers.Rescaling(1 / 127.5, offset=-1.0, name="rescale")(inputs)
    skips = []
    for level, width in enumerate(widths):
        x = _block(x, width, f"down{level}")
        skips.append(x)
        x = keras.layers.MaxPooling2D(2, name=f"pool{level}")(x)
    x = _block(x, 2 * widths[-1], "bottleneck")
    for level in reversed(range(len(widths))):
        x = keras.layers.UpSampling2D(2, interpolation="bilinear", name=f"up{level}")(x)
        x = keras.layers.Concatenate(name=f"skip{level}")([x, skips[level]])
        x = _block(x, widths[level], f"dec{level}")
    outputs = keras.layers.Conv2D(int(num_classes), 1, name="masks")(x)
    return keras.Model(inputs, outputs, name=name)


def pick_class(logits, class_ids):
    """``(B, S, S, C)`` logits and ``(B,)`` class indices -> ``(B, S, S)`` logits of each crop's class."""
    return tf.gather(logits, tf.cast(class_ids, tf.int32), axis=-1, batch_dims=1)


def mask_loss(logits, targets, class_ids):
    """Mean per-pixel sigmoid cross-entropy of each crop's class channel against ``targets (B, S, S)`` in {0, 1}."""
    picked = pick_class(logits, class_ids)
    return tf.reduce_mean(tf.nn.sigmoid_cross_entropy_with_logits(labels=tf.cast(targets, picked.dtype),
                                                                  logits=picked))


def mask_iou(logits, targets, class_ids):
    """Mean IoU of the thresholded (logit > 0) class channel against ``targets (B, S, S)``, per crop."""
    predicted = tf.cast(pick_class(logits, class_ids) > 0, tf.float32)
    targets = tf.cast(targets, tf.float32)
    intersection = tf.reduce_sum(predicted * targets, axis=(1, 2))
    union = tf.reduce_sum(tf.maximum(predicted, targets), axis=(1, 2))
    return tf.reduce_mean(tf.where(union > 0, intersection / tf.maximum(union, 1.0), 1.0))


def inference_function(model):
    """``crops (B, S, S, 3) -> probabilities (B, S, S, C) float32`` (a compiled sigmoid of the logits)."""

    @tf.function(reduce_retracing=True)
    def predict(crops):
        return tf.sigmoid(model(crops, training=False))

    return lambda crops: np.asarray(predict(tf.convert_to_tensor(np.asarray(crops, np.float32))))


def save_segmenter(model, path: str | Path) -> Path:
    """Saves the model (``.keras``, atomically)."""
    return save_keras_model_atomically(model, path)


def load_segmenter(path: str | Path, input_size: int, num_classes: int):
    """Loads a model and checks it maps ``(S, S, 3)`` crops to ``(S, S, num_classes)`` logits.

    Raises:
        SegmentationModelError: unreadable file or other shapes (the message names the file).
    """
    model = load_keras_model(path, SegmentationModelError)
    expected_in, expected_out = (None, input_size, input_size, 3), (None, input_size, input_size, num_classes)
    if tuple(model.input_shape) != expected_in or tuple(model.output_shape) != expected_out:
        raise SegmentationModelError(f"{path}: expected a model {expected_in} -> {expected_out} (as segmenter.json "
                                     f"says), got {model.input_shape} -> {model.output_shape}")
    return model
