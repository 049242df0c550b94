"""Probabilistic-keypoint training and evaluation: KeypointNet's supervised farthest-point keypoints with a
Gaussian head, trained with the shared Trainer on KeypointNet's rendered views (the command is
:mod:`paz6d.probabilistic_keypoints.command`, its settings :mod:`paz6d.probabilistic_keypoints.config`).

Data comes from :mod:`paz6d.keypointnet.views` (rendered in its spawn workers, crop jitter, clutter
backgrounds, colour jitter); each training crop is also covered, with probability ``train_occlusion``, by
flat polygons (:class:`paz6d.synthesis.occluders.PolygonOccluders`), so the network sees keypoints it
cannot see and can learn to be unsure about them. Loss: KeypointNet's supervised heatmap cross-entropy +
coordinate loss + depth-code loss, plus ``nll_weight`` × the Gaussian NLL
(:func:`~paz6d.probabilistic_keypoints.model.gaussian_nll`,
crop pixels) of the projected farthest-point keypoints.

After training, one scale factor of the covariances is fitted on held-out validation views (the
median squared Mahalanobis distance made ``2 ln 2``, that of a calibrated 2D Gaussian), the 3D keypoints
PnP uses are triangulated from the network's keypoints on unseen whole images cut as at inference (as
KeypointNet does: ``lifting="triangulate"``; ``"targets"`` uses the farthest-point keypoints), and
:func:`evaluate_run` scores held-out whole test images, clean and occluded: calibration (the fraction of
true keypoints inside the 1σ/2σ ellipses, :mod:`evaluation.calibration`) and ADD recall at 0.1 d with
plain RANSAC-EPnP + LM and with covariance-weighted PnP (:func:`paz6d.backend.pnp.solve_pnp_weighted`).
Re-running the same command resumes.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from evaluation.calibration import ellipse_coverage, mahalanobis_squared, plot_calibration
from evaluation.pose_errors import add_error, rotation_error_deg, translation_error
from paz6d.backend import keypoints as keypoints_backend
from paz6d.backend.files import finite_or_none, read_cache, save_npz_atomically
from paz6d.probabilistic_keypoints.run_dir import ProbabilisticKeypointsRunDir
from paz6d.training.precision import resolve_precision
from paz6d.keypointnet.keypoints import triangulate_keypoints
from paz6d.keypointnet.train import fixed_crops, inference_crops, supervised_keypoints
from paz6d.probabilistic_keypoints import run_dir as run_files
from paz6d.keypointnet.config import SUPERVISED_WEIGHTS
from paz6d.probabilistic_keypoints.config import (FIXED_SETTINGS, RANSAC_THRESHOLD, ROBUST_SCALE, ProbabilisticConfig,
                                                  ProbabilisticTraining)
from paz6d.processors.predict import predict_in_batches
from paz6d.synthesis.augment import share_generator
from paz6d.synthesis.occluders import PolygonOccluders
from paz6d.training.settings import check_same_run

#: Seed offsets of the validation views, of the lifting images and of the test images (disjoint from the
#: training views and from each other).
VALIDATION_SEED_OFFSET = 10_000
LIFT_SEED_OFFSET = 20_000
TEST_SEED_OFFSET = 30_000
EXAMPLE_COUNT = 8  # occluded test crops drawn in occluded_examples.png


def _prepare_run_dir(job: ProbabilisticTraining, settings: ProbabilisticConfig, object_diameter: float,
                     margin: float) -> None:
    config = {"method": "probabilistic_keypoints", "config": job.config, "seed": job.seed,
              "mesh_path": str(Path(job.mesh).resolve()), "mesh_scale": job.mesh_scale, "diameter": object_diameter,
              "input_size": settings.input_size, "margin": margin, "downsample": settings.downsample,
              "settings": settings.to_dict()}
    path = ProbabilisticKeypointsRunDir.config_path(job.out)
    if path.is_file():
        check_same_run(path, ProbabilisticKeypointsRunDir.read_config(job.out), config,
                       ("method", "config", "seed", "mesh_path", "mesh_scale"), settings, FIXED_SETTINGS)
    ProbabilisticKeypointsRunDir.write_config(job.out, config)


def occluder(settings: ProbabilisticConfig, probability: float, margin: float,
             max_count: int | None = None) -> PolygonOccluders:
    """The polygon occluders of a run (object side = crop side / ``margin``)."""
    return PolygonOccluders(probability, max_count or settings.test_occluders, settings.occluder_size, padding=margin)


def occlude(images: np.ndarray, occluders: PolygonOccluders, seed: int, stream: int) -> np.ndarray:
    """``images (B, S, S, 3)`` with occluders drawn from ``default_rng([seed, stream, i])`` per image."""
    out = np.empty_like(images)
    for index, image in enumerate(images):
        share_generator(occluders, np.random.default_rng([seed, stream, index]))
        out[index] = occluders(image)
    return out


def _loss_function(settings: ProbabilisticConfig, keypoints_model: np.ndarray, object_diameter: float):
    """``loss_fn(model, batch) -> dict`` for the shared Trainer."""
    from paz6d.keypointnet import model as kp
    from paz6d.probabilistic_keypoints.model import gaussian_nll

    tf = kp.tf
    size = float(settings.input_size)
    stride = settings.downsample
    grid = kp.cell_centres(int(size) // stride, int(size) // stride, stride)
    points = tf.constant(keypoints_model, tf.float32)
    scale, offset = (terms.astype(np.float32) for terms in keypoints_backend.normalization((size, size)))

    def normalised(uv):  # pixels -> [-1, 1]
        return uv * scale + offset

    def loss_fn(model, batch):
        outputs = model(batch["images"], training=True)
        K, T = batch["K"], batch["T_model2cam"]
        points_cam = tf.einsum("bij,nj->bni", T[:, :3, :3], points) + T[:, None, :3, 3]
        target_uv = kp.project(points_cam, K)
        target_code = points_cam[..., 2] / (object_diameter * K[:, 0:1, 0] / size)  # KeypointNet's depth code
        depth = tf.reduce_mean(tf.abs(outputs["depth"] - target_code))
        heatmap = kp.heatmap_loss(outputs["probabilities"], kp.gaussian_heatmaps(target_uv, grid, float(stride)))
        coordinates = kp.coordinate_loss(normalised(outputs["uv"]), normalised(target_uv))
        nll = gaussian_nll(outputs["uv"], outputs["cholesky"], target_uv)
        loss = (SUPERVISED_WEIGHTS["heatmap"] * heatmap + SUPERVISED_WEIGHTS["coordinates"] * coordinates
                + SUPERVISED_WEIGHTS["depth"] * depth + settings.nll_weight * nll)
        pixel_error = tf.reduce_mean(tf.norm(outputs["uv"] - target_uv, axis=-1))
        return {"loss": loss, "heatmap": heatmap, "coordinates": coordinates, "depth": depth, "nll": nll,
                "pixel_error": pixel_error}

    return loss_fn


def predict_gaussians(model, images: np.ndarray, batch_size: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Means ``(V, N, 2)`` and covariances ``(V, N, 2, 2)`` (crop pixels, unscaled) for crops ``(V, S, S, 3)``."""
    from paz6d.probabilistic_keypoints.model import covariance_from_cholesky, inference_function

    infer = inference_function(model)
    outputs = predict_in_batches(lambda batch: {key: infer(batch)[key] for key in ("uv", "cholesky")}, images,
                                 batch_size)
    cholesky = outputs["cholesky"].astype(np.float64)
    return outputs["uv"].astype(np.float64), covariance_from_cholesky(cholesky)


def projected_keypoints(points_model: np.ndarray, K: np.ndarray, T_model2cam: np.ndarray) -> np.ndarray:
    """True keypoints ``(V, N, 2)`` in each view's pixels."""
    from paz6d.backend.camera import transform_and_project

    return np.stack([transform_and_project(points_model, T, camera) for T, camera in zip(T_model2cam, K)])


def fit_covariance_scale(truth: np.ndarray, means: np.ndarray, covariances: np.ndarray) -> float:
    """The factor ``s`` that makes the median squared Mahalanobis distance of ``truth`` under
    ``N(means, s Σ)`` equal ``2 ln 2`` (the median of a χ²(2) variable)."""
    return float(np.median(mahalanobis_squared(truth, means, covariances)) / (2.0 * math.log(2.0)))


def pnp_poses(points_model: np.ndarray, means: np.ndarray, covariances: np.ndarray, K: np.ndarray,
              weighted: bool) -> list[np.ndarray | None]:
    """One pose per view (``None`` where PnP fails): RANSAC-EPnP + LM (``weighted=False``) or
    covariance-weighted PnP from the same start."""
    from paz6d.backend.pnp import PnPError, solve_pnp, solve_pnp_weighted

    poses = []
    for uv, covariance, camera in zip(means, covariances, K):
        try:
            if weighted:
                solution = solve_pnp_weighted(points_model, uv, camera, covariance, "epnp", True, None,
                                              RANSAC_THRESHOLD, ROBUST_SCALE)
            else:
                solution = solve_pnp(points_model, uv, camera, "epnp", True, None, True, RANSAC_THRESHOLD)
            poses.append(solution.T_model2cam)
        except PnPError:
            poses.append(None)
    return poses


def score_poses(poses, T_gt: np.ndarray, vertices: np.ndarray, object_diameter: float) -> dict:
    """ADD recall at 0.1 d (misses count as failures), median ADD, rotation and translation errors."""
    found = np.array([pose is not None for pose in poses])
    errors = np.full(len(poses), np.inf)
    rotation = np.full(len(poses), np.inf)
    translation = np.full(len(poses), np.inf)
    if found.any():
        estimates = np.stack([pose for pose in poses if pose is not None])
        errors[found] = add_error(estimates, T_gt[found], vertices)
        rotation[found] = rotation_error_deg(estimates[:, :3, :3], T_gt[found, :3, :3])
        translation[found] = translation_error(estimates[:, :3, 3], T_gt[found, :3, 3])
    return {"add_recall_0.1d": round(float(np.mean(errors < 0.1 * object_diameter)), 4),
            "add_recall_0.05d": round(float(np.mean(errors < 0.05 * object_diameter)), 4),
            "median_add_m": finite_or_none(float(np.median(errors)), 5),
            "median_rotation_deg": finite_or_none(float(np.median(rotation)), 3),
            "median_translation_m": finite_or_none(float(np.median(translation)), 5),
            "failures": int((~found).sum()), "count": len(poses)}


def evaluate_run(model, points_model: np.ndarray, targets: np.ndarray, covariance_scale: float, crops: dict,
                 settings: ProbabilisticConfig, vertices: np.ndarray, object_diameter: float, seed: int, margin: float,
                 png: Path | None = None, examples: Path | None = None) -> dict:
    """Calibration and plain vs covariance-weighted PnP on test crops, clean and occluded.

    Args:
        points_model: ``(N, 3)`` metres, the 3D keypoints PnP uses.
        targets: ``(N, 3)`` metres, the keypoints the network was trained on: their projections are the
            true keypoints of the calibration.
        crops: ``{"images": (V, S, S, 3) uint8, "K": (V, 3, 3), "T_model2cam": (V, 4, 4)}`` cut from
            whole test images as at inference (:func:`paz6d.keypointnet.train.inference_crops`).
        covariance_scale: factor applied to the predicted covariances (fitted on validation views).
        png: where to draw the calibration curves; examples: where to draw occluded test crops with
            their keypoints and 2σ ellipses.
    """
    clean = crops["images"]
    occluded = occlude(clean, occluder(settings, 1.0, margin), seed, 2)
    report, curves = {"covariance_scale": round(covariance_scale, 4), "test_views": len(clean)}, {}
    for name, images in (("clean", clean), ("occluded", occluded)):
        means, covariances = predict_gaussians(model, images.astype(np.float32))
        truth = projected_keypoints(targets, crops["K"], crops["T_model2cam"])
        raw = ellipse_coverage(truth, means, covariances)
        scaled = ellipse_coverage(truth, means, covariance_scale * covariances)
        curves[f"{name}, raw"], curves[f"{name}, scaled ×{covariance_scale:.2f}"] = raw, scaled
        errors = np.linalg.norm(means - truth, axis=-1)
        sigma = np.sqrt(np.linalg.eigvalsh(covariance_scale * covariances)[..., -1])
        report[name] = {
            "calibration_raw": raw.to_dict(), "calibration_scaled": scaled.to_dict(),
            "keypoint_error_px": {"median": round(float(np.median(errors)), 3),
                                  "mean": round(float(np.mean(errors)), 3)},
            "largest_sigma_px_median": round(float(np.median(sigma)), 3),
            "error_sigma_spearman": round(_spearman(errors.ravel(), sigma.ravel()), 3),
            "pnp": score_poses(pnp_poses(points_model, means, covariances, crops["K"], False), crops["T_model2cam"],
                               vertices, object_diameter),
            "weighted_pnp": score_poses(pnp_poses(points_model, means, covariance_scale * covariances, crops["K"],
                                                  True),
                                        crops["T_model2cam"], vertices, object_diameter)}
        if examples is not None and name == "occluded":
            draw_gaussians(images[:EXAMPLE_COUNT], means[:EXAMPLE_COUNT],
                           covariance_scale * covariances[:EXAMPLE_COUNT],
                           examples)
    if png is not None:
        plot_calibration(curves, png, "probabilistic keypoints: held-out test crops")
    return report


def _spearman(a: np.ndarray, b: np.ndarray) -> float:
    """Spearman rank correlation of two vectors."""
    rank_a, rank_b = np.argsort(np.argsort(a)), np.argsort(np.argsort(b))
    return float(np.corrcoef(rank_a, rank_b)[0, 1])


def _cached_test_crops(path: Path, job: ProbabilisticTraining, settings: ProbabilisticConfig, sampling, count: int,
                       seed: int) -> dict:
    """Crops of ``count`` freshly rendered whole images cut as at inference (``images``, ``K``,
    ``T_model2cam``), cached in ``path``."""
    from paz6d.keypointnet.views import render_test_images

    crops = read_cache(path, ("images", "K", "T_model2cam"))
    if crops is None:
        whole = render_test_images(job.mesh, count, seed, sampling, job.mesh_scale, job.workers, progress=job.progress)
        images, K, T = inference_crops(whole, sampling.camera.K, sampling.margin, settings.input_size)
        save_npz_atomically(path, images=images, K=K, T_model2cam=T)
        crops = {"images": images, "K": K, "T_model2cam": T}
    return crops


def draw_gaussians(images: np.ndarray, means: np.ndarray, covariances: np.ndarray, path: Path) -> Path:
    """A PNG of crops ``(V, S, S, 3)`` (enlarged ×2) with each keypoint's mean and 2σ ellipse, 4 per row."""
    import cv2

    from paz6d.backend.draw import image_grid, keypoint_colors
    from paz6d.backend.image import save_image

    colours = keypoint_colors(means.shape[1])
    tiles = []
    for picture, uv, covariance in zip(np.asarray(images, np.uint8), means, covariances):
        picture = cv2.resize(picture, None, fx=2, fy=2, interpolation=cv2.INTER_LINEAR)
        for point, matrix, colour in zip(uv, covariance, colours):
            values, vectors = np.linalg.eigh(matrix)
            axes = tuple(min(500, int(round(2 * 2 * math.sqrt(max(value, 1e-6))))) for value in values[::-1])
            angle = math.degrees(math.atan2(vectors[1, -1], vectors[0, -1]))
            centre = tuple(int(round(2 * value)) for value in point)
            colour = tuple(int(c) for c in colour)
            cv2.ellipse(picture, centre, axes, angle, 0, 360, colour, 1)
            cv2.circle(picture, centre, 2, colour, -1)
        tiles.append(picture)
    return save_image(path, image_grid(tiles, columns=4))


def _sample_drawer(images: np.ndarray):
    """``sample_callback(model, step, path)``: predicted keypoints with their 2σ ellipses (unscaled)."""

    def draw(model, step, path):
        means, covariances = predict_gaussians(model, images.astype(np.float32))
        draw_gaussians(images, means, covariances, path)

    return draw


def train_probabilistic_keypoints(job: ProbabilisticTraining) -> dict:
    """Trains (or resumes) one run, fits the covariance scale and evaluates on held-out test images.

    Returns:
        A summary (also ``metrics.json``; the evaluation is ``evaluation.json`` and ``calibration.png``).
    """
    from paz6d.backend.tensorflow_guard import import_tensorflow

    import_tensorflow()  # before any renderer in this process (workers=0)
    from paz6d.backend.mesh import diameter, load_mesh
    from paz6d.keypointnet.views import ViewSampling, cached_views, render_views, training_batch
    from paz6d.probabilistic_keypoints import model as pk
    from paz6d.training.trainer import Trainer

    settings = job.model_config
    precision = resolve_precision(settings.precision)
    started = time.perf_counter()
    mesh = load_mesh(job.mesh, job.mesh_scale)
    vertices = np.asarray(mesh.vertices)
    object_diameter = diameter(vertices)
    sampling = ViewSampling(input_size=settings.input_size)
    job.out.mkdir(parents=True, exist_ok=True)
    _prepare_run_dir(job, settings, object_diameter, sampling.margin)
    out = job.out

    def render(count, seed):
        return lambda: render_views(job.mesh, count, seed, sampling, job.mesh_scale, job.workers, progress=job.progress)

    train_views = cached_views(ProbabilisticKeypointsRunDir.views_path(out, "train"), render(settings.views, job.seed))
    validation_views = cached_views(ProbabilisticKeypointsRunDir.views_path(out, "val"),
                                    render(settings.validation_views, job.seed + VALIDATION_SEED_OFFSET))
    test = _cached_test_crops(ProbabilisticKeypointsRunDir.views_path(out, "test"), job, settings, sampling,
                              settings.test_images, job.seed + TEST_SEED_OFFSET)
    render_seconds = time.perf_counter() - started

    keypoints_model = supervised_keypoints(mesh, settings.num_keypoints, job.seed)
    pk.keras.utils.set_random_seed(job.seed)
    model = pk.build_probabilistic_keypointnet(settings.num_keypoints, settings.input_size, settings.filters,
                                               settings.downsample, settings.dilations, settings.context_stride,
                                               precision)
    schedule = pk.keras.optimizers.schedules.CosineDecay(settings.learning_rate, settings.steps, alpha=0.05)
    optimizer = pk.keras.optimizers.Adam(schedule, global_clipnorm=5.0)
    training_occluders = occluder(settings, settings.train_occlusion, sampling.margin, 2)

    def make_batch(step: int):
        batch = training_batch(train_views, np.random.default_rng([job.seed, 1, step]), settings.pairs,
                               settings.downsample)
        batch["images"] = occlude(batch["images"], training_occluders, job.seed, 1_000_000 + step)
        return batch

    sample_images = fixed_crops(validation_views, job.seed, 8)[0]
    trainer = Trainer(model, optimizer, _loss_function(settings, keypoints_model, object_diameter), make_batch, out,
                      settings.steps, checkpoint_every=settings.checkpoint_every, log_every=10,
                      sample_every=settings.sample_every,
                      sample_callback=_sample_drawer(sample_images), progress=job.progress, prefetch=1)
    previous_metrics = ProbabilisticKeypointsRunDir.read_metrics(out)
    training = trainer.fit()
    pk.save_model(model, ProbabilisticKeypointsRunDir.model_path(out))
    train_seconds = time.perf_counter() - started - render_seconds

    images, K, T = fixed_crops(validation_views, job.seed + 2)
    images = occlude(images, training_occluders, job.seed, 3)  # occluded as often as in training
    means, covariances = predict_gaussians(model, images.astype(np.float32))
    scale = fit_covariance_scale(projected_keypoints(keypoints_model, K, T), means, covariances)
    points_model = keypoints_model
    if settings.lifting == "triangulate":  # as KeypointNet: absorbs the network's 2D biases into the 3D model
        lift = _cached_test_crops(ProbabilisticKeypointsRunDir.views_path(out, "lift"), job, settings, sampling,
                                  settings.lift_images, job.seed + LIFT_SEED_OFFSET)
        lift_means, _ = predict_gaussians(model, lift["images"].astype(np.float32))
        points_model, _ = triangulate_keypoints(lift_means, lift["K"], lift["T_model2cam"])
    run_files.write_keypoints(out, points_model, scale, keypoints_model, settings.lifting)
    evaluation = evaluate_run(model, points_model, keypoints_model, scale, test, settings, vertices, object_diameter,
                              job.seed, sampling.margin, out / run_files.CALIBRATION_PNG, out / run_files.EXAMPLES_PNG)
    run_files.write_json(out, run_files.EVALUATION_FILE, evaluation)
    training_figures = {"render_seconds": round(render_seconds, 1), "train_seconds": round(train_seconds, 1),
                        "total_seconds": round(time.perf_counter() - started, 1), "final_losses": training.metrics,
                        "model_samples_per_second": finite_or_none(training.model_samples_per_second, 1)}
    if training.final_step == training.start_step and previous_metrics:  # a finished run re-run: evaluation only
        training_figures = {key: previous_metrics.get(key) for key in training_figures}
    summary = {"config": job.config, "steps": training.final_step, "precision": precision, **training_figures,
               "covariance_scale": round(scale, 4),
               "evaluation": {name: {"calibration_scaled": evaluation[name]["calibration_scaled"]["observed"],
                                     "calibration_raw": evaluation[name]["calibration_raw"]["observed"],
                                     "pnp_add_recall_0.1d": evaluation[name]["pnp"]["add_recall_0.1d"],
                                     "weighted_pnp_add_recall_0.1d":
                                         evaluation[name]["weighted_pnp"]["add_recall_0.1d"]}
                              for name in ("clean", "occluded")}}
    run_files.write_json(out, ProbabilisticKeypointsRunDir.METRICS_FILE, summary)
    return summary
