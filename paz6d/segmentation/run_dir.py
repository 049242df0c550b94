"""The mask-head run directory: the only module that knows its file names and formats.

``paz6d train segmentation`` writes, and :class:`~paz6d.segmentation.pipeline.SegmentInstances` reads::

    RUN_DIR/segmenter.json   input_size (crop side S, pixels), margin (window side / longer box side),
                             class_names (output channel i is class_names[i]), threshold (probability)
    RUN_DIR/model.keras      the U-Net (loaded in Keras safe mode)
    RUN_DIR/config.json      the training settings (dataset, seed, schedule)
    RUN_DIR/metrics.json     training summary

plus the shared trainer's ``checkpoints/``, ``log.csv``, ``tensorboard/`` and ``samples/``.
Every reader raises ``ValueError`` naming the file and what is missing or malformed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from paz6d.backend.files import load_run_json, write_json_atomically
from paz6d.run_dir import DescribedRunDir
from paz6d.segmentation.config import SegmentationConfig

SEGMENTER_FILE = "segmenter.json"
#: Fields of ``segmenter.json``.
SEGMENTER_KEYS = ("input_size", "margin", "class_names", "threshold")


class SegmentationRunDir(DescribedRunDir):
    """A ``paz6d train segmentation`` run directory (files in the module docstring)."""

    KIND = "a segmentation"
    SETTINGS = SegmentationConfig
    DESCRIPTION_FILE = SEGMENTER_FILE
    MESH_FIELDS = None

    @classmethod
    def read_description(cls, run_dir: str | Path) -> dict[str, Any]:
        """``segmenter.json`` checked field by field."""
        path = Path(run_dir) / SEGMENTER_FILE
        data = load_run_json(path, SEGMENTER_KEYS, cls.KIND, description="segmenter description")
        size = data["input_size"]
        if not isinstance(size, int) or isinstance(size, bool) or size <= 0:
            raise ValueError(f"{path}: input_size: expected a positive integer (pixels), got {size!r}")
        for key, low, high in (("margin", 0.0, float("inf")), ("threshold", 0.0, 1.0)):
            value = data[key]
            if not isinstance(value, (int, float)) or isinstance(value, bool) or not low < value < high:
                raise ValueError(f"{path}: {key}: expected a number in ({low}, {high}), got {value!r}")
        names = data["class_names"]
        if not isinstance(names, list) or not names or not all(isinstance(name, str) for name in names):
            raise ValueError(f"{path}: class_names: expected a non-empty list of names, got {names!r}")
        return data


def write_segmenter(run_dir: str | Path, input_size: int, margin: float, class_names, threshold: float = 0.5) -> Path:
    """Writes ``segmenter.json``: what the pipeline needs besides the weights."""
    class_names = [str(name) for name in class_names]
    if not class_names or len(set(class_names)) != len(class_names):
        raise ValueError(f"class_names: expected distinct names, got {class_names}")
    Path(run_dir).mkdir(parents=True, exist_ok=True)
    data = {"input_size": int(input_size), "margin": float(margin), "class_names": class_names,
            "threshold": float(threshold)}
    return write_json_atomically(Path(run_dir) / SEGMENTER_FILE, data, indent=2)



def read_model(run_dir: str | Path):
    """``(model, segmenter)``: the trained network (imports TensorFlow) and ``segmenter.json``.

    Raises:
        ValueError: missing or corrupt files, or a model that does not fit ``segmenter.json``.
    """
    from paz6d.segmentation.model import load_segmenter

    segmenter = SegmentationRunDir.validate(run_dir)
    path = SegmentationRunDir.model_path(run_dir)
    return load_segmenter(path, segmenter["input_size"], len(segmenter["class_names"])), segmenter
