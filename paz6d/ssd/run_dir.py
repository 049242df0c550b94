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

from pathlib import Path
from typing import Any

from paz6d.backend.boxes import SSD_VARIANCES
from paz6d.backend.files import load_run_json, write_json_atomically
from paz6d.run_dir import RunDir

DETECTOR_FILE = "detector.json"
#: Fields of ``detector.json``.
DETECTOR_KEYS = ("architecture", "class_names", "priors", "variances")


class SSDRunDir(RunDir):
    """A ``paz6d train ssd`` run directory (files in the module docstring)."""

    KIND = "an SSD"
    MARKER_FILES = (DETECTOR_FILE,)
    REQUIRED_FILES = (DETECTOR_FILE, RunDir.MODEL_FILE)
    MESH_FIELDS = None

    @classmethod
    def validate(cls, run_dir: str | Path) -> dict[str, Any]:
        """Checks that ``run_dir`` is a directory with ``detector.json`` and ``model.keras``; returns the
        detector description."""
        return read_detector(cls.check_files(run_dir))

    @classmethod
    def class_names(cls, run_dir: str | Path) -> tuple[str, ...]:
        """The detector's class names (``detector.json``), in class-id order."""
        return tuple(read_detector(run_dir)["class_names"])


# the module's functions, as its callers use them
_RUN_DIR = SSDRunDir
KIND, MARKER_FILES, REQUIRED_FILES = _RUN_DIR.KIND, _RUN_DIR.MARKER_FILES, _RUN_DIR.REQUIRED_FILES
CONFIG_FILE, MODEL_FILE, METRICS_FILE = _RUN_DIR.CONFIG_FILE, _RUN_DIR.MODEL_FILE, _RUN_DIR.METRICS_FILE
model_path, validate = _RUN_DIR.model_path, _RUN_DIR.validate
read_config, write_config, write_metrics = _RUN_DIR.read_config, _RUN_DIR.write_config, _RUN_DIR.write_metrics


def write_detector(run_dir: str | Path, architecture: str, class_names, priors: dict,
                   variances=SSD_VARIANCES, image_scale: float | None = None,
                   normalization: dict | None = None) -> Path:
    """Writes ``detector.json``: what the pipeline needs besides the weights.

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
    class_names = [str(name) for name in class_names]
    if not class_names or len(set(class_names)) != len(class_names):
        raise ValueError(f"class_names: expected distinct names, got {class_names}")
    Path(run_dir).mkdir(parents=True, exist_ok=True)
    data = {"architecture": architecture, "class_names": class_names, "priors": priors,
            "variances": [float(v) for v in variances]}
    if image_scale is not None:
        data["image_scale"] = float(image_scale)
    if normalization is not None:
        data["normalization"] = {key: [float(v) for v in normalization[key]] for key in ("mean", "std")}
    return write_json_atomically(Path(run_dir) / DETECTOR_FILE, data, indent=2)


def read_detector(run_dir: str | Path) -> dict[str, Any]:
    """``detector.json`` checked for its fields (``class_names`` a non-empty list of strings,
    4 positive ``variances``)."""
    path = Path(run_dir) / DETECTOR_FILE
    data = load_run_json(path, DETECTOR_KEYS, KIND, description="detector description")
    names = data["class_names"]
    if not isinstance(names, list) or not names or not all(isinstance(name, str) for name in names):
        raise ValueError(f"{path}: class_names: expected a non-empty list of names, got {names!r}")
    variances = data["variances"]
    if (not isinstance(variances, list) or len(variances) != 4
            or not all(isinstance(v, (int, float)) and v > 0 for v in variances)):
        raise ValueError(f"{path}: variances: expected 4 positive numbers, got {variances!r}")
    scale = data.get("image_scale")
    if scale is not None and not (isinstance(scale, (int, float)) and scale > 0):
        raise ValueError(f"{path}: image_scale: expected a positive number or null, got {scale!r}")
    normalization = data.get("normalization")
    if normalization is not None and not (
            isinstance(normalization, dict) and set(normalization) == {"mean", "std"}
            and all(isinstance(values, list) and len(values) == 3
                    and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
                    for values in normalization.values())
            and all(v > 0 for v in normalization["std"])):
        raise ValueError(f"{path}: normalization: expected {{'mean': [3 numbers], 'std': [3 positive numbers]}} "
                         f"or null, got {normalization!r}")
    if not isinstance(data["priors"], dict):
        raise ValueError(f"{path}: priors: expected an object, got {type(data['priors']).__name__}")
    return data


def read_model(run_dir: str | Path):
    """``(model, detector)``: the trained network (Keras safe mode; imports TensorFlow) and
    ``detector.json``.

    Raises:
        ValueError: missing or corrupt files, or a model that does not fit ``detector.json``.
    """
    from paz6d.ssd.model import PriorSpec, load_ssd

    detector = validate(run_dir)
    spec = PriorSpec.from_dict(detector["priors"])
    return load_ssd(model_path(run_dir), spec, len(detector["class_names"]) + 1), detector
