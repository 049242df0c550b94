"""SSD training: a single-shot detector trained on a ``paz6d generate`` data set with the shared Trainer.

The data set's COCO annotations (``<dataset>/<split>/<scene>/scene_gt_coco.json``, visible boxes) are read
by :mod:`paz6d.ssd.dataset`; every sample goes through SSD's augmentation
(:func:`paz6d.synthesis.box_augment.ssd_augmentation`), is resized to the network input and matched to
the priors. The loss is :class:`paz6d.ssd.loss.MultiboxLoss`. Configurations:

- ``quick``: the ``light`` CPU network (448 x 448 inputs), sized for a half-hour run on 2 CPU cores;
- ``full``: SSD300 with a VGG16 body (the paper's network), for a GPU.

With ``backbone`` (``--backbone efficientnet-lite0``, docs/backbones.md) the light network's body is the
pretrained ImageNet EfficientNet-Lite0: its batch-norm statistics and first stages stay fixed, its other
variables step at ``backbone_rate_factor`` times the learning rate (:mod:`paz6d.training.scaled_rates`),
and images are scaled as it expects (``detector.json``'s ``normalization``).

The run directory (:mod:`paz6d.ssd.run_dir`) gets ``detector.json`` + ``model.keras`` (what
:class:`~paz6d.ssd.pipeline.DetectSingleShot` loads), the Trainer's checkpoints, ``log.csv``,
``tensorboard/`` and ``samples/`` (detections on training images), and ``metrics.json``. Re-running
the same command resumes.

The command is :mod:`paz6d.ssd.command`, its settings :mod:`paz6d.ssd.config`; TensorFlow is loaded
inside :func:`train_ssd`.
"""

from __future__ import annotations

import time
from functools import partial

import numpy as np

from paz6d.backend.boxes import SSD_VARIANCES
from paz6d.backend.draw import image_grid
from paz6d.backend.files import finite_or_none
from paz6d.backend.image import load_image, resize, save_image
from paz6d.ssd import run_dir as run_files
from paz6d.ssd.dataset import load_detection_set, training_batch
from paz6d.ssd.config import FIXED_SETTINGS, SSDConfig, SSDTraining
from paz6d.ssd.pipeline import DetectSingleShot, draw_detections
from paz6d.ssd.run_dir import SSDRunDir
from paz6d.synthesis.box_augment import ssd_augmentation
from paz6d.training.settings import check_same_run

def _prepare_run_dir(job: SSDTraining, settings: SSDConfig, class_names: tuple[str, ...]) -> None:
    """Writes ``config.json`` or checks that an existing one describes the same run."""
    config = {"dataset": str(job.dataset.resolve()), "split": job.split, "config": job.config, "seed": job.seed,
              "class_names": list(class_names), "settings": settings.to_dict()}
    check_same_run(job.out / SSDRunDir.CONFIG_FILE, SSDRunDir.read_config(job.out), config,
                   ("dataset", "config", "seed", "class_names"), settings, FIXED_SETTINGS)
    SSDRunDir.write_config(job.out, config)


def _schedule(keras, settings: SSDConfig):
    """Linear warm-up to ``learning_rate`` then cosine decay to 1 % of it."""
    steps, warmup = settings.steps, min(settings.warmup_steps, settings.steps - 1)
    return keras.optimizers.schedules.CosineDecay(
        0.0 if warmup else settings.learning_rate, max(steps - warmup, 1), alpha=0.01,
        warmup_target=settings.learning_rate if warmup else None, warmup_steps=warmup)


def _sample_drawer(images: list[np.ndarray], detector: dict):
    """``sample_callback(model, step, path)``: detections (score >= 0.3) on a few training images, by the
    pipeline a run directory with ``detector`` (``detector.json``'s contents) would give."""

    pipelines = {}  # one per model: its compiled network is traced once, not at every sample step

    def draw(model, step, path):
        if id(model) not in pipelines:
            pipelines[id(model)] = DetectSingleShot.from_model(model, detector, score_threshold=0.3)
        detect = pipelines[id(model)]
        tiles = [draw_detections(image, detect(image), detect.class_names) for image in images]
        size = (tiles[0].shape[1], tiles[0].shape[0])  # data sets on disk mix image sizes: tile at the first's
        save_image(path, image_grid([tile if tile.shape[:2] == size[::-1] else resize(tile, size) for tile in tiles],
                                    columns=2))

    return draw


def augmentation_factory(settings: SSDConfig):
    """A factory of :func:`ssd_augmentation` chains (one per batch) with a run's settings: the expand ratio and
    probability, the ``white_balance`` strength and ``grayscale`` probability (0: off) and ``scale_crops`` (a
    factor range: input-sized windows of rescaled images instead of whole images)."""
    return partial(ssd_augmentation, settings.expand_ratio, settings.expand_probability,
                   white_balance=settings.white_balance, grayscale=settings.grayscale,
                   scale_crops=settings.scale_crops, crop_size=settings.input_size)


def image_scale(settings: SSDConfig) -> float | None:
    """The factor whole images are scaled by for detection: the geometric mean of ``scale_crops``
    (``None`` without it: images are resized to the square input)."""
    scale_crops = settings.scale_crops
    return None if scale_crops is None else float(np.sqrt(scale_crops[0] * scale_crops[1]))


def train_ssd(job: SSDTraining) -> dict:
    """Trains (or resumes) one SSD run and writes everything ``DetectSingleShot`` needs.

    Returns:
        A summary (also ``job.out/metrics.json``): steps, seconds, final losses, samples per second.
    Raises:
        ValueError: empty or malformed data set, a different run in ``job.out``.
    """
    from paz6d.ssd.loss import multibox_terms
    from paz6d.ssd.model import (backbone_variables, build_ssd, input_normalization, normalize_images, priors_for,
                                 save_ssd)
    from paz6d.training.scaled_rates import ScaledRateAdamW, keras
    from paz6d.training.trainer import Trainer

    settings = job.model_config
    started = time.perf_counter()
    data = load_detection_set(job.dataset, job.split, dataset_format=job.format)
    job.out.mkdir(parents=True, exist_ok=True)
    _prepare_run_dir(job, settings, data.class_names)
    keras.utils.set_random_seed(job.seed)
    scale = image_scale(settings)
    model, spec = build_ssd(len(data.class_names) + 1, settings.architecture, settings.input_size, settings.width,
                            settings.top_down, any_size=scale is not None, backbone=settings.backbone,
                            frozen_stages=settings.frozen_stages)
    priors = priors_for(spec)
    normalization = input_normalization(settings.backbone)
    run_files.write_detector(job.out, settings.architecture, data.class_names, spec.to_dict(), SSD_VARIANCES,
                             image_scale=scale, normalization=normalization)
    optimizer = ScaledRateAdamW(backbone_variables(model), settings.backbone_rate_factor,
                                learning_rate=_schedule(keras, settings), weight_decay=settings.weight_decay,
                                global_clipnorm=10.0)
    augmentation = augmentation_factory(settings)

    def make_batch(step: int):
        images, targets = training_batch(data, augmentation, job.seed, step, settings.batch_size,
                                         spec.input_size, priors, settings.iou_threshold)
        return normalize_images(images, normalization), targets

    def loss_fn(model, batch):
        images, targets = batch
        terms = multibox_terms(targets, model(images, training=True))
        return {"loss": terms["classification"] + terms["localization"], **terms}

    sample_images = [load_image(sample.path) for sample in data.samples[:4]]
    trainer = Trainer(model, optimizer, loss_fn, make_batch, job.out, settings.steps,
                      checkpoint_every=settings.checkpoint_every, log_every=10, sample_every=settings.sample_every,
                      sample_callback=_sample_drawer(sample_images, SSDRunDir.read_description(job.out)),
                      progress=job.progress, prefetch=2, prefetch_workers=1)
    training = trainer.fit()
    save_ssd(model, SSDRunDir.model_path(job.out))
    summary = {"config": job.config, "architecture": settings.architecture,
               "backbone": settings.backbone, "steps": training.final_step,
               "train_seconds": round(time.perf_counter() - started, 1), "images": len(data),
               "class_names": list(data.class_names), "final_losses": training.metrics,
               "loader_samples_per_second": finite_or_none(training.loader_samples_per_second, 1),
               "model_samples_per_second": finite_or_none(training.model_samples_per_second, 1)}
    SSDRunDir.write_metrics(job.out, summary)
    return summary
