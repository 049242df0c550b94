"""The SSD run directory: the only module that knows its file names and formats.

``paz6d train ssd`` writes, and :class:`~paz6d.ssd.pipeline.DetectSingleShot` and ``paz6d detect`` read::

    RUN_DIR/detector.json   architecture, class_names (class id i is class_names[i - 1]; 0 = background),
                            priors (input_size, feature maps, steps, sizes, aspect ratios), variances,
                            optionally image_scale (the network runs on whole images scaled by it) and
                            normalization (mean, std of its input (image / 255 - mean) / std; absent:
                            ImageNet's channel statistics)
    RUN_DIR/model.keras     the network (loaded in Keras safe mode)
    RUN_DIR/config.json     the training settings (dataset, seed, schedule)
    RUN_DIR/metrics.json    training summary

plus the shared trainer's ``checkpoints/``, ``log.csv``, ``tensorboard/`` and ``samples/``.
Every reader raises ``ValueError`` naming the file and what is missing or malformed.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from paz6d.backend.boxes import SSD_VARIANCES
from paz6d.backend.checks import short_repr
from paz6d.backend.files import load_run_json, write_json_atomically
from paz6d.run_dir import DescribedRunDir
from paz6d.ssd.config import ARCHITECTURES, SSDConfig, check_input_size

DETECTOR_FILE = "detector.json"
#: Fields of ``detector.json``.
DETECTOR_KEYS = ("architecture", "class_names", "priors", "variances")


class SSDRunDir(DescribedRunDir):
    """A ``paz6d train ssd`` run directory (files in the module docstring)."""

    KIND = "an SSD"
    SETTINGS = SSDConfig
    DESCRIPTION_FILE = DETECTOR_FILE
    MESH_FIELDS = None

    @classmethod
    def read_description(cls, run_dir: str | Path) -> dict[str, Any]:
        """``detector.json``, checked by :func:`check_detector`."""
        path = Path(run_dir) / DETECTOR_FILE
        return check_detector(load_run_json(path, DETECTOR_KEYS, cls.KIND, description="detector description"), path)

    @classmethod
    def class_names(cls, run_dir: str | Path) -> tuple[str, ...]:
        """The detector's class names (``detector.json``), in class-id order."""
        return tuple(cls.read_description(run_dir)["class_names"])


#: Fields of ``detector.json``'s ``priors`` (:class:`paz6d.ssd.model.PriorSpec`), one entry per feature map
#: each but ``input_size``.
PRIOR_KEYS = ("input_size", "feature_map_sizes", "steps", "min_sizes", "max_sizes", "aspect_ratios")
#: The range of ``image_scale``: whole images are scaled by it before detection (a factor outside it shrinks
#: a VGA image below the light network's smallest input or blows it up beyond 10,000 pixels).
IMAGE_SCALE_RANGE = (1 / 16, 16.0)


def write_detector(run_dir: str | Path, architecture: str, class_names, priors: dict,
                   variances=SSD_VARIANCES, image_scale: float | None = None,
                   normalization: dict | None = None) -> Path:
    """Writes ``detector.json``: what the pipeline needs besides the weights (checked as
    :func:`check_detector` reads it).

    Args:
        architecture: ``"ssd300"``, ``"ssd512"`` or ``"light"``.
        class_names: object classes in class-id order (without the background).
        priors: :meth:`paz6d.ssd.model.PriorSpec.to_dict`.
        image_scale: for a network trained on rescaled windows (``scale_crops``): the factor by which
            whole images are scaled before they are padded and detected; ``None``: they are resized to
            the square input.
        normalization: ``{"mean": [3 floats], "std": [3 floats]}`` of the network input
            (:func:`paz6d.ssd.model.input_normalization`); ``None``: ImageNet's statistics.
    """
    data = {"architecture": architecture, "class_names": [str(name) for name in class_names], "priors": priors,
            "variances": [float(v) for v in variances]}
    if image_scale is not None:
        data["image_scale"] = float(image_scale)
    if normalization is not None:
        data["normalization"] = {key: [float(v) for v in normalization[key]] for key in ("mean", "std")}
    check_detector(data, "detector")
    Path(run_dir).mkdir(parents=True, exist_ok=True)
    return write_json_atomically(Path(run_dir) / DETECTOR_FILE, data, indent=2)


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _numbers(data: dict, key: str, where: str, count: int, expected: str, valid) -> list:
    """``data[key]``, checked to be a list of ``count`` numbers for which ``valid(number)`` holds."""
    values = data[key]
    if not (isinstance(values, list) and len(values) == count and all(_is_number(v) and valid(v) for v in values)):
        raise ValueError(f"{where}: {key}: expected {count} {expected}, got {short_repr(values)}")
    return values


def _check_priors(priors, where: str, architecture: str) -> None:
    """The prior layout (:data:`PRIOR_KEYS`): an input side ``architecture`` takes, and per feature map a
    positive whole side, a positive step and prior sides (``min <= max``) and positive aspect ratios."""
    if not isinstance(priors, dict):
        raise ValueError(f"{where}: priors: expected an object, got {short_repr(priors)}")
    missing = [key for key in PRIOR_KEYS if key not in priors]
    if missing:
        raise ValueError(f"{where}: priors: missing field(s) {missing}")
    where = f"{where}: priors"
    size = priors["input_size"]
    if not (type(size) is int and size > 0):
        raise ValueError(f"{where}: input_size: expected a positive number of pixels, got {short_repr(size)}")
    try:
        check_input_size(architecture, size)
    except ValueError as error:
        raise ValueError(f"{where}: {error}") from None
    maps = priors["feature_map_sizes"]
    if not (isinstance(maps, list) and maps and all(type(side) is int and 0 < side <= size for side in maps)):
        raise ValueError(f"{where}: feature_map_sizes: expected a non-empty list of sides from 1 to input_size "
                         f"({size}), got {short_repr(maps)}")
    count, per_map = len(maps), "(one per entry of feature_map_sizes)"
    _numbers(priors, "steps", where, count, f"positive steps in pixels {per_map}", lambda v: v > 0)
    minimum = _numbers(priors, "min_sizes", where, count, f"positive prior sides in pixels {per_map}", lambda v: v > 0)
    maximum = _numbers(priors, "max_sizes", where, count, f"positive prior sides in pixels {per_map}", lambda v: v > 0)
    if any(low > high for low, high in zip(minimum, maximum)):
        raise ValueError(f"{where}: max_sizes: expected each at least its min_sizes entry, got {maximum} for "
                         f"{minimum}")
    ratios = priors["aspect_ratios"]
    if not (isinstance(ratios, list) and len(ratios) == count
            and all(isinstance(entry, list) and all(_is_number(r) and r > 0 for r in entry) for entry in ratios)):
        raise ValueError(f"{where}: aspect_ratios: expected {count} lists of positive ratios {per_map}, got "
                         f"{short_repr(ratios)}")


def check_detector(data: dict, where: str | Path) -> dict:
    """The validator of ``detector.json``: every field of ``data`` (the file's JSON object) checked; returns it.

    Raises:
        ValueError: ``"<where>: <field>: expected ..."``.
    """
    where = str(where)
    missing = [key for key in DETECTOR_KEYS if key not in data]
    if missing:
        raise ValueError(f"{where}: missing field(s) {missing}")
    architecture = data["architecture"]
    if architecture not in ARCHITECTURES:
        raise ValueError(f"{where}: architecture: expected one of {ARCHITECTURES}, got {short_repr(architecture)}")
    names = data["class_names"]
    if not isinstance(names, list) or not names or not all(isinstance(name, str) and name for name in names):
        raise ValueError(f"{where}: class_names: expected a non-empty list of names, got {short_repr(names)}")
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise ValueError(f"{where}: class_names: expected distinct names, {repeated} repeated")
    _numbers(data, "variances", where, 4, "positive numbers", lambda v: v > 0)
    scale = data.get("image_scale")
    low, high = IMAGE_SCALE_RANGE
    if scale is not None and not (_is_number(scale) and low <= scale <= high):
        raise ValueError(f"{where}: image_scale: expected a factor from {low:g} to {high:g} or null, got "
                         f"{short_repr(scale)}")
    if scale is not None and architecture != "light":
        raise ValueError(f"{where}: image_scale: only the light network detects on scaled whole images, not "
                         f"{architecture}")
    normalization = data.get("normalization")
    if normalization is not None and not (
            isinstance(normalization, dict) and set(normalization) == {"mean", "std"}
            and all(isinstance(values, list) and len(values) == 3 and all(_is_number(v) for v in values)
                    for values in normalization.values())
            and all(v > 0 for v in normalization["std"])):
        raise ValueError(f"{where}: normalization: expected {{'mean': [3 numbers], 'std': [3 positive numbers]}} "
                         f"or null, got {short_repr(normalization)}")
    _check_priors(data["priors"], where, architecture)
    return data



def read_model(run_dir: str | Path):
    """``(model, detector)``: the trained network (Keras safe mode; imports TensorFlow) and
    ``detector.json``.

    Raises:
        ValueError: missing or corrupt files, or a model that does not fit ``detector.json``.
    """
    from paz6d.ssd.model import PriorSpec, load_ssd

    detector = SSDRunDir.validate(run_dir)
    spec = PriorSpec.from_dict(detector["priors"])
    return load_ssd(SSDRunDir.model_path(run_dir), spec, len(detector["class_names"]) + 1), detector
