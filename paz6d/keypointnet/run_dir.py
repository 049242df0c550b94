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

import numpy as np

from paz6d.backend.checks import as_array, as_points, number_field
from paz6d.backend.files import load_run_json, null_non_finite, write_json_atomically
from paz6d.keypointnet.config import KeypointConfig
from paz6d.run_dir import CropRunDir, RunDir

KEYPOINTS_FILE = "keypoints.json"
OBJECT_FILE = "object.json"
EVALUATION_FILE = "evaluation.json"


class KeypointNetRunDir(CropRunDir):
    """A ``paz6d train keypointnet`` run directory (files in the module docstring)."""

    KIND = "a KeypointNet"
    SETTINGS = KeypointConfig
    MARKER_FILES = (RunDir.CONFIG_FILE, KEYPOINTS_FILE)
    REQUIRED_FILES = (RunDir.CONFIG_FILE, RunDir.MODEL_FILE, KEYPOINTS_FILE)

    @classmethod
    def read_keypoints(cls, run_dir: str | Path) -> tuple[np.ndarray, np.ndarray]:
        """``points_model (N, 3)`` metres and ``usable (N,)`` flags from a run's ``keypoints.json``."""
        path = Path(run_dir) / KEYPOINTS_FILE
        data = load_run_json(path, ("points_model", "usable"), cls.KIND)
        points = as_points(data["points_model"], f"{path}: points_model (metres)")
        usable = np.asarray(data["usable"])
        if usable.shape != (len(points),) or usable.dtype != bool:
            raise ValueError(f"{path}: usable: expected {len(points)} true/false flags, got shape {usable.shape}")
        return points, usable


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
            "error": None if error is None else null_non_finite(np.asarray(error, dtype=np.float64).tolist()),
            "targets": None if targets is None else as_array(targets, "targets", (3,)).tolist()}
    return write_json_atomically(Path(run_dir) / KEYPOINTS_FILE, data, indent=2)


def write_object(run_dir: str | Path, diameter: float, hull_points) -> Path:
    """Writes ``object.json``: the object's diameter and convex-hull points (metres)."""
    hull_points = as_array(hull_points, "hull_points", (3,))
    return write_json_atomically(Path(run_dir) / OBJECT_FILE, {"diameter": float(diameter),
                                                               "hull_points": hull_points.tolist(), "units": "metres"})


def read_object(run_dir: str | Path) -> dict:
    """``{"diameter": float, "hull_points": (M, 3)}`` (metres) from a run's ``object.json``."""
    path = Path(run_dir) / OBJECT_FILE
    data = load_run_json(path, ("diameter", "hull_points"), KeypointNetRunDir.KIND)
    hull = as_points(data["hull_points"], f"{path}: hull_points (metres)", min_count=4)
    return {"diameter": number_field(data, "diameter", str(path), positive=True), "hull_points": hull}


def read_model(run_dir: str | Path):
    """The trained KeypointNet (imports TensorFlow)."""
    from paz6d.keypointnet.model import load_keypointnet

    return load_keypointnet(KeypointNetRunDir.model_path(run_dir))


def evaluation_path(run_dir: str | Path) -> Path:
    """Where the demo writes its evaluation of the run."""
    return Path(run_dir) / EVALUATION_FILE
