"""mini-Xception (Arriaga, Valdenegro-Toro & Plöger 2017) for facial expression classification.

"Real-time Convolutional Neural Networks for Emotion and Gender Classification", arXiv:1710.07557:
two plain 3x3 convolutions, four residual modules of depthwise-separable convolutions (16, 32,
64, 128 filters, each halving the resolution), then a 3x3 convolution to one map per class,
global average pooling and softmax. No fully connected layers; about 58k parameters for
64x64x1 inputs and 7 classes. Inputs are grey images scaled to ``[-1, 1]`` (see
:func:`preprocess_faces`).

Importing this module imports TensorFlow (through the guard) and Keras.
"""

from __future__ import annotations

import numpy as np

from paz6d.backend.tensorflow_guard import import_keras

keras = import_keras()

MODULE_FILTERS = (16, 32, 64, 128)


def preprocess_faces(faces) -> np.ndarray:
    """``uint8`` grey faces ``(N, H, W)`` to the network input ``(N, H, W, 1)`` float32 in ``[-1, 1]``."""
    faces = np.asarray(faces)
    if faces.dtype != np.uint8 or faces.ndim != 3 or 0 in faces.shape:
        raise ValueError(f"faces: expected non-empty uint8 grey faces (N, H, W), got {faces.dtype} {faces.shape}")
    return (faces[..., None].astype(np.float32) / 255.0 - 0.5) * 2.0


def _residual_module(x, filters: int, regularizer, index: int):
    residual = keras.layers.Conv2D(filters, 1, strides=2, padding="same", use_bias=False,
                                   name=f"module{index}_shortcut_conv")(x)
    residual = keras.layers.BatchNormalization(name=f"module{index}_shortcut_bn")(residual)
    x = keras.layers.SeparableConv2D(filters, 3, padding="same", use_bias=False, depthwise_regularizer=regularizer,
                                     pointwise_regularizer=regularizer, name=f"module{index}_sepconv1")(x)
    x = keras.layers.BatchNormalization(name=f"module{index}_sepconv1_bn")(x)
    x = keras.layers.Activation("relu", name=f"module{index}_sepconv1_relu")(x)
    x = keras.layers.SeparableConv2D(filters, 3, padding="same", use_bias=False, depthwise_regularizer=regularizer,
                                     pointwise_regularizer=regularizer, name=f"module{index}_sepconv2")(x)
    x = keras.layers.BatchNormalization(name=f"module{index}_sepconv2_bn")(x)
    x = keras.layers.MaxPooling2D(3, strides=2, padding="same", name=f"module{index}_pool")(x)
    return keras.layers.Add(name=f"module{index}_add")([x, residual])


def mini_xception(input_shape: tuple[int, int, int] = (64, 64, 1), num_classes: int = 7,
                  l2_weight: float = 0.01, name: str = "mini_xception"):
    """Builds the mini-Xception classifier (Keras 3 functional model, softmax output ``(N, num_classes)``).

    Args:
        input_shape: ``(height, width, channels)``; 48x48x1 for FER2013, 64x64x1 for the ``fer`` weights.
        num_classes: number of expression classes (7 for FER2013).
        l2_weight: L2 penalty on every convolution kernel (0.01 in the paper's code).
    """
    shape = tuple(int(value) for value in input_shape)
    if len(shape) != 3 or min(shape) < 1:
        raise ValueError(f"input_shape: expected (height, width, channels) positive, got {input_shape}")
    if shape[0] < 16 or shape[1] < 16:
        raise ValueError(f"input_shape: expected height and width >= 16 (two 3x3 valid convolutions and "
                         f"four stride-2 modules), got {shape[:2]}")
    if int(num_classes) < 2:
        raise ValueError(f"num_classes: expected at least 2 classes, got {num_classes}")
    regularizer = keras.regularizers.L2(l2_weight) if l2_weight else None
    inputs = keras.Input(shape, name="face")
    x = inputs
    for index in (1, 2):
        x = keras.layers.Conv2D(8, 3, use_bias=False, kernel_regularizer=regularizer, name=f"stem_conv{index}")(x)
        x = keras.layers.BatchNormalization(name=f"stem_bn{index}")(x)
        x = keras.layers.Activation("relu", name=f"stem_relu{index}")(x)
    for index, filters in enumerate(MODULE_FILTERS, start=1):
        x = _residual_module(x, filters, regularizer, index)
    x = keras.layers.Conv2D(int(num_classes), 3, padding="same", name="class_conv")(x)
    x = keras.layers.GlobalAveragePooling2D(name="class_pool")(x)
    outputs = keras.layers.Activation("softmax", name="class_probabilities")(x)
    return keras.Model(inputs, outputs, name=name)
