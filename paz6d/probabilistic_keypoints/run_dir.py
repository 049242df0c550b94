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

from paz6d.backend.checks import as_array, as_points, number_field
from paz6d.backend.files import load_run_json, write_json_atomically
from paz6d.probabilistic_keypoints.config import ProbabilisticConfig
from paz6d.run_dir import CropRunDir, RunDir

KEYPOINTS_FILE = "gaussian_keypoints.json"
EVALUATION_FILE = "evaluation.json"
CALIBRATION_PNG = "calibration.png"
EXAMPLES_PNG = "occluded_examples.png"


class ProbabilisticKeypointsRunDir(CropRunDir):
    """A ``paz6d train probabilistic-keypoints`` run directory (files in the module docstring)."""

    KIND = "a probabilistic-keypoints"
    SETTINGS = ProbabilisticConfig
    MARKER_FILES = (RunDir.CONFIG_FILE, KEYPOINTS_FILE)
    REQUIRED_FILES = (RunDir.CONFIG_FILE, RunDir.MODEL_FILE, KEYPOINTS_FILE)

    @classmethod
    def read_keypoints(cls, run_dir: str | Path) -> tuple[np.ndarray, float]:
        """``points_model (N, 3)`` metres and ``covariance_scale`` from ``gaussian_keypoints.json``."""
        path = cls.path_of(run_dir, KEYPOINTS_FILE)
        data = load_run_json(path, ("points_model", "covariance_scale"), cls.KIND)
        points = as_points(data["points_model"], f"{path}: points_model (metres)", min_count=4)
        return points, number_field(data, "covariance_scale", str(path), positive=True)


def write_keypoints(run_dir: str | Path, points_model, covariance_scale: float = 1.0, targets=None,
                    method: str = "targets") -> Path:
    """Writes ``gaussian_keypoints.json``: ``points_model (N, 3)`` metres (what PnP uses), the covariance
    scale, optionally the ``targets (N, 3)`` the network was trained on, and how the points were obtained."""
    points_model = as_array(points_model, "points_model", (3,))
    if not (np.isfinite(covariance_scale) and covariance_scale > 0):
        raise ValueError(f"covariance_scale: expected a positive factor, got {covariance_scale}")
    data = {"points_model": points_model.tolist(), "units": "metres", "covariance_scale": float(covariance_scale),
            "method": str(method), "targets": None if targets is None else as_array(targets, "targets", (3,)).tolist()}
    return write_json_atomically(Path(run_dir) / KEYPOINTS_FILE, data, indent=2)


def write_json(run_dir: str | Path, name: str, data: dict[str, Any]) -> Path:
    """Writes ``metrics.json`` or ``evaluation.json``."""
    metrics_file = ProbabilisticKeypointsRunDir.METRICS_FILE
    if name not in (metrics_file, EVALUATION_FILE):
        raise ValueError(f"name: expected {metrics_file} or {EVALUATION_FILE}, got {name!r}")
    return write_json_atomically(Path(run_dir) / name, data, indent=2)


def read_model(run_dir: str | Path):
    """The trained network (imports TensorFlow)."""
    from paz6d.probabilistic_keypoints.model import load_model

    return load_model(ProbabilisticKeypointsRunDir.model_path(run_dir))
