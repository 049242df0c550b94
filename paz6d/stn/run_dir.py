"""The spatial-transformer run directory: the only module that knows its file names and formats.

``paz6d train stn`` writes, and :class:`~paz6d.stn.pipeline.ClassifyDigit` reads::

    RUN_DIR/classifier.json  canvas_size, crop_size (pixels), transformer (bool), class_names, padding
    RUN_DIR/model.keras      the network (loaded in Keras safe mode)
    RUN_DIR/config.json      the training settings (config, seed, schedule, data)
    RUN_DIR/metrics.json     training summary and test accuracy
    RUN_DIR/crops.png        test canvases and the transformer's crops (with the transformer)

plus the shared trainer's ``checkpoints/``, ``log.csv``, ``tensorboard/`` and ``samples/``.
Every reader raises ``ValueError`` naming the file and what is missing or malformed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from paz6d.backend.checks import integer_field
from paz6d.backend.files import load_run_json, write_json_atomically
from paz6d.run_dir import DescribedRunDir
from paz6d.stn.config import STNConfig

CLASSIFIER_FILE = "classifier.json"
CROPS_FILE = "crops.png"
#: Fields of ``classifier.json``.
CLASSIFIER_KEYS = ("canvas_size", "crop_size", "transformer", "class_names")


class STNRunDir(DescribedRunDir):
    """A ``paz6d train stn`` run directory (files in the module docstring)."""

    KIND = "a spatial-transformer"
    SETTINGS = STNConfig
    DESCRIPTION_FILE = CLASSIFIER_FILE
    MESH_FIELDS = None

    @classmethod
    def read_description(cls, run_dir: str | Path) -> dict[str, Any]:
        """``classifier.json`` checked for its fields (sizes >= 16 pixels, a boolean ``transformer``,
        at least 2 distinct string ``class_names``)."""
        path = Path(run_dir) / CLASSIFIER_FILE
        data = load_run_json(path, CLASSIFIER_KEYS, cls.KIND)
        for name in ("canvas_size", "crop_size"):
            integer_field(data, name, str(path), minimum=16)
        if not isinstance(data["transformer"], bool):
            raise ValueError(f"{path}: transformer: expected true or false, got {data['transformer']!r}")
        names = data["class_names"]
        if (not isinstance(names, list) or len(names) < 2 or not all(isinstance(name, str) for name in names)
                or len(set(names)) != len(names)):
            raise ValueError(f"{path}: class_names: expected a list of at least 2 distinct names, got {names!r}")
        return data


def crops_path(run_dir: str | Path) -> Path:
    """Where the PNG of input canvases and learned crops is written."""
    return Path(run_dir) / CROPS_FILE


def write_classifier(run_dir: str | Path, canvas_size: int, crop_size: int, transformer: bool, class_names,
                     padding: str) -> Path:
    """Writes ``classifier.json``: what the pipeline needs besides the weights."""
    class_names = [str(name) for name in class_names]
    if len(class_names) < 2 or len(set(class_names)) != len(class_names):
        raise ValueError(f"class_names: expected at least 2 distinct names, got {class_names}")
    Path(run_dir).mkdir(parents=True, exist_ok=True)
    data = {"canvas_size": int(canvas_size), "crop_size": int(crop_size), "transformer": bool(transformer),
            "class_names": class_names, "padding": padding}
    return write_json_atomically(Path(run_dir) / CLASSIFIER_FILE, data, indent=2)



def read_model(run_dir: str | Path):
    """``(model, classifier)``: the trained network (Keras safe mode; imports TensorFlow) and
    ``classifier.json``.

    Raises:
        ValueError: missing or corrupt files, or a model that does not fit ``classifier.json``.
    """
    from paz6d.stn.model import has_transformer, load_classifier

    classifier = STNRunDir.validate(run_dir)
    path = STNRunDir.model_path(run_dir)
    model = load_classifier(path)
    expected = (None, classifier["canvas_size"], classifier["canvas_size"], 1)
    if tuple(model.input_shape) != expected:
        raise ValueError(f"{path}: input shape {model.input_shape} does not match {CLASSIFIER_FILE} "
                         f"(canvas_size {classifier['canvas_size']}: expected {expected})")
    if has_transformer(model) != classifier["transformer"]:
        raise ValueError(f"{path}: transformer={has_transformer(model)} but {CLASSIFIER_FILE} says "
                         f"{classifier['transformer']}")
    if int(model.output["logits"].shape[-1]) != len(classifier["class_names"]):
        raise ValueError(f"{path}: {model.output['logits'].shape[-1]} classes but {CLASSIFIER_FILE} names "
                         f"{len(classifier['class_names'])}")
    return model, classifier
