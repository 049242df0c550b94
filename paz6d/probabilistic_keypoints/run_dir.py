"""The probabilistic-keypoints run directory: the only module that knows its file names and formats.

``paz6d train probabilistic-keypoints`` writes, and
:class:`~paz6d.probabilistic_keypoints.pipeline.ProbabilisticKeypointPose6D` reads::

    RUN_DIR/config.json        input_size, margin (crop side = margin x longer box side), downsample, mesh, settings
    RUN_DIR/model.keras        the network (loaded in Keras safe mode)
    RUN_DIR/gaussian_keypoints.json
                               points_model (N, 3) metres (object frame; triangulated, or the targets),
                               targets (N, 3) the farthest-point keypoints trained on, method,
                               covariance_scale (the factor fitted on validation views, > 0)
    RUN_DIR/metrics.json       training summary
    RUN_DIR/evaluation.json    calibration and PnP (plain vs covariance-weighted) on held-out clean and occluded views
    RUN_DIR/calibration.png    observed vs expected coverage of the k-sigma ellipses
    RUN_DIR/occluded_examples.png  occluded test crops with the keypoints and their 2-sigma ellipses
    RUN_DIR/views_*.npz        rendered views (training, validation) and test crops, reused on resume

Every reader raises ``ValueError`` naming the file and what is missing or malformed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from paz6d.backend.checks import as_array, integer_field, number_field
from paz6d.backend.files import check_run_files, load_json_object, load_run_json, write_json_atomically

CONFIG_FILE = "config.json"
MODEL_FILE = "model.keras"
KEYPOINTS_FILE = "gaussian_keypoints.json"
METRICS_FILE = "metrics.json"
EVALUATION_FILE = "evaluation.json"
CALIBRATION_PNG = "calibration.png"
EXAMPLES_PNG = "occluded_examples.png"
#: Keys of ``config.json`` that the pipeline reads.
PIPELINE_CONFIG_KEYS = ("input_size", "margin", "downsample")
#: Files that mark a directory as a probabilistic-keypoints run.
MARKER_FILES = (CONFIG_FILE, KEYPOINTS_FILE)
#: Files without which a run directory cannot estimate poses.
REQUIRED_FILES = (CONFIG_FILE, MODEL_FILE, KEYPOINTS_FILE)
#: How messages name these run directories.
KIND = "a probabilistic-keypoints"



def path_of(run_dir: str | Path, name: str) -> Path:
    """``run_dir / name`` for one of this module's file names."""
    return Path(run_dir) / name


def views_path(run_dir: str | Path, name: str) -> Path:
    """The cache ``views_<name>.npz`` (``train``, ``val``, ``test``)."""
    return Path(run_dir) / f"views_{name}.npz"


def write_config(run_dir: str | Path, config: dict[str, Any]) -> Path:
    """Writes ``config.json`` (creating ``run_dir``); ``config`` must hold the pipeline's keys."""
    missing = [key for key in PIPELINE_CONFIG_KEYS if key not in config]
    if missing:
        raise ValueError(f"config: missing key(s) {missing} the pipeline needs")
    Path(run_dir).mkdir(parents=True, exist_ok=True)
    return write_json_atomically(path_of(run_dir, CONFIG_FILE), config, indent=2)


def read_config(run_dir: str | Path) -> dict[str, Any]:
    """``config.json``, checked for ``input_size``, ``margin`` and ``downsample``."""
    path = path_of(run_dir, CONFIG_FILE)
    data = load_run_json(path, PIPELINE_CONFIG_KEYS, KIND)
    for name in ("input_size", "downsample"):
        integer_field(data, name, str(path), minimum=1)
    number_field(data, "margin", str(path), positive=True)
    return data


def write_keypoints(run_dir: str | Path, points_model, covariance_scale: float = 1.0, targets=None,
                    method: str = "targets") -> Path:
    """Writes ``gaussian_keypoints.json``: ``points_model (N, 3)`` metres (what PnP uses), the covariance
    scale, optionally the ``targets (N, 3)`` the network was trained on, and how the points were obtained."""
    points_model = as_array(points_model, "points_model", (3,))
    if not (np.isfinite(covariance_scale) and covariance_scale > 0):
        raise ValueError(f"covariance_scale: expected a positive factor, got {covariance_scale}")
    data = {"points_model": points_model.tolist(), "units": "metres", "covariance_scale": float(covariance_scale),
            "method": str(method), "targets": None if targets is None else as_array(targets, "targets", (3,)).tolist()}
    return write_json_atomically(path_of(run_dir, KEYPOINTS_FILE), data, indent=2)


def read_keypoints(run_dir: str | Path) -> tuple[np.ndarray, float]:
    """``points_model (N, 3)`` metres and ``covariance_scale`` from ``gaussian_keypoints.json``."""
    path = path_of(run_dir, KEYPOINTS_FILE)
    data = load_run_json(path, ("points_model", "covariance_scale"), KIND)
    try:
        points = np.asarray(data["points_model"], dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{path}: points_model: expected a list of [x, y, z] rows (metres)") from None
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 4 or not np.all(np.isfinite(points)):
        raise ValueError(f"{path}: points_model: expected finite (N >= 4, 3) metres, got shape {points.shape}")
    return points, number_field(data, "covariance_scale", str(path), positive=True)


def write_json(run_dir: str | Path, name: str, data: dict[str, Any]) -> Path:
    """Writes ``metrics.json`` or ``evaluation.json``."""
    if name not in (METRICS_FILE, EVALUATION_FILE):
        raise ValueError(f"name: expected {METRICS_FILE} or {EVALUATION_FILE}, got {name!r}")
    return write_json_atomically(path_of(run_dir, name), data, indent=2)


def read_metrics(run_dir: str | Path) -> dict[str, Any] | None:
    """``metrics.json`` of an earlier invocation, ``None`` when there is none (``ValueError`` naming the
    file when it is not a JSON object)."""
    path = path_of(run_dir, METRICS_FILE)
    return load_json_object(path) if path.is_file() else None


def read_model(run_dir: str | Path):
    """The trained network (imports TensorFlow)."""
    from paz6d.probabilistic_keypoints.model import load_model

    return load_model(path_of(run_dir, MODEL_FILE))


def validate(run_dir: str | Path) -> Path:
    """Checks that ``run_dir`` is a directory with every file the pipeline needs and readable configuration
    and keypoints; returns it as a Path."""
    run_dir = check_run_files(run_dir, REQUIRED_FILES, KIND)
    read_config(run_dir)
    read_keypoints(run_dir)
    return run_dir
