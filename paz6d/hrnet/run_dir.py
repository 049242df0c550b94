"""The HRNet run directory: the only module that knows its file names and formats.

``paz6d train hrnet`` writes, and :class:`~paz6d.hrnet.pipeline.HRNetKeypoints2D` reads::

    RUN_DIR/hrnet.json        what the pipeline needs besides the weights: input_size, margin (crop side =
                              margin x longer box side), stride (crop pixels per heatmap cell),
                              num_keypoints, domain ("log": softmax logits, "value": Gaussians of peak 1),
                              sigma (heatmap cells), points_model (N, 3) metres in the object frame
                              (the farthest-point keypoints the network was trained on)
    RUN_DIR/model.keras       the network (loaded in Keras safe mode)
    RUN_DIR/config.json       the run: mesh, seed, config name, all settings (checked on resume)
    RUN_DIR/metrics.json      training summary
    RUN_DIR/evaluation.json   PCK on held-out renders
    RUN_DIR/keypoints.png     predicted (filled) vs true (hollow) keypoints on held-out crops
    RUN_DIR/pck.png           PCK against the threshold (fraction of the crop side)
    RUN_DIR/views_*.npz, crops_test.npz   caches of rendered training views and held-out crops

plus the shared trainer's ``checkpoints/``, ``log.csv``, ``tensorboard/`` and ``samples/``. Every reader
raises ``ValueError`` naming the file and the field that is missing or malformed.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any


from paz6d.backend.checks import as_points
from paz6d.backend.files import load_run_json, write_json_atomically
from paz6d.hrnet.config import HRNetConfig
from paz6d.run_dir import DescribedRunDir

EVALUATION_FILE = "evaluation.json"
KEYPOINTS_PLOT = "keypoints.png"
PCK_PLOT = "pck.png"
HELD_OUT_CROPS_FILE = "crops_test.npz"
DOMAINS = ("log", "value")
#: Fields of ``hrnet.json``.
DESCRIPTION_KEYS = ("input_size", "margin", "stride", "num_keypoints", "domain", "sigma", "points_model")
#: Fields of ``config.json``.
CONFIG_KEYS = ("mesh_path", "seed", "config", "settings")


class HRNetRunDir(DescribedRunDir):
    """A ``paz6d train hrnet`` run directory (files in the module docstring)."""

    KIND = "an HRNet"
    SETTINGS = HRNetConfig
    DESCRIPTION_FILE = "hrnet.json"

    @classmethod
    def check_config(cls, config: dict[str, Any], path: Path) -> dict[str, Any]:
        """``config.json`` checked for the fields a resumed run compares and its settings."""
        for key in CONFIG_KEYS:
            if key not in config:
                raise ValueError(f"{path}: missing field {key!r} (not an HRNet run configuration)")
        return super().check_config(config, path)

    @classmethod
    def read_description(cls, run_dir: str | Path) -> dict[str, Any]:
        """``hrnet.json``, checked: positive ``input_size``/``stride``/``num_keypoints`` (integers) and
        ``margin``/``sigma``, a known ``domain``, ``points_model`` finite ``(num_keypoints, 3)`` (returned
        as an array), ``input_size`` divisible by ``stride``."""
        path = Path(run_dir) / cls.DESCRIPTION_FILE
        data = load_run_json(path, DESCRIPTION_KEYS, cls.KIND)
        for name in ("input_size", "stride", "num_keypoints"):
            _positive(data, name, path, integer=True)
        for name in ("margin", "sigma"):
            _positive(data, name, path, integer=False)
        if data["input_size"] % data["stride"]:
            raise ValueError(f"{path}: input_size: expected a multiple of stride={data['stride']}, "
                             f"got {data['input_size']}")
        if data["domain"] not in DOMAINS:
            raise ValueError(f"{path}: domain: expected one of {DOMAINS}, got {data['domain']!r}")
        points = as_points(data["points_model"], f"{path}: points_model (metres)")
        if len(points) != data["num_keypoints"]:
            raise ValueError(f"{path}: points_model: expected num_keypoints = {data['num_keypoints']} points, "
                             f"got {len(points)}")
        return {**data, "points_model": points}


def held_out_crops_path(run_dir: str | Path) -> Path:
    """The held-out crops cache."""
    return Path(run_dir) / HELD_OUT_CROPS_FILE


def write_description(run_dir: str | Path, input_size: int, margin: float, stride: int, domain: str, sigma: float,
                      points_model, class_name: str | None = None) -> Path:
    """Writes ``hrnet.json`` (creating ``run_dir``).

    Args:
        input_size: crop side in pixels; margin: crop side / longer box side; stride: crop pixels per cell.
        domain: ``"log"`` or ``"value"`` (see :mod:`paz6d.hrnet.heatmaps`); sigma: target width in cells.
        points_model: ``(N, 3)`` metres, object frame, in heatmap order.
    """
    points_model = as_points(points_model, "points_model (metres)")
    if domain not in DOMAINS:
        raise ValueError(f"domain: expected one of {DOMAINS}, got {domain!r}")
    data = {"input_size": int(input_size), "margin": float(margin), "stride": int(stride),
            "num_keypoints": len(points_model), "domain": domain, "sigma": float(sigma),
            "points_model": points_model.tolist(), "units": "metres", "class_name": class_name}
    Path(run_dir).mkdir(parents=True, exist_ok=True)
    return write_json_atomically(Path(run_dir) / HRNetRunDir.DESCRIPTION_FILE, data, indent=2)


def _positive(data: dict, name: str, path: Path, integer: bool) -> float:
    value = data[name]
    valid = isinstance(value, int) if integer else isinstance(value, (int, float))
    if isinstance(value, bool) or not valid or not math.isfinite(value) or value <= 0:
        kind = "a positive integer" if integer else "a positive number"
        raise ValueError(f"{path}: {name}: expected {kind}, got {value!r}")
    return value



def write_evaluation(run_dir: str | Path, evaluation: dict[str, Any]) -> Path:
    """Writes ``evaluation.json`` (PCK on held-out renders)."""
    return write_json_atomically(Path(run_dir) / EVALUATION_FILE, evaluation, indent=2)


def read_model(run_dir: str | Path, description: dict[str, Any] | None = None):
    """The trained network (Keras safe mode; imports TensorFlow), checked against ``hrnet.json``.

    Raises:
        ValueError: missing/corrupt model, or one whose input size or keypoint count is not the description's.
    """
    from paz6d.hrnet.model import load_hrnet

    description = HRNetRunDir.read_description(run_dir) if description is None else description
    path = HRNetRunDir.model_path(run_dir)
    model = load_hrnet(path)
    size = model.input_shape[1]
    heatmaps = model.output["heatmaps"].shape
    expected = (description["input_size"] // description["stride"], description["num_keypoints"])
    if size != description["input_size"] or (heatmaps[1], heatmaps[3]) != expected:
        raise ValueError(f"{path}: the model takes {size}-pixel crops and predicts {heatmaps[3]} maps of "
                         f"{heatmaps[1]} cells, but {Path(run_dir) / HRNetRunDir.DESCRIPTION_FILE} describes "
                         f"{description['input_size']}-pixel crops and {expected[1]} maps of {expected[0]} cells")
    return model
