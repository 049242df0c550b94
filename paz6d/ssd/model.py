"""SSD (Liu et al., "SSD: Single Shot MultiBox Detector", ECCV 2016) networks, randomly initialised.

Three architectures share one head and one output layout:

- ``"ssd300"``: VGG16 body (conv1_1 ... conv5_3, pool5 3x3/1, dilated fc6, fc7 as convolutions) with an
  L2-normalised conv4_3 (learned per-channel scale, initialised to 20), four extra blocks; feature maps
  38, 19, 10, 5, 3, 1 and the paper's prior boxes.
- ``"ssd512"``: the same body on 512 x 512 inputs, five extra blocks; feature maps 64, 32, 16, 8, 4, 2, 1.
- ``"light"``: a CPU configuration (input side :data:`~paz6d.ssd.config.DEFAULT_INPUT_SIZE` by default):
  MobileNet-style depthwise-separable body with batch normalisation, ``width`` channels scaling, feature
  maps of stride 8, 16, 32, 64 and two more, and depthwise-separable heads; priors sized for small
  objects. With a ``backbone`` (:data:`BACKBONES`), a pretrained ImageNet network (:mod:`paz6d.backbones`)
  replaces its body up to stride 32 (the same six maps, priors and heads; the extra maps are the light
  network's).

The model maps ``images (B, S, S, 3)`` float32 (normalised with :data:`IMAGE_MEAN`/:data:`IMAGE_STD`, or a
backbone's own scaling: :func:`input_normalization`, :func:`normalize_images`) to ``(B, P, 4 + C)``: per
prior, the 4 box offsets (encoded as in :func:`paz6d.backend.boxes.encode`) then ``C`` class logits, class 0
being the background. Priors (:func:`priors_for`) are in the same order: feature map, then cell
(row-major), then prior shape.

Models save as ``.keras`` with only registered layers (no ``Lambda``): loading runs in safe mode.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from paz6d.backbones import efficientnet_lite0 as lite0
from paz6d.backend.boxes import prior_boxes
from paz6d.backend.files import save_keras_model_atomically
from paz6d.backend.image import normalize
from paz6d.backend.tensorflow_guard import compiled_inference, import_keras, import_tensorflow, load_keras_model
from paz6d.ssd.config import BACKBONES, check_input_size, check_light_side

tf = import_tensorflow()
keras = import_keras()

PACKAGE = "paz6d"
#: Input normalisation: ``(image / 255 - IMAGE_MEAN) / IMAGE_STD`` per channel (RGB).
IMAGE_MEAN = (0.485, 0.456, 0.406)
IMAGE_STD = (0.229, 0.224, 0.225)
#: Name of the nested backbone model inside an SSD built with a ``backbone``.
BACKBONE_LAYER = "backbone"


class SSDModelError(ValueError):
    """An SSD model file or architecture setting is unusable."""


@dataclass(frozen=True)
class PriorSpec:
    """Prior boxes of every feature map (pixels of the square network input).

    Attributes:
        input_size: side of the network input.
        feature_map_sizes: side of each feature map.
        steps: pixels between neighbouring cell centres, per map.
        min_sizes, max_sizes: prior sides per map (a ``min`` square, a ``sqrt(min * max)`` square).
        aspect_ratios: per map, the extra ratios ``r`` (each gives an ``r`` and a ``1/r`` box).
    """

    input_size: int
    feature_map_sizes: tuple[int, ...]
    steps: tuple[float, ...]
    min_sizes: tuple[float, ...]
    max_sizes: tuple[float, ...]
    aspect_ratios: tuple[tuple[float, ...], ...]

    @property
    def priors_per_cell(self) -> tuple[int, ...]:
        return tuple(2 + 2 * len(ratios) for ratios in self.aspect_ratios)

    def to_dict(self) -> dict:
        return {key: [list(item) for item in value] if key == "aspect_ratios" else
                (list(value) if isinstance(value, tuple) else value) for key, value in asdict(self).items()}

    @classmethod
    def from_dict(cls, data: dict) -> "PriorSpec":
        try:
            return cls(int(data["input_size"]), tuple(int(v) for v in data["feature_map_sizes"]),
                       tuple(float(v) for v in data["steps"]), tuple(float(v) for v in data["min_sizes"]),
                       tuple(float(v) for v in data["max_sizes"]),
                       tuple(tuple(float(r) for r in ratios) for ratios in data["aspect_ratios"]))
        except (KeyError, TypeError, ValueError) as error:
            raise SSDModelError(f"priors: expected input_size, feature_map_sizes, steps, min_sizes, max_sizes and "
                                f"aspect_ratios ({type(error).__name__}: {error})") from error


def paper_priors(architecture: str, input_size: int | None = None) -> PriorSpec:
    """The prior layout of ``architecture``: the SSD paper's (Caffe release) for ``ssd300``/``ssd512``,
    small-object priors for ``light`` (``input_size``: :func:`paz6d.ssd.config.check_input_size`).

    Raises:
        SSDModelError: an unknown ``architecture`` or an ``input_size`` it cannot take.
    """
    size = check_input_size(architecture, input_size, SSDModelError)
    if architecture == "ssd300":
        return PriorSpec(size, (38, 19, 10, 5, 3, 1), (8, 16, 32, 64, 100, 300), (30, 60, 111, 162, 213, 264),
                         (60, 111, 162, 213, 264, 315), ((2,), (2, 3), (2, 3), (2, 3), (2,), (2,)))
    if architecture == "ssd512":
        return PriorSpec(size, (64, 32, 16, 8, 4, 2, 1), (8, 16, 32, 64, 128, 256, 512),
                         (35.84, 76.8, 153.6, 230.4, 307.2, 384.0, 460.8),
                         (76.8, 153.6, 230.4, 307.2, 384.0, 460.8, 537.6),
                         ((2,), (2, 3), (2, 3), (2, 3), (2, 3), (2,), (2,)))
    maps = tuple(rows for rows, _ in light_feature_maps(size, size))
    fractions = np.array([0.044, 0.094, 0.19, 0.34, 0.53, 0.75, 1.0])
    sides = tuple(float(v) for v in np.round(fractions * size, 1))
    return PriorSpec(size, maps, tuple(float(size) / m for m in maps), sides[:-1], sides[1:],
                     ((2,), (2, 3), (2, 3), (2, 3), (2,), (2,)))


def light_feature_maps(height: int, width: int) -> tuple[tuple[int, int], ...]:
    """``(rows, cols)`` of the light network's six feature maps on a ``height × width`` input (multiples
    of 64): strides 8, 16, 32 and 64, then half the stride-64 map (rounded up) and one global cell."""
    def sides(length: int) -> tuple[int, ...]:
        return length // 8, length // 16, length // 32, length // 64, (length // 64 + 1) // 2, 1
    return tuple(zip(sides(int(height)), sides(int(width))))


def priors_for(spec: PriorSpec, image_shape: tuple[int, int] | None = None) -> np.ndarray:
    """Normalised ``cxcywh`` priors ``(P, 4)`` of ``spec`` (:func:`paz6d.backend.boxes.prior_boxes`).

    Args:
        image_shape: ``(height, width)`` of another input than the square ``spec.input_size`` (the light
            network on whole images, multiples of 64): its feature maps' cells, the same prior sides in
            pixels, normalised by that input's width and height.
    """
    if image_shape is None:
        return prior_boxes(spec.input_size, spec.feature_map_sizes, spec.steps, spec.min_sizes, spec.max_sizes,
                           spec.aspect_ratios)
    height, width = (check_light_side(int(v), SSDModelError) for v in image_shape)
    maps = light_feature_maps(height, width)
    if len(maps) != len(spec.feature_map_sizes):
        raise SSDModelError(f"priors: a {len(spec.feature_map_sizes)}-map prior layout is not the light network's")
    steps = tuple((width / cols, height / rows) for rows, cols in maps)
    return prior_boxes((width, height), maps, steps, spec.min_sizes, spec.max_sizes, spec.aspect_ratios)


def input_normalization(backbone: str | None = None) -> dict[str, list[float]]:
    """``{"mean": [r, g, b], "std": [r, g, b]}`` of the network input ``(image / 255 - mean) / std``:
    ImageNet's channel statistics for the from-scratch networks, a pretrained backbone's own scaling
    (EfficientNet-Lite0: ``(image - 127) / 128``) otherwise."""
    if backbone in (None, "none"):
        return {"mean": list(IMAGE_MEAN), "std": list(IMAGE_STD)}
    if backbone == "efficientnet-lite0":
        return {"mean": [lite0.PIXEL_MEAN / 255.0] * 3, "std": [lite0.PIXEL_SCALE / 255.0] * 3}
    raise SSDModelError(f"backbone: expected one of {BACKBONES}, got {backbone!r}")


def normalize_images(images, normalization: dict | None = None) -> np.ndarray:
    """``uint8`` RGB ``(..., H, W, 3)`` to the network's float32 input (:func:`paz6d.backend.image.normalize`)
    with ``normalization`` (:func:`input_normalization`; default ImageNet's statistics)."""
    normalization = normalization or input_normalization()
    return normalize(images, normalization["mean"], normalization["std"])


@keras.saving.register_keras_serializable(package=PACKAGE)
class L2Normalization(keras.layers.Layer):
    """Channel-wise L2 normalisation with a learned per-channel scale (SSD's conv4_3 norm).

    ``y = scale * x / ||x||`` over the last axis; ``scale`` starts at ``initial_scale``.
    """

    def __init__(self, initial_scale: float = 20.0, **kwargs):
        super().__init__(**kwargs)
        self.initial_scale = float(initial_scale)

    def build(self, input_shape):
        self.scale = self.add_weight(name="scale", shape=(input_shape[-1],),
                                     initializer=keras.initializers.Constant(self.initial_scale))

    def call(self, inputs):
        return keras.ops.normalize(inputs, axis=-1, order=2) * self.scale

    def get_config(self):
        return {**super().get_config(), "initial_scale": self.initial_scale}


def _conv(x, filters: int, kernel: int, name: str, strides: int = 1, padding: str = "same", dilation: int = 1):
    return keras.layers.Conv2D(filters, kernel, strides=strides, padding=padding, dilation_rate=dilation,
                               activation="relu", kernel_initializer="he_normal", name=name)(x)


def _vgg16_body(inputs) -> tuple[list, object]:
    """VGG16 up to fc7: returns ``([L2-normalised conv4_3, fc7], fc7)``."""
    x = inputs
    for block, (filters, count) in enumerate(((64, 2), (128, 2), (256, 3), (512, 3)), start=1):
        for index in range(1, count + 1):
            x = _conv(x, filters, 3, f"conv{block}_{index}")
        if block == 4:
            conv4_3 = x
        x = keras.layers.MaxPooling2D(2, 2, padding="same", name=f"pool{block}")(x)
    for index in range(1, 4):
        x = _conv(x, 512, 3, f"conv5_{index}")
    x = keras.layers.MaxPooling2D(3, 1, padding="same", name="pool5")(x)
    x = _conv(x, 1024, 3, "fc6", dilation=6)
    fc7 = _conv(x, 1024, 1, "fc7")
    return [L2Normalization(20.0, name="conv4_3_norm")(conv4_3), fc7], fc7


def _vgg_extras(x, strided_blocks: int, valid_blocks: int) -> list:
    """SSD's extra blocks (1x1 bottleneck + 3x3): ``strided_blocks`` of stride 2 ('same'), then
    ``valid_blocks`` 3x3 'valid' ones."""
    features = []
    widths = [(256, 512)] + [(128, 256)] * (strided_blocks + valid_blocks - 1)
    for index, (bottleneck, filters) in enumerate(widths, start=6):
        x = _conv(x, bottleneck, 1, f"conv{index}_1")
        if index - 6 < strided_blocks:
            x = _conv(x, filters, 3, f"conv{index}_2", strides=2)
        else:
            x = _conv(x, filters, 3, f"conv{index}_2", padding="valid")
        features.append(x)
    return features


def _separable(x, filters: int, name: str, strides: int = 1):
    """Depthwise 3x3 + BN + ReLU, pointwise 1x1 + BN + ReLU."""
    x = keras.layers.DepthwiseConv2D(3, strides=strides, padding="same", use_bias=False, name=f"{name}_dw")(x)
    x = keras.layers.BatchNormalization(name=f"{name}_dw_bn")(x)
    x = keras.layers.ReLU(name=f"{name}_dw_relu")(x)
    x = keras.layers.Conv2D(filters, 1, use_bias=False, kernel_initializer="he_normal", name=f"{name}_pw")(x)
    x = keras.layers.BatchNormalization(name=f"{name}_pw_bn")(x)
    return keras.layers.ReLU(name=f"{name}_pw_relu")(x)


def _light_body(inputs, width: float, top_down: bool = False) -> list:
    """Depthwise-separable body: six feature maps of stride 8, 16, 32, 64, 128 and a 1x1 map; with
    ``top_down``, the maps of stride 8, 16 and 32 pass through :func:`_top_down`."""
    channels = _channels(width)
    x = keras.layers.Conv2D(channels(32), 3, strides=2, padding="same", use_bias=False,
                            kernel_initializer="he_normal", name="stem")(inputs)
    x = keras.layers.ReLU(name="stem_relu")(keras.layers.BatchNormalization(name="stem_bn")(x))
    x = _separable(x, channels(64), "block1", strides=2)
    x = _separable(x, channels(64), "block2")
    x = _separable(x, channels(128), "block3", strides=2)
    stride8 = _separable(x, channels(128), "block4")
    x = _separable(stride8, channels(256), "block5", strides=2)
    stride16 = _separable(x, channels(256), "block6")
    stride32 = _separable(stride16, channels(256), "block7", strides=2)
    return _light_extras([stride8, stride16, stride32], channels, top_down)


def _light_extras(features: list, channels: Callable[[int], int], top_down: bool) -> list:
    """The maps of stride 64 and 128 and a 1x1 map after the stride-32 map of ``features`` (strides 8, 16,
    32), and with ``top_down`` :func:`_top_down` over those three: the six maps of the light network."""
    stride8, stride16, stride32 = features
    x = _conv(stride32, channels(128), 1, "extra1_1")
    stride64 = _separable(x, channels(256), "extra1_2", strides=2)
    x = _conv(stride64, channels(64), 1, "extra2_1")
    stride128 = _separable(x, channels(128), "extra2_2", strides=2)
    x = _conv(stride128, channels(64), 1, "extra3_1")
    last = keras.layers.GlobalAveragePooling2D(keepdims=True, name="extra3_pool")(x)
    last = _conv(last, channels(128), 1, "extra3_2")
    if top_down:
        stride8, stride16, stride32 = _top_down([stride8, stride16, stride32], channels(128))
    return [stride8, stride16, stride32, stride64, stride128, last]


def _backbone_body(inputs, backbone: str, width: float, top_down: bool, frozen_stages: int) -> list:
    """The six light-network maps on a pretrained ``backbone``'s stride-8, 16 and 32 maps (a nested model
    named :data:`BACKBONE_LAYER`, ImageNet weights, batch-norm statistics frozen)."""
    if backbone != "efficientnet-lite0":
        raise SSDModelError(f"backbone: expected one of {BACKBONES}, got {backbone!r}")
    body = lite0.build_features(tuple(inputs.shape[1:]), pretrained=True, frozen_stages=frozen_stages,
                                name=BACKBONE_LAYER)
    return _light_extras(list(body(inputs)), _channels(width), top_down)


def _channels(width: float) -> Callable[[int], int]:
    """Channels of the light network's layers: ``count`` scaled by ``width``, a multiple of 8 (at least 8)."""
    return lambda count: max(8, int(round(count * width / 8)) * 8)


def backbone_variables(model) -> list:
    """The trainable variables of an SSD's pretrained backbone (none for the from-scratch networks)."""
    names = {layer.name for layer in model.layers}
    return list(model.get_layer(BACKBONE_LAYER).trainable_variables) if BACKBONE_LAYER in names else []


def _top_down(features: list, filters: int) -> list:
    """A feature-pyramid top-down path (Lin et al., "Feature Pyramid Networks for Object Detection",
    CVPR 2017) over maps of strides ``s, 2s, 4s, ...``: each map, projected to ``filters`` channels by a
    1x1 conv, plus the 2x-upsampled merged map above it, then a depthwise-separable 3x3. The fine maps,
    shallow in the body, get the context of the deep ones."""
    merged = [_conv(features[-1], filters, 1, f"lateral_{len(features) - 1}")]
    for index in range(len(features) - 2, -1, -1):
        lateral = _conv(features[index], filters, 1, f"lateral_{index}")
        above = keras.layers.UpSampling2D(2, interpolation="nearest", name=f"topdown_up_{index}")(merged[0])
        merged.insert(0, keras.layers.Add(name=f"topdown_add_{index}")([lateral, above]))
    return [_separable(x, filters, f"topdown_{index}") for index, x in enumerate(merged)]


def _heads(features: list, spec: PriorSpec, num_classes: int, separable: bool):
    """Per map: a 3x3 regression and a 3x3 classification conv, reshaped and concatenated to
    ``(B, P, 4 + num_classes)``."""
    offsets, logits = [], []
    for index, (feature, count) in enumerate(zip(features, spec.priors_per_cell)):
        for kind, depth, outputs in (("loc", 4, offsets), ("conf", num_classes, logits)):
            name = f"{kind}_{index}"
            if separable:
                y = keras.layers.SeparableConv2D(count * depth, 3, padding="same", name=name)(feature)
            else:
                y = keras.layers.Conv2D(count * depth, 3, padding="same", name=name)(feature)
            outputs.append(keras.layers.Reshape((-1, depth), name=f"{name}_flat")(y))
    offsets = keras.layers.Concatenate(axis=1, name="offsets")(offsets)
    logits = keras.layers.Concatenate(axis=1, name="logits")(logits)
    return keras.layers.Concatenate(axis=-1, name="boxes")([offsets, logits])


def build_ssd(num_classes: int, architecture: str = "light", input_size: int | None = None,
              width: float = 1.0, top_down: bool = False, any_size: bool = False, backbone: str | None = None,
              frozen_stages: int = lite0.DEFAULT_FROZEN_STAGES) -> tuple[object, PriorSpec]:
    """An SSD network and its prior layout.

    Args:
        num_classes: classes including the background (class 0), at least 2.
        architecture: ``"ssd300"``, ``"ssd512"`` or ``"light"``.
        input_size: side of the square input (:func:`paz6d.ssd.config.check_input_size`: ``light`` a multiple
            of 64 in [128, 2048], by default the quick config's; the VGG models 300 / 512).
        width: ``light`` only: channel multiplier of the body.
        top_down: ``light`` only: a feature-pyramid top-down path over its three finest maps.
        any_size: ``light`` only: the model takes inputs of any height and width that are multiples of 64
            (trained on ``input_size`` squares, run on whole images; priors from :func:`priors_for`).
        backbone: ``light`` only: a pretrained body (:data:`BACKBONES`; ``None``/``"none"``: the light body,
            randomly initialised); its input is scaled as :func:`input_normalization` says.
        frozen_stages: with a ``backbone``: its first stages kept fixed
            (:func:`paz6d.backbones.efficientnet_lite0.build_features`).
    Returns:
        ``(model, spec)``: ``model(images (B, S, S, 3)) -> (B, P, 4 + num_classes)``; ``spec`` gives the priors.
    Raises:
        SSDModelError: bad ``num_classes``, ``architecture``, ``input_size`` or ``width``.
    """
    if int(num_classes) < 2:
        raise SSDModelError(f"num_classes: expected at least 2 (background + one object class), got {num_classes}")
    spec = paper_priors(architecture, input_size)
    if not 0.1 <= float(width) <= 4.0:
        raise SSDModelError(f"width: expected a channel multiplier in [0.1, 4], got {width}")
    backbone = None if backbone == "none" else backbone
    for name, value in (("top_down", top_down), ("any_size", any_size), ("backbone", backbone)):
        if value and architecture != "light":
            raise SSDModelError(f"{name}: only the light network offers it, not {architecture}")
    side = None if any_size else spec.input_size
    inputs = keras.Input((side, side, 3), name="image")
    if architecture == "light" and backbone is not None:
        features = _backbone_body(inputs, backbone, float(width), bool(top_down), frozen_stages)
    elif architecture == "light":
        features = _light_body(inputs, float(width), bool(top_down))
    else:
        features, fc7 = _vgg16_body(inputs)
        features += _vgg_extras(fc7, 2 if architecture == "ssd300" else 4, 2 if architecture == "ssd300" else 0)
        if architecture == "ssd512":
            features.append(_vgg_extras_last(features[-1]))
    sizes = spec.feature_map_sizes if any_size else tuple(int(feature.shape[1]) for feature in features)
    if sizes != spec.feature_map_sizes:
        raise SSDModelError(f"{architecture}: feature maps {sizes} differ from the prior layout "
                            f"{spec.feature_map_sizes}")
    outputs = _heads(features, spec, int(num_classes), separable=architecture == "light")
    return keras.Model(inputs, outputs, name=f"ssd_{architecture}"), spec


def _vgg_extras_last(x):
    """SSD512's last block: 1x1 bottleneck and a 3x3 stride-2 conv from 2 x 2 to 1 x 1."""
    x = _conv(x, 128, 1, "conv10_1")
    return _conv(x, 256, 3, "conv10_2", strides=2)


def save_ssd(model, path: str | Path) -> Path:
    """Saves ``model`` to a ``.keras`` file (temporary file, then rename)."""
    return save_keras_model_atomically(model, path)


def load_ssd(path: str | Path, spec: PriorSpec, num_classes: int):
    """Loads a model saved by :func:`save_ssd` in Keras safe mode and checks it against ``spec``.

    Raises:
        SSDModelError: missing, unreadable or mismatching file (message names the file).
    """
    path = Path(path)
    model = load_keras_model(path, SSDModelError)
    expected = (None, len(priors_for(spec)), 4 + int(num_classes))
    output_shape = tuple(model.output_shape)
    if tuple(model.input_shape[1:3]) == (None, None):  # built with any_size: the output of a square input
        output_shape = (None,) + tuple(model.compute_output_shape((1, spec.input_size, spec.input_size, 3)))[1:]
    if output_shape != expected or tuple(model.input_shape[1:]) not in {(spec.input_size, spec.input_size, 3),
                                                                        (None, None, 3)}:
        raise SSDModelError(f"{path}: expected an SSD with input {(spec.input_size,) * 2 + (3,)} and output "
                            f"{expected}, got {model.input_shape} -> {model.output_shape}")
    return model


def inference_function(model):
    """Compiled ``images (B, S, S, 3) float32 -> (B, P, 4 + C)`` (one trace for any batch size)."""
    return compiled_inference(model)
