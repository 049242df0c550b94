"""Scoring and reporting shared by the demos: one pose scorer with one key set, one table printer and
one JSON writer (values that were not measured, NaN or infinite, are written as ``null``).

The metric keys of :func:`score_poses` (lengths in metres, angles in degrees)::

    metric             "ADD" or "ADD-S" (symmetric objects)
    count              scored instances, misses included
    diameter_m         object diameter d
    recall_0.1d        fraction with error < 0.1 d (the BOP/LINEMOD criterion)
    recall_0.05d       fraction with error < 0.05 d
    auc_10cm           area under the accuracy-threshold curve up to 10 cm (PoseCNN)
    median_error_m     median ADD(-S)
    rotation_error_deg {median, mean, below_5, below_10}
    translation_error_m {median, mean}
    z_error_m_median   median |z_est - z_gt|
    failures           instances without an estimate (e.g. PnP with too few keypoints)
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from evaluation.pose_errors import accuracy_auc, add_error, adi_error, rotation_error_deg, translation_error
from paz6d.backend.files import finite_or_none, null_non_finite, write_json_atomically

AUC_MAX_THRESHOLD = 0.1  # metres (PoseCNN's ADD(-S) AUC)


@dataclass(frozen=True)
class PoseScores:
    """What :func:`score_poses` returns.

    Attributes:
        metrics: the summary (keys in the module doc), JSON-ready.
        errors_m: ``(N,)`` ADD or ADD-S per instance in metres, ``inf`` for a miss.
        rotation_errors_deg: ``(N,)`` rotation error per instance, ``inf`` for a miss.
    """

    metrics: dict
    errors_m: np.ndarray
    rotation_errors_deg: np.ndarray


def score_poses(T_est: Sequence[np.ndarray | None], T_gt: np.ndarray, points: np.ndarray, diameter: float,
                symmetric: bool = False) -> PoseScores:
    """Scores estimated poses against the ground truth.

    Args:
        T_est: ``N`` estimated ``4×4`` T_model2cam (metres), ``None`` for a miss.
        T_gt: ``(N, 4, 4)`` ground-truth T_model2cam.
        points: ``(P, 3)`` model points in metres (for ADD / ADD-S).
        diameter: object diameter in metres.
        symmetric: score with ADD-S (closest point) instead of ADD.
    """
    T_gt = np.asarray(T_gt, dtype=np.float64).reshape(-1, 4, 4)
    if len(T_est) != len(T_gt):
        raise ValueError(f"T_est: expected {len(T_gt)} poses like T_gt, got {len(T_est)}")
    found = np.array([pose is not None for pose in T_est], dtype=bool)
    estimates = np.stack([np.eye(4) if pose is None else np.asarray(pose, dtype=np.float64) for pose in T_est]
                         ) if len(T_est) else np.zeros((0, 4, 4))
    errors, rotation, translation, z_error = (np.full(len(T_gt), np.inf) for _ in range(4))
    if found.any():
        error_function = adi_error if symmetric else add_error
        errors[found] = error_function(estimates[found], T_gt[found], points)
        rotation[found] = rotation_error_deg(estimates[found, :3, :3], T_gt[found, :3, :3])
        translation[found] = translation_error(estimates[found, :3, 3], T_gt[found, :3, 3])
        z_error[found] = np.abs(estimates[found, 2, 3] - T_gt[found, 2, 3])

    def statistic(function, values):
        return finite_or_none(function(values)) if len(values) else None

    metrics = {"metric": "ADD-S" if symmetric else "ADD", "count": len(T_gt), "diameter_m": float(diameter),
               "recall_0.1d": statistic(np.mean, errors < 0.1 * diameter),
               "recall_0.05d": statistic(np.mean, errors < 0.05 * diameter),
               "auc_10cm": accuracy_auc(errors, AUC_MAX_THRESHOLD),
               "median_error_m": statistic(np.median, errors),
               "rotation_error_deg": {"median": statistic(np.median, rotation), "mean": statistic(np.mean, rotation),
                                      "below_5": statistic(np.mean, rotation < 5),
                                      "below_10": statistic(np.mean, rotation < 10)},
               "translation_error_m": {"median": statistic(np.median, translation),
                                       "mean": statistic(np.mean, translation)},
               "z_error_m_median": statistic(np.median, z_error),
               "failures": int((~found).sum())}
    return PoseScores(metrics, errors, rotation)


def number(value: float | None, scale: float = 1.0, unit: str = "", digits: int = 1) -> str:
    """``scale × value`` with ``digits`` decimals and ``unit``; ``"-"`` for a value not measured."""
    value = finite_or_none(value)
    return "-" if value is None else f"{scale * value:.{digits}f}{unit}"


def pose_rows(metrics: dict, suffix: str = "") -> list[tuple[str, str]]:
    """Table rows of a :func:`score_poses` summary; ``suffix`` names the variant (e.g. ``", PnP"``)."""
    rotation, translation = metrics["rotation_error_deg"], metrics["translation_error_m"]
    return [(f"{metrics['metric']} recall @ 0.1 d{suffix}", number(metrics["recall_0.1d"], 100, " %")),
            (f"{metrics['metric']} AUC (0-10 cm){suffix}", number(metrics["auc_10cm"], 100, " %")),
            (f"median rotation error{suffix}", number(rotation["median"], unit=" deg", digits=2)),
            (f"rotation error < 5 / 10 deg{suffix}",
             f"{number(rotation['below_5'], 100, ' %')} / {number(rotation['below_10'], 100, ' %')}"),
            (f"median translation error{suffix}", number(translation["median"], 1000, " mm")),
            (f"median |z| error{suffix}", number(metrics["z_error_m_median"], 1000, " mm")),
            (f"no estimate{suffix}", f"{metrics['failures']} of {metrics['count']}")]


def print_rows(rows: list[tuple[str, str]]) -> None:
    """Prints ``(name, value)`` rows as an aligned two-column table."""
    width = max(len(name) for name, _ in rows)
    print("\n" + "\n".join(f"  {name:<{width}}  {value}" for name, value in rows))


def write_report(path: str | Path, report: dict) -> Path:
    """Writes ``report`` as indented JSON, atomically, with NaN and infinities as ``null``."""
    return write_json_atomically(path, null_non_finite(report), indent=2)
