"""HRNet training on renderings of one mesh (the command ``paz6d train hrnet`` is :mod:`paz6d.hrnet.command`,
its settings :mod:`paz6d.hrnet.config`).

The data are KeypointNet's (:mod:`paz6d.keypointnet.views`): crops around the object rendered in spawn
workers, composited over random clutter, jittered in scale/shift/colour at batch time, each with its crop
intrinsics ``K_crop`` and pose. The keypoints are the supervised KeypointNet's: ``N`` farthest-point samples
of the mesh surface (:func:`paz6d.keypointnet.train.supervised_keypoints`), projected into every crop as
Gaussian heatmap targets (``sigma`` heatmap cells). The network trains on the shared
:class:`~paz6d.training.trainer.Trainer` (checkpoints, resume, ``log.csv``, TensorBoard, sample PNGs).

After training, ``settings.test_images`` held-out whole images (another seed: other poses, lights and
backgrounds) are rendered and cut around their ground-truth boxes exactly as
:class:`~paz6d.hrnet.pipeline.HRNetKeypoints2D` cuts its input; PCK@0.05 of the crop side
(:func:`evaluation.keypoints.pck`) of every decoder is written to ``evaluation.json``, with ``keypoints.png``
(predicted vs true keypoints) and ``pck.png``. Re-running the same command resumes.

TensorFlow and the renderer are loaded inside :func:`train_hrnet`.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from paz6d.backend.files import finite_or_none, read_cache, save_npz_atomically
from paz6d.hrnet import run_dir as run_files
from paz6d.hrnet.config import FIXED_SETTINGS, MARGIN, STRIDE, HRNetConfig, HRNetTraining
from paz6d.hrnet.evaluate import (HEADLINE_ALPHA, save_keypoint_grid, save_pck_plot, score_keypoints, score_poses,
                                  true_keypoints)
from paz6d.hrnet.heatmaps import DEFAULT_DECODER, decode_heatmaps
from paz6d.hrnet.run_dir import HRNetRunDir
from paz6d.training.precision import resolve_precision
from paz6d.keypointnet.train import fixed_crops, inference_crops, supervised_keypoints
from paz6d.processors.predict import predict_in_batches
from paz6d.training.settings import changed_settings, recorded_settings

#: Seed offsets of the validation views and of the held-out test images (the training views use ``seed``).
VALIDATION_SEED_OFFSET = 10_000
TEST_SEED_OFFSET = 20_000
#: Summary fields that describe the training itself (kept in ``metrics.json`` when a finished run is re-run).
TRAINING_RECORD = ("render_seconds", "train_seconds", "final_losses", "loader_samples_per_second",
                   "model_samples_per_second")


def _prepare_run_dir(job: HRNetTraining, settings: HRNetConfig) -> dict:
    """Writes ``config.json``, or checks that an existing one describes the same run (``steps`` may grow)."""
    config = {"mesh_path": str(Path(job.mesh).resolve()), "mesh_scale": job.mesh_scale, "seed": job.seed,
              "config": job.config, "settings": settings.to_dict()}
    previous = HRNetRunDir.read_config(job.out)
    if previous is None:
        HRNetRunDir.write_config(job.out, config)
        return config
    path = Path(job.out) / HRNetRunDir.CONFIG_FILE
    for key in ("mesh_path", "mesh_scale", "seed", "config"):
        if previous[key] != config[key]:
            raise ValueError(f"{path}: this run directory holds a different run ({key}={previous[key]!r}, now "
                             f"{config[key]!r}); choose another --out")
    earlier = recorded_settings(HRNetConfig, path, previous)
    changed = changed_settings(earlier, settings, FIXED_SETTINGS)
    if changed:
        key = changed[0]
        raise ValueError(f"{path}: this run directory holds a different network ({key}={getattr(earlier, key)!r}, "
                         f"now {getattr(settings, key)!r}); choose another --out")
    if earlier.steps != settings.steps:
        previous["settings"]["steps"] = settings.steps  # extending (or shortening) a run is allowed
        HRNetRunDir.write_config(job.out, previous)
    return previous


def keypoint_batch(views, rng: np.random.Generator, batch_size: int, points_model: np.ndarray) -> dict[str, np.ndarray]:
    """A training batch: ``images (B, S, S, 3) float32`` (0..255; KeypointNet's augmented crops) and the
    projected keypoints ``uv (B, N, 2) float32`` (crop pixels, through each jittered crop's ``K``)."""
    from paz6d.keypointnet.views import training_batch

    batch = training_batch(views, rng, batch_size // 2, STRIDE)
    uv = true_keypoints(points_model, batch["K"].astype(np.float64), batch["T_model2cam"].astype(np.float64))
    return {"images": batch["images"], "uv": uv.astype(np.float32)}


def _loss_function(settings: HRNetConfig):
    """``loss_fn(model, batch) -> {"loss", "pixel_error"}`` for the Trainer (TensorFlow imported here)."""
    from paz6d.hrnet import model as hr

    tf = hr.tf
    cells = settings.input_size // STRIDE
    sigma = settings.sigma
    heatmap_loss = hr.softmax_heatmap_loss if settings.loss == "softmax" else hr.mse_heatmap_loss

    def loss_fn(model, batch):
        heatmaps = model(batch["images"], training=True)["heatmaps"]
        targets = hr.gaussian_targets(batch["uv"], cells, cells, STRIDE, sigma)
        loss = heatmap_loss(heatmaps, targets)
        error = tf.reduce_mean(tf.norm(hr.argmax_keypoints(heatmaps, STRIDE) - batch["uv"], axis=-1))
        return {"loss": loss, "argmax_px": error}

    return loss_fn


def _sample_drawer(images: np.ndarray, targets: np.ndarray, settings: HRNetConfig):
    """``sample_callback(model, step, path)``: predicted (filled) vs true (hollow) keypoints on fixed crops."""
    domain = "log" if settings.loss == "softmax" else "value"

    def draw(model, step, path):
        heatmaps = np.asarray(model(images.astype(np.float32), training=False)["heatmaps"])
        uv, _ = decode_heatmaps(heatmaps, STRIDE, DEFAULT_DECODER, domain, settings.sigma)
        save_keypoint_grid(path, images, uv, targets, count=len(images))

    return draw


def held_out_crops(job: HRNetTraining, settings: HRNetConfig, sampling) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``images (V, S, S, 3) uint8``, ``K (V, 3, 3)``, ``T_model2cam (V, 4, 4)`` of ``settings.test_images``
    whole images rendered with seed ``seed + 20000`` and cut around their ground-truth boxes as the
    pipeline cuts them; cached in the run directory."""
    from paz6d.keypointnet.views import render_test_images

    path = run_files.held_out_crops_path(job.out)
    cached = read_cache(path, ("images", "K", "T_model2cam"))
    if cached is not None and len(cached["images"]) == settings.test_images:
        return cached["images"], cached["K"], cached["T_model2cam"]
    test = render_test_images(job.mesh, settings.test_images, job.seed + TEST_SEED_OFFSET, sampling, job.mesh_scale,
                              job.workers, progress=job.progress)
    images, K, T = inference_crops(test, sampling.camera.K, sampling.margin, settings.input_size)
    save_npz_atomically(path, images=images, K=K, T_model2cam=T)
    return images, K, T


def evaluate_run(model, crops, points_model: np.ndarray, settings: HRNetConfig, out: Path, vertices=None) -> dict:
    """PCK of every decoder on held-out ``crops = (images, K, T)`` and, with the mesh ``vertices (M, 3)``
    (metres), ADD recall of the poses PnP makes of the keypoints; writes ``evaluation.json``,
    ``keypoints.png`` and ``pck.png`` into ``out`` and returns the evaluation."""
    from paz6d.backend.mesh import diameter
    from paz6d.hrnet.model import inference_function

    images, K, T = crops
    started = time.perf_counter()
    heatmaps = predict_in_batches(inference_function(model), images, 32)
    seconds = time.perf_counter() - started
    target = true_keypoints(points_model, K, T)
    domain = "log" if settings.loss == "softmax" else "value"
    scores, decoded = score_keypoints(heatmaps, target, settings.input_size, STRIDE, domain, settings.sigma)
    evaluation = {"held_out_crops": len(images), "input_size": settings.input_size, "alpha": HEADLINE_ALPHA,
                  "threshold_px": HEADLINE_ALPHA * settings.input_size,
                  f"pck@{HEADLINE_ALPHA}": scores[DEFAULT_DECODER][f"pck@{HEADLINE_ALPHA}"], "decoder": DEFAULT_DECODER,
                  "decoders": scores, "inference_ms_per_crop": round(1000 * seconds / max(len(images), 1), 2)}
    if vertices is not None:
        evaluation["pnp"] = score_poses(decoded[DEFAULT_DECODER], K, T, points_model, vertices,
                                        diameter(np.asarray(vertices)), settings.input_size)
    run_files.write_evaluation(out, evaluation)
    save_keypoint_grid(out / run_files.KEYPOINTS_PLOT, images, decoded[DEFAULT_DECODER], target)
    save_pck_plot(out / run_files.PCK_PLOT, scores, settings.input_size, len(images))
    return evaluation


def train_hrnet(job: HRNetTraining) -> dict:
    """Trains (or resumes) one HRNet run, writes everything :class:`~paz6d.hrnet.pipeline.HRNetKeypoints2D`
    needs, and scores it on held-out renders.

    Returns:
        A summary (also in ``metrics.json``): steps, seconds, final losses and the held-out PCK@0.05
        (``evaluation.json`` has every decoder and threshold).
    """
    from paz6d.backend.tensorflow_guard import import_tensorflow

    import_tensorflow()  # before any renderer in this process (workers=0)
    from paz6d.backend.mesh import load_mesh
    from paz6d.keypointnet.views import ViewSampling, cached_views, render_views

    settings = job.model_config
    precision = resolve_precision(settings.precision)
    started = time.perf_counter()
    if not Path(job.mesh).is_file():
        raise ValueError(f"mesh: {job.mesh}: mesh file not found")
    mesh = load_mesh(job.mesh, job.mesh_scale)
    _prepare_run_dir(job, settings)
    out = job.out
    points_model = supervised_keypoints(mesh, settings.num_keypoints, job.seed)
    domain = "log" if settings.loss == "softmax" else "value"
    sampling = ViewSampling(input_size=settings.input_size, margin=MARGIN)

    def render(count, seed):
        return lambda: render_views(job.mesh, count, seed, sampling, job.mesh_scale, job.workers, progress=job.progress)

    train_views = cached_views(HRNetRunDir.views_path(out, "train"), render(settings.views, job.seed))
    validation_views = cached_views(HRNetRunDir.views_path(out, "val"),
                                    render(settings.validation_views, job.seed + VALIDATION_SEED_OFFSET))
    render_seconds = time.perf_counter() - started

    from paz6d.hrnet import model as hr
    from paz6d.training.trainer import Trainer

    keras = hr.keras
    keras.utils.set_random_seed(job.seed)
    model = hr.build_hrnet(settings.num_keypoints, settings.input_size, settings.widths, settings.stage_modules,
                           settings.blocks, settings.stem_width, settings.stem_blocks, compute_dtype=precision)
    schedule = keras.optimizers.schedules.CosineDecay(settings.learning_rate, settings.steps, alpha=0.05)
    ema = settings.ema_momentum
    optimizer = keras.optimizers.Adam(schedule, global_clipnorm=5.0, use_ema=ema is not None,
                                      ema_momentum=0.99 if ema is None else ema)

    def make_batch(step: int):
        return keypoint_batch(train_views, np.random.default_rng([job.seed, 1, step]), settings.batch_size,
                              points_model)

    sample_images, sample_K, sample_T = fixed_crops(validation_views, job.seed, 8)
    trainer = Trainer(model, optimizer, _loss_function(settings), make_batch, out, settings.steps,
                      checkpoint_every=settings.checkpoint_every, log_every=10, sample_every=settings.sample_every,
                      sample_callback=_sample_drawer(sample_images, true_keypoints(points_model, sample_K, sample_T),
                                                     settings),
                      progress=job.progress, prefetch=1)
    training = trainer.fit()
    hr.save_hrnet(model, HRNetRunDir.model_path(out))
    run_files.write_description(out, settings.input_size, MARGIN, STRIDE, domain, settings.sigma, points_model)
    train_seconds = time.perf_counter() - started - render_seconds

    evaluation_started = time.perf_counter()
    crops = held_out_crops(job, settings, sampling)
    evaluation = evaluate_run(model, crops, points_model, settings, out, np.asarray(mesh.vertices))
    summary = {"config": job.config, "steps": training.final_step, "precision": precision,
               "parameters": int(model.count_params()), "render_seconds": round(render_seconds, 1),
               "train_seconds": round(train_seconds, 1),
               "evaluation_seconds": round(time.perf_counter() - evaluation_started, 1),
               "final_losses": training.metrics,
               "loader_samples_per_second": finite_or_none(training.loader_samples_per_second, 1),
               "model_samples_per_second": finite_or_none(training.model_samples_per_second, 1),
               "held_out_crops": evaluation["held_out_crops"],
               f"pck@{HEADLINE_ALPHA}": evaluation[f"pck@{HEADLINE_ALPHA}"],
               "median_px": evaluation["decoders"][DEFAULT_DECODER]["median_px"],
               "add_recall_0.1d": evaluation["pnp"]["add_recall_0.1d"]}
    previous = HRNetRunDir.read_metrics(out)
    if training.final_step == training.start_step and previous is not None:
        # a finished run re-run (e.g. to re-score it): keep the numbers of the run that trained
        summary.update({key: previous[key] for key in TRAINING_RECORD if key in previous})
    HRNetRunDir.write_metrics(out, summary)
    return summary
