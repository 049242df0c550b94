"""The AAE demo run by ``paz6d demo``: from a mesh to a scored 6D pose estimator on a CPU, end to end.

1. writes the procedural, asymmetric, coloured demo object (``DIR/mesh/obj_000001.ply`` in
   millimetres + ``models_info.json``, BOP units);
2. generates held-out synthetic test images with ``data_gen`` (random lights, backgrounds,
   distractors, occluders; a seed different from training);
3. with ``scene_crops > 0``, generates training scenes the same way (seed 0, ``DIR/train_data``): that
   share of the AAE's training inputs is cut from them, so it sees real occlusion by the generator's occluders;
4. trains an Augmented Autoencoder with the quick config (``DIR/model/``, an ``ImplicitPose6D`` run dir);
5. estimates the pose of every test instance from its ground-truth box;
6. scores them with :func:`paz6d.demo.report.score_poses` (ADD recall at 0.1 d, rotation/translation
   errors, AUC of the ADD accuracy curve up to 10 cm; the demo object is asymmetric) and writes
   ``DIR/report.json``, a printed table and PNGs (recall curves, input / reconstruction / estimate grid).

Every stage resumes from what ``DIR`` already holds; re-running a finished demo redoes stages 4 and 5.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from paz6d.aae import run_dir as aae_run_dir
from paz6d.datasets.bop.units import MM_PER_M
from paz6d.datasets.bop.models import load_models_info
from paz6d.demo.report import AUC_MAX_THRESHOLD, number, pose_rows, print_rows, score_poses, write_report

TRAIN_SEED = 0
TEST_SEED = 1000
MIN_VISIBLE_FRACTION = 0.1  # BOP's rule for evaluation targets
VISIBILITY_BINS = ((0.1, 0.7), (0.7, 0.95), (0.95, 1.01))  # breakdown by visible fraction (occlusion)


def _stage(message: str) -> None:
    print(f"\n== {message}", flush=True)


def _test_targets(dataset_root: Path) -> list[dict]:
    """Every annotated instance with visible fraction >= 0.1: image, camera, GT pose and GT box."""
    from paz6d.datasets.bop.reader import BOPDataset

    targets = []
    for sample in BOPDataset(dataset_root, split="test"):
        for instance in sample.objects:
            info = instance.info or {}
            if info.get("visib_fract", 1.0) < MIN_VISIBLE_FRACTION:
                continue
            x, y, width, height = info["bbox_obj"]
            targets.append({"image": sample.image, "camera": sample.camera, "T_gt": instance.T_model2cam,
                            "box": (float(x), float(y), float(x + width), float(y + height)),
                            "scene_id": sample.scene_id, "im_id": sample.im_id,
                            "visible_fraction": float(info.get("visib_fract", 1.0))})
    return targets


def _estimate(run_dir: Path, targets: list[dict]) -> tuple[list, float, object]:
    from tqdm.auto import tqdm

    from paz6d.aae.pipeline import ImplicitPose6D

    estimator = ImplicitPose6D(run_dir, targets[0]["camera"])
    poses = []
    started = time.perf_counter()
    for target in tqdm(targets, desc="estimate poses", unit="object", dynamic_ncols=True):
        poses.append(estimator(target["image"], target["box"]))
    return poses, (time.perf_counter() - started) / len(targets), estimator


def by_visible_fraction(errors: np.ndarray, rotation: np.ndarray, visible: np.ndarray, diameter: float) -> dict:
    """Recall at 0.1 d and median rotation error (degrees) per :data:`VISIBILITY_BINS` bin of visible
    fraction; ``None`` for an empty bin."""
    bins = {}
    for low, high in VISIBILITY_BINS:
        chosen = (visible >= low) & (visible < high)
        bins[f"{low}-{min(high, 1.0)}"] = {
            "count": int(chosen.sum()),
            "recall_0.1d": float(np.mean(errors[chosen] < 0.1 * diameter)) if chosen.any() else None,
            "median_rotation_error_deg": float(np.median(rotation[chosen])) if chosen.any() else None}
    return bins


def _plot_recall(path: Path, add: np.ndarray, rotation: np.ndarray, diameter: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, 2, figsize=(10, 4))
    thresholds = np.linspace(0, AUC_MAX_THRESHOLD, 201)
    axes[0].plot(thresholds * 100, [np.mean(add <= t) for t in thresholds])
    axes[0].axvline(10 * diameter, color="gray", linestyle="--", label=f"0.1 d = {100 * 0.1 * diameter:.1f} cm")
    axes[0].set(xlabel="ADD threshold (cm)", ylabel="recall", title="ADD(-S) accuracy curve", ylim=(0, 1.02))
    axes[0].legend()
    angles = np.linspace(0, 45, 181)
    axes[1].plot(angles, [np.mean(rotation <= a) for a in angles])
    axes[1].set(xlabel="rotation error threshold (deg)", ylabel="recall", title="rotation accuracy", ylim=(0, 1.02))
    for axis in axes:
        axis.grid(alpha=0.3)
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


def _overlay(image: np.ndarray, mask_gt: np.ndarray, mask_est: np.ndarray, box, size: int) -> np.ndarray:
    """``size``² crop around ``box`` with the outlines of the ground truth (green) and the estimate (red)."""
    import cv2

    from paz6d.aae.model import crop_object

    canvas = crop_object(image, box, size, padding=1.5)
    for mask, color in ((mask_gt, (0, 255, 0)), (mask_est, (255, 40, 40))):
        resized = crop_object(mask.astype(np.uint8) * 255, box, size, padding=1.5) > 127
        contours, _ = cv2.findContours(resized.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        cv2.drawContours(canvas, contours, -1, color, 2)
    return canvas


def _plot_grid(path: Path, estimator, targets, poses, mesh_path: Path, rows: int = 8) -> None:
    """Rows of: test crop (model input) / reconstruction / estimate overlay (green GT, red estimate)."""
    from paz6d.backend.image import save_image
    from paz6d.backend.mesh import load_mesh
    from paz6d.aae.model import crop_object
    from renderers import Renderer

    mesh = load_mesh(mesh_path, 1.0 / MM_PER_M)
    size = 128
    chosen = np.linspace(0, len(targets) - 1, min(rows, len(targets))).astype(int)
    camera = targets[0]["camera"]
    tiles = []
    with Renderer(camera.width, camera.height) as renderer:
        for index in chosen:
            target, pose = targets[index], poses[index]
            crop = estimator.crop(target["image"], target["box"])
            reconstruction = estimator.reconstruct(crop[None])[0]
            masks = renderer.render(camera.K, [(mesh, target["T_gt"]), (mesh, pose.to_matrix())], rgb=False).masks
            view = _overlay(target["image"], masks[0], masks[1], target["box"], size)
            row = [crop_object(crop, (0, 0, crop.shape[1], crop.shape[0]), size, 1.0),
                   crop_object(reconstruction, (0, 0, crop.shape[1], crop.shape[0]), size, 1.0), view]
            tiles.append(np.concatenate(row, axis=1))
    save_image(path, np.concatenate(tiles, axis=0))


def _print_table(report: dict) -> None:
    metrics, training = report["metrics"], report["training"]
    print_rows([("test instances", f"{metrics['count']}"), *pose_rows(metrics),
                *[(f"  visible {name}: n / {metrics['metric']} / median rot",
                   f"{b['count']} / {number(b['recall_0.1d'], 100, ' %')} / "
                   f"{number(b['median_rotation_error_deg'], unit=' deg')}")
                  for name, b in metrics["by_visible_fraction"].items()],
                ("training steps", f"{training['steps']}"),
                ("loader samples/s (1 thread)", number(training["loader_samples_per_second_one_thread"], digits=0)),
                ("model samples/s", number(training["model_samples_per_second"], digits=0)),
                ("inference per object", number(report["seconds_per_estimate"], 1000, " ms")),
                ("total time", number(report["timings"]["total_seconds"], 1 / 60, " min"))])


def _generate_scenes(mesh_path: Path, out: Path, num_images: int, seed: int, split: str, workers: int,
                     platform: str | None) -> None:
    """``num_images`` single-object scenes of the demo object (the generator's default randomisation)."""
    from data_gen.config import GenerationConfig
    from data_gen.generator import generate

    generate(GenerationConfig(meshes=(mesh_path,), out=out, num_images=num_images, seed=seed, split=split,
                              mesh_scale=1.0 / MM_PER_M, objects_per_image=(1, 1), platform=platform),
             workers=max(1, workers))


def run_demo(out: Path, config=None, test_images: int = 200, workers: int = 2, platform: str | None = None,
             grid_rows: int = 8, train_images: int = 0, scene_crops: float = 0.0) -> dict:
    """Runs the whole demo into ``out`` and returns the report (also written to ``out/report.json``).

    Args:
        train_images / scene_crops: training scenes generated, and the share of AAE training inputs cut
            from them (0: rendered views only, no training scenes); ``paz6d demo --scene-crops``
            (:class:`~paz6d.demo.command.DemoOptions`).
    """
    from paz6d.backend.tensorflow_guard import import_tensorflow

    import_tensorflow()  # first: rendering in this process (overlays) is then safe next to TensorFlow
    from paz6d.assets.demo_object import OBJECT_ID, write_demo_object
    from paz6d.aae.config import QUICK
    from paz6d.aae.train import train_aae

    config = QUICK if config is None else config
    if int(test_images) <= 0:
        raise ValueError(f"test_images: expected a positive number of images, got {test_images}")
    if not 0.0 <= scene_crops <= 1.0:
        raise ValueError(f"scene_crops: expected a share in [0, 1], got {scene_crops}")
    if scene_crops > 0 and int(train_images) <= 0:
        raise ValueError(f"train_images: expected a positive number of images for scene_crops, got {train_images}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    timings = {}
    started = time.perf_counter()

    _stage("1/6 demo object")
    mesh_path = write_demo_object(out / "mesh")
    print(f"wrote {mesh_path} and {out / 'mesh' / 'models_info.json'}")

    _stage(f"2/6 held-out test images ({test_images}, seed {TEST_SEED})")
    tick = time.perf_counter()
    _generate_scenes(mesh_path, out / "test_data", test_images, TEST_SEED, "test", workers, platform)
    timings["test_data_seconds"] = time.perf_counter() - tick

    scenes = None
    if scene_crops > 0:
        _stage(f"3/6 training scenes ({train_images}, seed {TRAIN_SEED}; {scene_crops:.0%} of the AAE's inputs)")
        tick = time.perf_counter()
        scenes = out / "train_data"
        _generate_scenes(mesh_path, scenes, train_images, TRAIN_SEED, "train", workers, platform)
        timings["train_data_seconds"] = time.perf_counter() - tick

    _stage(f"4/6 training the Augmented Autoencoder ({config.steps} steps, seed {TRAIN_SEED})")
    tick = time.perf_counter()
    training = train_aae(mesh_path, out / "model", config, mesh_scale=1.0 / MM_PER_M, seed=TRAIN_SEED, workers=workers,
                         platform=platform, dataset=scenes, object_id=OBJECT_ID,
                         pair_fraction=scene_crops)
    timings["training_seconds"] = time.perf_counter() - tick

    _stage("5/6 estimating poses from ground-truth boxes")
    tick = time.perf_counter()
    targets = _test_targets(out / "test_data")
    if not targets:
        raise ValueError(f"{out / 'test_data'}: no test instance is visible enough to evaluate")
    poses, seconds_per_estimate, estimator = _estimate(out / "model", targets)
    timings["estimation_seconds"] = time.perf_counter() - tick

    _stage("6/6 scoring and plots")

    points = aae_run_dir.read_object(out / "model")["vertices"]
    diameter = load_models_info(out / "mesh" / "models_info.json")[OBJECT_ID].diameter
    scores = score_poses([pose.to_matrix() for pose in poses], np.stack([target["T_gt"] for target in targets]),
                         points, diameter)
    add, rotation = scores.errors_m, scores.rotation_errors_deg
    visible = np.array([target["visible_fraction"] for target in targets])
    metrics = {**scores.metrics, "by_visible_fraction": by_visible_fraction(add, rotation, visible, diameter)}
    _plot_recall(out / "recall_curves.png", add, rotation, diameter)
    _plot_grid(out / "estimates_grid.png", estimator, targets, poses, mesh_path, grid_rows)
    timings["total_seconds"] = time.perf_counter() - started
    report = {"metrics": metrics, "training": training, "seconds_per_estimate": seconds_per_estimate,
              "timings": timings, "test_images": test_images, "test_seed": TEST_SEED, "train_seed": TRAIN_SEED,
              "train_images": int(train_images) if scenes else 0, "scene_crops": float(scene_crops),
              "config": config.to_dict(), "cpu_count": os.cpu_count(),
              "load_average_1min_at_end": os.getloadavg()[0],
              "targets": {"instances_evaluated": len(targets), "min_visible_fraction": MIN_VISIBLE_FRACTION},
              "estimates": [{"scene_id": t["scene_id"], "im_id": t["im_id"], "box": list(t["box"]),
                             "T_est": p.to_matrix().tolist(), "T_gt": t["T_gt"].tolist(),
                             "error_m": float(a), "rotation_error_deg": float(r),
                             "visible_fraction": t["visible_fraction"]}
                            for t, p, a, r in zip(targets, poses, add, rotation)],
              "files": {"model": str(out / "model"), "mesh": str(mesh_path),
                        "recall_curves": str(out / "recall_curves.png"), "grid": str(out / "estimates_grid.png")}}
    write_report(out / "report.json", report)
    _print_table(report)
    print(f"\nreport: {out / 'report.json'}; plots: {out / 'recall_curves.png'}, {out / 'estimates_grid.png'}")
    return report
