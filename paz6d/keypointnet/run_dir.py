"""The KeypointNet run directory: the only module that knows its file names and formats.

``paz6d train keypointnet`` writes, and :class:`~paz6d.keypointnet.pipeline.KeypointPose6D`, the demo
and ``paz6d estimate`` read::

    RUN_DIR/config.json      input_size, margin (crop side = margin x longer box side), downsample, mode, mesh ...
    RUN_DIR/model.keras      the network (loaded in Keras safe mode)
    RUN_DIR/object.json      diameter (m) and hull_points (M, 3) metres, the convex hull of the mesh
    RUN_DIR/keypoints.json   points_model (N, 3) metres in the object frame, usable flags, method
                             ("triangulated" or "lifted-median"; the supervised mode also keeps its targets)
    RUN_DIR/metrics.json     training summary
    RUN_DIR/evaluation.json  the demo's evaluation
    RUN_DIR/views_*.npz      training caches of rendered views

Every reader raises ``ValueError`` naming the file and what is missing or malformed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from paz6d.backend.checks import as_array, integer_field, number_field
from paz6d.backend.files import check_run_files, load_run_json, write_json_atomically

CONFIG_FILE = "config.json"
MODEL_FILE = "model.keras"
KEYPOINTS_FILE = "keypoints.json"
OBJECT_FILE = "object.json"
METRICS_FILE = "metrics.json"
EVALUATION_FILE = "evaluation.json"
#: Keys of ``config.json`` that the pipeline reads.
PIPELINE_CONFIG_KEYS = ("input_size", "margin", "downsample")
#: Files without which a run directory cannot estimate poses.
REQUIRED_FILES = (CONFIG_FILE, MODEL_FILE, KEYPOINTS_FILE)
#: Files that mark a directory as a KeypointNet run (see :func:`paz6d.run_dirs.method_of`).
MARKER_FILES = (CONFIG_FILE, KEYPOINTS_FILE)
#: How messages name these run directories.
KIND = "a KeypointNet"



def _numeric_array(value, path: Path, name: str) -> np.ndarray:
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{path}: {name}: expected a list of numeric rows") from None


def model_path(run_dir: str | Path) -> Path:
    """Where the network is (or will be) saved."""
    return Path(run_dir) / MODEL_FILE


def views_path(run_dir: str | Path, name: str) -> Path:
    """The training cache ``views_<name>.npz`` (``name``: ``train``, ``val``, ``lift``)."""
    return Path(run_dir) / f"views_{name}.npz"


def config_path(run_dir: str | Path) -> Path:
    """The run's ``config.json``."""
    return Path(run_dir) / CONFIG_FILE


def write_config(run_dir: str | Path, config: dict[str, Any]) -> Path:
    """Writes ``config.json`` (creating ``run_dir``); ``config`` must hold the pipeline's keys."""
    missing = [key for key in PIPELINE_CONFIG_KEYS if key not in config]
    if missing:
        raise ValueError(f"config: missing key(s) {missing} the pipeline needs")
    Path(run_dir).mkdir(parents=True, exist_ok=True)
    return write_json_atomically(config_path(run_dir), config, indent=2)


def read_config(run_dir: str | Path) -> dict[str, Any]:
    """``config.json``, checked for ``input_size``, ``margin`` and ``downsample``."""
    path = config_path(run_dir)
    data = load_run_json(path, PIPELINE_CONFIG_KEYS, KIND)
    for name in ("input_size", "downsample"):
        integer_field(data, name, str(path), minimum=1)
    number_field(data, "margin", str(path), positive=True)
    return data


def write_keypoints(run_dir: str | Path, points_model, usable, method: str, error=None, targets=None) -> Path:
    """Writes ``keypoints.json`` (temporary file, then rename).

    Args:
        points_model: ``(N, 3)`` metres, object frame; usable: ``(N,)`` flags.
        method: how the points were obtained (e.g. ``"triangulated"``).
        error: optional ``(N,)`` per-keypoint fit error (pixels for lifted keypoints).
        targets: optional ``(N, 3)`` keypoints the network was trained on (supervised mode).
    """
    points_model = as_array(points_model, "points_model", (3,))
    usable = np.asarray(usable, dtype=bool)
    if usable.shape != (len(points_model),):
        raise ValueError(f"usable: expected {len(points_model)} flags, got shape {usable.shape}")
    data = {"points_model": points_model.tolist(), "usable": usable.tolist(), "method": method, "units": "metres",
            "error": None if error is None else np.asarray(error, dtype=np.float64).tolist(),
            "targets": None if targets is None else as_array(targets, "targets", (3,)).tolist()}
    return write_json_atomically(Path(run_dir) / KEYPOINTS_FILE, data, indent=2)


def read_keypoints(run_dir: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """``points_model (N, 3)`` metres and ``usable (N,)`` flags from a run's ``keypoints.json``."""
    path = Path(run_dir) / KEYPOINTS_FILE
    data = load_run_json(path, ("points_model", "usable"), KIND)
    points = _numeric_array(data["points_model"], path, "points_model")
    if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
        raise ValueError(f"{path}: points_model: expected finite (N, 3) metres, got shape {points.shape}")
    usable = np.asarray(data["usable"])
    if usable.shape != (len(points),) or usable.dtype != bool:
        raise ValueError(f"{path}: usable: expected {len(points)} true/false flags, got shape {usable.shape}")
    return points, usable


def write_object(run_dir: str | Path, diameter: float, hull_points) -> Path:
    """Writes ``object.json``: the object's diameter and convex-hull points (metres)."""
    hull_points = as_array(hull_points, "hull_points", (3,))
    return write_json_atomically(Path(run_dir) / OBJECT_FILE, {"diameter": float(diameter),
                                                               "hull_points": hull_points.tolist(), "units": "metres"})


def read_object(run_dir: str | Path) -> dict:
    """``{"diameter": float, "hull_points": (M, 3)}`` (metres) from a run's ``object.json``."""
    path = Path(run_dir) / OBJECT_FILE
    data = load_run_json(path, ("diameter", "hull_points"), KIND)
    hull = _numeric_array(data["hull_points"], path, "hull_points")
    if hull.ndim != 2 or hull.shape[1] != 3 or len(hull) < 4 or not np.all(np.isfinite(hull)):
        raise ValueError(f"{path}: hull_points: expected finite (M >= 4, 3) metres, got shape {hull.shape}")
    return {"diameter": number_field(data, "diameter", str(path), positive=True), "hull_points": hull}


def read_model(run_dir: str | Path):
    """The trained KeypointNet (imports TensorFlow)."""
    from paz6d.keypointnet.model import load_keypointnet

    return load_keypointnet(model_path(run_dir))


def write_metrics(run_dir: str | Path, metrics: dict[str, Any]) -> Path:
    """Writes the training summary ``metrics.json``."""
    return write_json_atomically(Path(run_dir) / METRICS_FILE, metrics, indent=2)


def evaluation_path(run_dir: str | Path) -> Path:
    """Where the demo writes its evaluation of the run."""
    return Path(run_dir) / EVALUATION_FILE


def validate(run_dir: str | Path) -> Path:
    """Checks that ``run_dir`` is a directory with every file the pipeline needs and readable
    configuration and keypoints; returns it as a Path."""
    run_dir = check_run_files(run_dir, REQUIRED_FILES, KIND)
    read_config(run_dir)
    read_keypoints(run_dir)
    return run_dir
