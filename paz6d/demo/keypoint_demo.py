"""Keypoint demo: train KeypointNet (the quick config by default, or robust) on a mesh, estimate 6D poses
on held-out synthetic images with ground-truth boxes, score them with ``evaluation.pose_errors`` and write
a report.

Meant to be called by ``paz6d demo --keypoints``::

    report = run_keypoint_demo(Path("demo_output"), Path("demo_output/mesh/obj_000001.ply"), mesh_scale=0.001)

Outputs in ``out_dir``: ``keypointnet_<mode>/`` (run directories that
:class:`~paz6d.keypointnet.pipeline.KeypointPose6D` loads), ``keypoint_report.json`` (every number),
``keypoint_recall.png`` (ADD(-S) recall against threshold) and ``keypoint_<mode>_examples.png``
(crops with predicted keypoints, the ground-truth 3D box in green and the estimate in red).
Each mode is scored three times (:data:`EVALUATIONS`): PnP on one crop per box (``pnp``, the
pipeline's default), on 13 crops per box (``pnp_13_crops``) and on one crop with the depth fitted to the
ground-truth box (``pnp_depth_from_box``); see :class:`~paz6d.keypointnet.pipeline.KeypointPose6D`.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from paz6d.backend.files import finite_or_none, new_figure, save_figure_atomically
from paz6d.demo.report import number, pose_rows, print_rows, score_poses, write_report
from paz6d.keypointnet import run_dir as keypointnet_run_dir
from paz6d.keypointnet.config import KeypointConfig, KeypointTraining
from paz6d.keypointnet.train import train_keypointnet

TEST_SEED_OFFSET = 1_000_003  # test images never share a seed with training/validation views
MANY_CROPS = 13
#: ``(report key, depth_from_box, crops per box)`` of each scoring of a mode.
EVALUATIONS = (("pnp", False, 1), (f"pnp_{MANY_CROPS}_crops", False, MANY_CROPS), ("pnp_depth_from_box", True, 1))


def mode_run_dir(out_dir: str | Path, mode: str) -> Path:
    """The run directory of the KeypointNet trained in ``mode`` by :func:`run_keypoint_demo` in ``out_dir``."""
    return Path(out_dir) / f"keypointnet_{mode}"


def evaluate_keypoint_pose(run_dir: str | Path, test, points: np.ndarray, object_diameter: float, camera,
                           symmetric: bool = False, depth_from_box: bool = False, crops: int = 1,
                           chunk: int = 25) -> tuple[dict, list]:
    """Scores :class:`KeypointPose6D` on rendered test images with their ground-truth boxes.

    Args:
        test: :class:`~paz6d.keypointnet.views.TestImages`.
        points: ``(N, 3)`` model points in metres (for ADD / ADD-S).
        symmetric: score with ADD-S (ADI) instead of ADD.
        depth_from_box, crops: the :class:`KeypointPose6D` options of those names.
    Returns:
        ``(metrics, poses)``: the :func:`~paz6d.demo.report.score_poses` summary (PnP failures are its
        ``failures``) plus ``milliseconds_per_crop``, ``error`` (why no image could be estimated, e.g.
        too few usable keypoints, else ``None``) and ``errors_m`` (per image, ``None`` for a miss);
        poses are ``Pose6D`` or ``None``.
    """
    from paz6d.backend.pnp import PnPError
    from paz6d.keypointnet.pipeline import KeypointPose6D

    poses: list = [None] * len(test.images)
    problem = None
    started = time.perf_counter()
    try:
        estimator = KeypointPose6D(run_dir, camera, crops=crops, depth_from_box=depth_from_box)
    except PnPError as error:  # e.g. too few usable lifted keypoints: every image is a miss
        problem = str(error)
    else:
        poses = []
        for start in range(0, len(test.images), chunk):
            poses.extend(estimator.estimate_batch(list(test.images[start:start + chunk]),
                                                  list(test.boxes[start:start + chunk])))
    milliseconds = 1000.0 * (time.perf_counter() - started) / len(test.images)
    scores = score_poses([None if pose is None else pose.to_matrix() for pose in poses], test.T_model2cam, points,
                         object_diameter, symmetric)
    metrics = {**scores.metrics, "milliseconds_per_crop": round(milliseconds, 2), "error": problem,
               "errors_m": [finite_or_none(value) for value in scores.errors_m]}
    return metrics, poses


def _examples_png(path: Path, run_dir: Path, test, poses, camera, points: np.ndarray, count: int = 12) -> Path:
    from paz6d.backend.camera import transform_and_project
    from paz6d.backend.draw import draw_cube, draw_keypoints, image_grid
    from paz6d.backend.image import save_image
    from paz6d.backend.mesh import bounding_box_corners
    from paz6d.backend.square_crop import crop_square, crop_transform, square_window
    from paz6d.keypointnet.pipeline import KeypointPose6D

    estimator = KeypointPose6D(run_dir, camera)
    corners = bounding_box_corners(points)
    tiles = []
    for index in range(min(count, len(test.images))):
        window = square_window(test.boxes[index], estimator.margin * 1.2)
        A = crop_transform(window, 192)

        def to_crop(pixels):
            return pixels @ A[:2, :2].T + A[:2, 2]

        tile = crop_square(test.images[index], window, 192)
        tile = draw_cube(tile, to_crop(transform_and_project(corners, test.T_model2cam[index], camera.K)), (0, 255, 0))
        if poses[index] is not None:
            tile = draw_cube(tile, to_crop(transform_and_project(corners, poses[index].to_matrix(), camera.K)),
                             (255, 0, 0))
        keypoints = estimator.detect(test.images[index], test.boxes[index])
        tiles.append(draw_keypoints(tile, to_crop(keypoints.points), radius=3))
    return save_image(path, image_grid(tiles, columns=4))


def _recall_png(path: Path, curves: dict[str, np.ndarray], object_diameter: float, metric: str) -> Path:
    thresholds = np.linspace(0.0, 0.2, 101)
    figure = new_figure(5, 4, dpi=120)
    axis = figure.add_subplot()
    for name, errors in curves.items():
        recall = [(errors < threshold * object_diameter).mean() for threshold in thresholds]
        axis.plot(thresholds, recall, label=name)
    axis.axvline(0.1, color="grey", linestyle="--", linewidth=0.8)
    axis.set_xlabel(f"{metric} threshold (fraction of the diameter)")
    axis.set_ylabel("recall")
    axis.set_ylim(0, 1)
    axis.grid(alpha=0.3)
    axis.legend()
    axis.set_title(f"KeypointPose6D, {metric} recall")
    figure.tight_layout()
    return save_figure_atomically(figure, path)


def run_keypoint_demo(out_dir: Path, mesh_path: Path, mesh_scale: float = 1.0,
                      modes: tuple[str, ...] = ("supervised",), config: str = "quick",
                      test_images: int = 200, seed: int = 0, workers: int = 2, steps: int | None = None,
                      symmetric: bool = False, progress: bool = True, settings: KeypointConfig | None = None,
                      orientation_network: bool = False) -> dict:
    """Trains each mode in ``modes`` and evaluates it on ``test_images`` held-out synthetic images.

    Args:
        out_dir: output folder (created); re-running resumes training and redoes the evaluation.
        mesh_path: the object mesh; ``mesh_scale`` converts its units to metres (0.001 for BOP mm).
        steps: override the config's training steps.
        symmetric: the object is symmetric (score with ADD-S).
        settings: replace the preset ``config`` (e.g. a smaller network for tests).
        orientation_network: train with the orientation network (a BOP mesh with a half-turn symmetry in
            its ``models_info.json``; implies ``symmetric``).
    Returns:
        The report (also written to ``out_dir/keypoint_report.json``).
    """
    from paz6d.backend.tensorflow_guard import import_tensorflow

    import_tensorflow()
    from paz6d.backend.mesh import diameter, load_mesh
    from paz6d.keypointnet.views import ViewSampling, render_test_images

    symmetric = symmetric or orientation_network
    started = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    mesh = load_mesh(mesh_path, mesh_scale)
    points = np.asarray(mesh.vertices)
    object_diameter = diameter(points)
    sampling = ViewSampling()
    report: dict = {"mesh": str(mesh_path), "mesh_scale": mesh_scale, "diameter_m": object_diameter,
                    "config": config, "seed": seed, "test_images": test_images, "modes": {}}
    runs = {}
    for mode in modes:
        run_dir = mode_run_dir(out_dir, mode)
        runs[mode] = run_dir
        report["modes"][mode] = {"training": train_keypointnet(
            KeypointTraining(run_dir, Path(mesh_path), mesh_scale=mesh_scale, config=config, mode=mode, seed=seed,
                             workers=workers, steps=steps, progress=progress, settings=settings,
                             orientation_network=orientation_network))}
    render_started = time.perf_counter()
    test = render_test_images(mesh_path, test_images, seed + TEST_SEED_OFFSET, sampling, mesh_scale, workers,
                              progress=progress)
    report["test_render_seconds"] = round(time.perf_counter() - render_started, 1)
    curves = {}
    for mode, run_dir in runs.items():
        evaluations = {}
        for variant, from_box, crops in EVALUATIONS:
            metrics, poses = evaluate_keypoint_pose(run_dir, test, points, object_diameter, sampling.camera,
                                                    symmetric, depth_from_box=from_box, crops=crops)
            curves[f"{mode}, {variant}"] = np.array([np.inf if value is None else value
                                                     for value in metrics["errors_m"]])
            report["modes"][mode][variant] = {key: value for key, value in metrics.items() if key != "errors_m"}
            evaluations[variant] = metrics
            if variant == "pnp" and metrics["error"] is None:
                _examples_png(out_dir / f"keypoint_{mode}_examples.png", run_dir, test, poses, sampling.camera, points)
        write_report(keypointnet_run_dir.evaluation_path(run_dir), evaluations)
    _recall_png(out_dir / "keypoint_recall.png", curves, object_diameter, "ADD-S" if symmetric else "ADD")
    report["total_seconds"] = round(time.perf_counter() - started, 1)
    write_report(out_dir / "keypoint_report.json", report)
    _print_summary(report, out_dir)
    return report


def _print_summary(report: dict, out_dir: Path) -> None:
    rows = []
    for mode, result in report["modes"].items():
        plain, boxed, cropped = result["pnp"], result["pnp_depth_from_box"], result[f"pnp_{MANY_CROPS}_crops"]
        rows += [(f"KeypointNet ({mode}): test images", f"{plain['count']}"),
                 ("keypoint re-projection (median)", number(result["training"].get("reprojection_px_median"),
                                                            unit=" px", digits=2)),
                 *pose_rows(plain, ", PnP"),
                 (f"{cropped['metric']} recall @ 0.1 d, PnP, {MANY_CROPS} crops per box",
                  number(cropped["recall_0.1d"], 100, " %")),
                 (f"{boxed['metric']} recall @ 0.1 d, PnP + depth_from_box", number(boxed["recall_0.1d"], 100, " %"))]
        if plain["error"]:
            rows.append(("why no estimate, PnP", plain["error"]))
    rows.append(("total time", number(report["total_seconds"], 1 / 60, " min")))
    print_rows(rows)
    print(f"\nreport: {out_dir / 'keypoint_report.json'}; plots: {out_dir / 'keypoint_recall.png'}")
