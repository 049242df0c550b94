"""Mask-head training on a ``paz6d generate`` data set with the shared Trainer.

Crops around jittered visible boxes and their visible-mask targets come from :mod:`paz6d.segmentation.dataset`;
the loss is the per-pixel sigmoid cross-entropy of the box class's output channel
(:func:`paz6d.segmentation.model.mask_loss`, Mask R-CNN's mask loss), logged with the crops' mean mask IoU.
The run directory (:mod:`paz6d.segmentation.run_dir`) gets ``segmenter.json`` + ``model.keras`` (what
:class:`~paz6d.segmentation.pipeline.SegmentInstances` loads), the Trainer's checkpoints, ``log.csv``,
``tensorboard/``, ``samples/`` (predicted masks on fixed crops) and ``metrics.json``. Re-running the same
command resumes. Held-out scoring: :mod:`paz6d.segmentation.evaluate`.
"""

from __future__ import annotations

import time

import numpy as np

from paz6d.backend.draw import draw_mask_outline, image_grid
from paz6d.backend.files import finite_or_none
from paz6d.backend.image import save_image
from paz6d.segmentation import run_dir as run_files
from paz6d.segmentation.config import FIXED_SETTINGS, SegmentationConfig, SegmentationTraining
from paz6d.segmentation.dataset import MaskSet, crop_batch, cut_instance, load_mask_set
from paz6d.segmentation.run_dir import SegmentationRunDir
from paz6d.training.settings import check_same_run


def _prepare_run_dir(job: SegmentationTraining, settings: SegmentationConfig, class_names: tuple[str, ...]) -> None:
    """Writes ``config.json`` or checks that an existing one describes the same run."""
    config = {"dataset": str(job.dataset.resolve()), "split": job.split, "config": job.config, "seed": job.seed,
              "class_names": list(class_names), "settings": settings.to_dict()}
    check_same_run(job.out / SegmentationRunDir.CONFIG_FILE, SegmentationRunDir.read_config(job.out), config,
                   ("dataset", "split", "config", "seed", "class_names"), settings, FIXED_SETTINGS)
    SegmentationRunDir.write_config(job.out, config)


def fixed_crops(data: MaskSet, count: int, size: int, margin: float) -> dict[str, np.ndarray]:
    """``count`` evenly spaced instances cut around their exact boxes (sample images of the run)."""
    picks = np.linspace(0, len(data) - 1, min(count, len(data))).astype(int)
    cut = [cut_instance(data, data.instances[pick], data.instances[pick].box, size, margin) for pick in picks]
    return {"crops": np.stack([crop for crop, _ in cut]), "masks": np.stack([mask for _, mask in cut]),
            "class_ids": np.array([data.instances[pick].class_id for pick in picks], np.int32)}


def draw_crop_masks(crops: np.ndarray, predicted: np.ndarray, truth: np.ndarray, scale: int = 2) -> np.ndarray:
    """A grid of crops with the predicted mask tinted red and the true mask's outline in green."""
    tiles = []
    for crop, mask, target in zip(crops, predicted, truth):
        tile = crop.astype(np.float32)
        tile[mask] = 0.5 * tile[mask] + [127.5, 0, 0]
        tile = np.repeat(np.repeat(tile.astype(np.uint8), scale, 0), scale, 1)
        target = np.repeat(np.repeat(target, scale, 0), scale, 1)
        tiles.append(draw_mask_outline(tile, target, (0, 255, 0)))
    return image_grid(tiles, columns=4)


def _sample_drawer(samples: dict[str, np.ndarray]):
    def draw(model, step, path):
        from paz6d.segmentation.model import pick_class

        logits = pick_class(model(samples["crops"].astype(np.float32), training=False), samples["class_ids"])
        save_image(path, draw_crop_masks(samples["crops"], np.asarray(logits) > 0, samples["masks"]))

    return draw


def train_segmentation(job: SegmentationTraining) -> dict:
    """Trains (or resumes) one mask-head run and writes everything ``SegmentInstances`` needs.

    Returns:
        A summary (also ``job.out/metrics.json``): steps, seconds, final loss and crop IoU, instances.
    Raises:
        ValueError: a missing or malformed data set, a different run in ``job.out``.
    """
    from paz6d.segmentation.model import build_segmenter, keras, mask_iou, mask_loss, save_segmenter
    from paz6d.training.trainer import Trainer

    settings = job.model_config
    started = time.perf_counter()
    data = load_mask_set(job.dataset, job.split, progress=job.progress)
    job.out.mkdir(parents=True, exist_ok=True)
    _prepare_run_dir(job, settings, data.class_names)
    keras.utils.set_random_seed(job.seed)
    size, margin = settings.input_size, settings.margin
    model = build_segmenter(len(data.class_names), size, settings.widths)
    run_files.write_segmenter(job.out, size, margin, data.class_names)
    schedule = keras.optimizers.schedules.CosineDecay(settings.learning_rate, settings.steps, alpha=0.02)
    optimizer = keras.optimizers.Adam(schedule, global_clipnorm=5.0)

    def make_batch(step: int):
        return crop_batch(data, np.random.default_rng([job.seed, step]), settings.batch_size, size, margin,
                          settings.jitter)

    def loss_fn(model, batch):
        logits = model(batch["crops"], training=True)
        return {"loss": mask_loss(logits, batch["masks"], batch["class_ids"]),
                "iou": mask_iou(logits, batch["masks"], batch["class_ids"])}

    trainer = Trainer(model, optimizer, loss_fn, make_batch, job.out, settings.steps,
                      checkpoint_every=settings.checkpoint_every, log_every=10, sample_every=settings.sample_every,
                      sample_callback=_sample_drawer(fixed_crops(data, 16, size, margin)),
                      progress=job.progress, prefetch=2, prefetch_workers=1)
    training = trainer.fit()
    save_segmenter(model, SegmentationRunDir.model_path(job.out))
    summary = {"config": job.config, "steps": training.final_step, "parameters": int(model.count_params()),
               "train_seconds": round(time.perf_counter() - started, 1), "images": len(data.images),
               "instances": len(data), "class_names": list(data.class_names), "final_losses": training.metrics,
               "loader_samples_per_second": finite_or_none(training.loader_samples_per_second, 1),
               "model_samples_per_second": finite_or_none(training.model_samples_per_second, 1)}
    SegmentationRunDir.write_metrics(job.out, summary)
    return summary
