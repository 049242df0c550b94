"""Scoring HRNet keypoints on held-out crops: PCK (:mod:`evaluation.keypoints`) per decoder, the poses that
PnP makes of them (ADD, :mod:`evaluation.pose_errors`), and the PNGs (predicted vs true keypoints on crops;
PCK against the threshold)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from evaluation.keypoints import pck
from evaluation.pose_errors import add_error, rotation_error_deg, translation_error
from paz6d.abstract import Keypoints2D
from paz6d.backend.camera import Camera
from paz6d.backend.pnp import PnPError
from paz6d.backend.camera import transform_and_project
from paz6d.backend.draw import draw_keypoints, image_grid
from paz6d.backend.files import new_figure, save_figure_atomically
from paz6d.backend.image import resize, save_image
from paz6d.hrnet.heatmaps import DECODERS, decode_heatmaps
from paz6d.keypointnet.pipeline import KeypointPnP

#: PCK thresholds (fractions of the crop side) of the curve in ``pck.png`` and ``evaluation.json``.
PCK_ALPHAS = (0.01, 0.02, 0.03, 0.05, 0.075, 0.1, 0.15, 0.2)
#: The headline threshold: PCK@0.05 of the crop side.
HEADLINE_ALPHA = 0.05


def true_keypoints(points_model, K, T_model2cam) -> np.ndarray:
    """``(V, N, 2)`` projections (crop pixels) of ``points_model (N, 3)`` with ``K (V, 3, 3)``, ``T (V, 4, 4)``."""
    return np.stack([transform_and_project(points_model, T, intrinsics) for T, intrinsics in zip(T_model2cam, K)])


def score_keypoints(heatmaps, target, input_size: int, stride: int, domain: str, sigma: float,
                    decoders=DECODERS) -> tuple[dict, dict[str, np.ndarray]]:
    """PCK of each decoder's keypoints against ``target (V, N, 2)`` (crop pixels, crops ``input_size`` wide).

    Returns:
        ``(scores, keypoints)``: per decoder ``{"pck@0.05", "pck_curve": {alpha: pck}, "per_keypoint_pck@0.05",
        "median_px", "mean_px"}`` and the decoded ``(V, N, 2)`` keypoints.
    """
    scores, decoded = {}, {}
    for method in decoders:
        uv, _ = decode_heatmaps(heatmaps, stride, method, domain, sigma)
        curve = {alpha: pck(uv, target, input_size, alpha) for alpha in PCK_ALPHAS}
        headline = curve[HEADLINE_ALPHA]
        scores[method] = {f"pck@{HEADLINE_ALPHA}": headline.pck,
                          "pck_curve": {str(alpha): result.pck for alpha, result in curve.items()},
                          f"per_keypoint_pck@{HEADLINE_ALPHA}": [round(float(value),
                                                                       4) for value in headline.per_keypoint],
                          "median_px": float(np.median(headline.distances)),
                          "mean_px": float(np.mean(headline.distances))}
        decoded[method] = uv
    return scores, decoded


def score_poses(uv, K, T_model2cam, points_model, vertices, diameter: float, input_size: int,
                ransac_threshold: float = 5.0) -> dict:
    """Poses from keypoints by the pose pipeline's PnP step (:class:`~paz6d.keypointnet.pipeline.KeypointPnP`:
    RANSAC EPnP, then Levenberg–Marquardt) and their ADD against the true poses.

    Args:
        uv: ``(V, N, 2)`` keypoints in crop pixels; K: ``(V, 3, 3)`` crop intrinsics; T_model2cam: ``(V, 4, 4)``.
        points_model: ``(N, 3)`` metres; vertices: ``(M, 3)`` model points for ADD (metres); diameter: metres.
    Returns:
        ``{"count", "failures", "add_recall_0.1d", "median_rotation_deg", "median_translation_mm"}``
        (a failed PnP counts as a miss).
    """
    solve = KeypointPnP(points_model, ransac_threshold, input_size)
    errors, rotations, translations, failures = [], [], [], 0
    for keypoints, intrinsics, T in zip(uv, K, T_model2cam):
        try:
            pose = solve(Keypoints2D(keypoints, np.ones(len(keypoints))), (0, 0, input_size),
                         Camera(intrinsics, input_size, input_size))
        except PnPError:
            failures += 1
            errors.append(np.inf)
            continue
        estimate = pose.to_matrix()
        errors.append(float(add_error(estimate, T, vertices)[0]))
        rotations.append(float(rotation_error_deg(estimate[:3, :3], T[:3, :3])))
        translations.append(float(translation_error(estimate[:3, 3], T[:3, 3])))
    errors = np.asarray(errors)
    return {"count": len(errors), "failures": failures, "add_recall_0.1d": float(np.mean(errors < 0.1 * diameter)),
            "median_rotation_deg": float(np.median(rotations)) if rotations else None,
            "median_translation_mm": 1000 * float(np.median(translations)) if translations else None}


def save_keypoint_grid(path: str | Path, images, predicted, target, count: int = 16, columns: int = 4,
                       zoom: int = 2) -> Path:
    """PNG of the first ``count`` crops, enlarged ``zoom`` times, with predicted keypoints (filled) and true
    ones (hollow rings), keypoint ``i`` in colour ``i``; ``predicted``/``target`` are ``(V, N, 2)`` crop pixels."""
    tiles = []
    for image, guess, truth in list(zip(images, predicted, target))[:count]:
        image = np.asarray(image, dtype=np.uint8)
        canvas = resize(image, (image.shape[1] * zoom, image.shape[0] * zoom), "nearest")
        # pixel centres at integers: crop pixel u is at zoom * u + (zoom - 1) / 2 in the enlarged tile
        offset = (zoom - 1) / 2.0
        canvas = draw_keypoints(canvas, np.asarray(truth) * zoom + offset, visible=[False] * len(truth), radius=5)
        tiles.append(draw_keypoints(canvas, np.asarray(guess) * zoom + offset, radius=3))
    return save_image(path, image_grid(tiles, columns=columns))


def save_pck_plot(path: str | Path, scores: dict, input_size: int, count: int) -> Path:
    """PNG of PCK against the threshold (fraction of the crop side) for each decoder in ``scores``."""
    figure = new_figure(5.5, 4.0)
    axes = figure.add_subplot(1, 1, 1)
    for method, result in scores.items():
        alphas = [float(alpha) for alpha in result["pck_curve"]]
        axes.plot(alphas, [100 * value for value in result["pck_curve"].values()], marker="o", markersize=3,
                  label=f"{method} (PCK@{HEADLINE_ALPHA} {100 * result[f'pck@{HEADLINE_ALPHA}']:.1f}%)")
    axes.axvline(HEADLINE_ALPHA, color="grey", linestyle=":", linewidth=1)
    axes.set_xlabel(f"threshold (fraction of the {input_size}-pixel crop side)")
    axes.set_ylabel("correct keypoints (%)")
    axes.set_title(f"HRNet keypoints, {count} held-out crops")
    axes.set_ylim(0, 100)
    axes.grid(alpha=0.3)
    axes.legend(loc="lower right", fontsize=8)
    figure.tight_layout()
    return save_figure_atomically(figure, path)
