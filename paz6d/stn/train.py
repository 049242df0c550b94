"""Spatial-transformer training: a digit classifier on cluttered canvases (:mod:`paz6d.stn.digits`)
with or without the transformer, on the shared Trainer (the command is :mod:`paz6d.stn.command`, its
settings :mod:`paz6d.stn.config`).

Every step draws ``batch_size`` fresh training canvases (sample ``step * batch_size + i`` of the train
stream), so a resumed run sees the same data. At the end the network is scored on ``test_samples``
canvases of the held-out digits (test accuracy in ``metrics.json``) and ``crops.png`` shows test
canvases next to what the classifier saw (the transformer's crops). Re-running the same command resumes.
TensorFlow is loaded inside :func:`train_stn`.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from paz6d.backend.draw import image_grid
from paz6d.backend.files import finite_or_none
from paz6d.backend.image import save_image
from paz6d.processors.predict import predict_in_batches
from paz6d.stn import run_dir as run_files
from paz6d.stn.config import FIXED_SETTINGS, STNConfig, STNTraining
from paz6d.stn.digits import CLASS_NAMES, TEST, TRAIN, ClutteredDigits, DigitCanvas
from paz6d.stn.run_dir import STNRunDir
from paz6d.training.settings import check_same_run

#: Canvases and crops drawn in ``crops.png`` and the training samples.
PREVIEW_COUNT = 16
PREVIEW_SCALE = 3  # pixels per canvas pixel in the PNGs


def _prepare_run_dir(job: STNTraining, settings: STNConfig) -> None:
    """Writes ``config.json`` or checks that an existing one describes the same run."""
    config = {"method": "stn", "config": job.config, "transformer": job.transformer, "seed": job.seed,
              "settings": settings.to_dict()}
    check_same_run(job.out / STNRunDir.CONFIG_FILE, STNRunDir.read_config(job.out), config,
                   ("method", "config", "transformer", "seed"), settings, FIXED_SETTINGS)
    STNRunDir.write_config(job.out, config)


def canvas_settings(settings: STNConfig) -> DigitCanvas:
    """The :class:`DigitCanvas` of a run's settings."""
    return DigitCanvas(settings.canvas_size, settings.scale, settings.clutter, settings.fragment_size)


def _tile(image: np.ndarray, factor: int) -> np.ndarray:
    """``(h, w)`` values in [0, 1] -> an RGB uint8 tile enlarged ``factor`` times (nearest neighbour)."""
    grey = np.round(np.clip(image, 0.0, 1.0) * 255.0).astype(np.uint8)
    grey = np.kron(grey, np.ones((factor, factor), np.uint8))
    return np.repeat(grey[..., None], 3, axis=2)


def draw_crops(model, images: np.ndarray, labels: np.ndarray, path: Path) -> Path:
    """A PNG of canvases (left) and what the classifier saw (right: the transformer's crop, enlarged to
    the canvas's size), the predicted class in the corner (green when right, red when wrong), 4 pairs per row."""
    import cv2

    outputs = predict_in_batches(lambda batch: model(batch, training=False), images)
    crops = outputs["crop"][..., 0] if "crop" in outputs else images[..., 0]
    predicted = np.argmax(outputs["probabilities"], axis=-1)
    crop_factor = max(1, round(PREVIEW_SCALE * images.shape[1] / crops.shape[1]))  # both about the same size
    canvas_side, crop_side = images.shape[1] * PREVIEW_SCALE, crops.shape[1] * crop_factor
    side = max(canvas_side, crop_side)
    tiles = []
    for image, crop, label, guess in zip(images[..., 0], crops, labels, predicted):
        pair = np.full((side, 2 * side + 4, 3), 255, np.uint8)
        pair[:canvas_side, :canvas_side] = _tile(image, PREVIEW_SCALE)
        pair[:crop_side, side + 4:side + 4 + crop_side] = _tile(crop, crop_factor)
        colour = (0, 200, 0) if guess == label else (230, 0, 0)
        cv2.putText(pair, CLASS_NAMES[int(guess)], (side + 8, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.6, colour, 2)
        tiles.append(pair)
    return save_image(path, image_grid(tiles, columns=4, padding=6))


def test_accuracy(model, data: ClutteredDigits, count: int, seed: int, batch_size: int = 256) -> dict:
    """Accuracy of ``model`` on ``count`` test canvases (held-out digits), and per-class accuracy."""
    correct = np.zeros(len(CLASS_NAMES))
    total = np.zeros(len(CLASS_NAMES))
    for start in range(0, count, batch_size):
        images, labels, _ = data.batch(TEST, start, min(batch_size, count - start), seed)
        probabilities = np.asarray(model(images, training=False)["probabilities"])
        hits = np.argmax(probabilities, axis=-1) == labels
        np.add.at(correct, labels, hits)
        np.add.at(total, labels, 1)
    per_class = {name: finite_or_none(correct[i] / total[i], 4) if total[i] else None
                 for i, name in enumerate(CLASS_NAMES)}
    return {"test_accuracy": round(float(correct.sum() / total.sum()), 4), "test_samples": int(count),
            "test_accuracy_per_class": per_class}


def train_stn(job: STNTraining, digits: ClutteredDigits | None = None) -> dict:
    """Trains (or resumes) one run and writes everything :class:`~paz6d.stn.pipeline.ClassifyDigit` needs.

    Args:
        job: what to train and where.
        digits: optional data (default: :class:`ClutteredDigits` of the run's canvas settings).
    Returns:
        A summary (also ``job.out/metrics.json``): steps, seconds, final losses, test accuracy.
    Raises:
        ValueError: a different run in ``job.out``, bad settings.
    """
    from paz6d.stn.model import build_classifier, keras, save_classifier, tf
    from paz6d.training.trainer import Trainer

    settings = job.model_config
    started = time.perf_counter()
    data = digits if digits is not None else ClutteredDigits(canvas_settings(settings))
    job.out.mkdir(parents=True, exist_ok=True)
    _prepare_run_dir(job, settings)
    keras.utils.set_random_seed(job.seed)
    model = build_classifier(len(CLASS_NAMES), settings.canvas_size, job.transformer, settings.crop_size,
                             settings.filters, settings.padding, settings.theta_scale)
    run_files.write_classifier(job.out, settings.canvas_size, settings.crop_size, job.transformer, CLASS_NAMES,
                               settings.padding)
    schedule = keras.optimizers.schedules.CosineDecay(settings.learning_rate, settings.steps, alpha=0.05)
    optimizer = keras.optimizers.Adam(schedule, global_clipnorm=5.0)
    batch_size = settings.batch_size

    def make_batch(step: int):
        images, labels, _ = data.batch(TRAIN, step * batch_size, batch_size, job.seed)
        return images, labels

    def loss_fn(model, batch):
        images, labels = batch
        outputs = model(images, training=True)
        loss = tf.reduce_mean(tf.nn.sparse_softmax_cross_entropy_with_logits(labels, outputs["logits"]))
        accuracy = tf.reduce_mean(tf.cast(tf.equal(tf.argmax(outputs["logits"], -1), labels), tf.float32))
        return {"loss": loss, "accuracy": accuracy}

    preview_images, preview_labels, _ = data.batch(TEST, 0, PREVIEW_COUNT, job.seed)

    def sample(model, step, path):
        draw_crops(model, preview_images, preview_labels, path)

    trainer = Trainer(model, optimizer, loss_fn, make_batch, job.out, settings.steps,
                      checkpoint_every=settings.checkpoint_every, log_every=10, sample_every=settings.sample_every,
                      sample_callback=sample, progress=job.progress, prefetch=2)
    previous = STNRunDir.read_metrics(job.out)
    training = trainer.fit()
    train_seconds = time.perf_counter() - started
    save_classifier(model, STNRunDir.model_path(job.out))
    draw_crops(model, preview_images, preview_labels, run_files.crops_path(job.out))
    figures = {"train_seconds": round(train_seconds, 1), "final_losses": training.metrics,
               "model_samples_per_second": finite_or_none(training.model_samples_per_second, 1)}
    if training.final_step == training.start_step and previous:  # a finished run re-run: keep its training figures
        figures = {key: previous.get(key) for key in figures}
    summary = {"config": job.config, "transformer": job.transformer, "steps": training.final_step,
               "batch_size": batch_size, **figures, "parameters": int(model.count_params()),
               **test_accuracy(model, data, settings.test_samples, job.seed)}
    STNRunDir.write_metrics(job.out, summary)
    return summary
