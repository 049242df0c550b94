"""``paz6d train ssd``: a single-shot detector trained on a ``paz6d generate`` data set with the shared Trainer.

The data set's COCO annotations (``<dataset>/<split>/<scene>/scene_gt_coco.json``, visible boxes) are read
by :mod:`paz6d.ssd.dataset`; every sample goes through SSD's augmentation
(:func:`paz6d.synthesis.box_augment.ssd_augmentation`), is resized to the network input and matched to
the priors. The loss is :class:`paz6d.ssd.loss.MultiboxLoss`. Configurations:

- ``quick``: the ``light`` CPU network (320 x 320), sized for a half-hour run on 2 CPU cores;
- ``full``: SSD300 with a VGG16 body (the paper's network), for a GPU.

The run directory (:mod:`paz6d.ssd.run_dir`) gets ``detector.json`` + ``model.keras`` (what
:class:`~paz6d.ssd.pipeline.DetectSingleShot` loads), the Trainer's checkpoints, ``log.csv``,
``tensorboard/`` and ``samples/`` (detections on training images), and ``metrics.json``. Re-running
the same command resumes.

This module is cheap to import: TensorFlow is loaded inside :func:`run`.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np

from paz6d.backend.boxes import SSD_VARIANCES
from paz6d.backend.draw import image_grid
from paz6d.backend.files import finite_or_none
from paz6d.backend.image import load_image, resize, save_image
from paz6d.cli_options import add_config_arguments, config_from_args, flags_in_errors, option
from paz6d.processors.boxes import ToBoxes2D
from paz6d.ssd import run_dir as run_files
from paz6d.ssd.dataset import load_detection_set, training_batch
from paz6d.ssd.encoding import BACKGROUND, decode_outputs, select_detections
from paz6d.ssd.pipeline import draw_detections
from paz6d.synthesis.box_augment import ssd_augmentation

CONFIGS: dict[str, dict] = {
    # CPU budget: generation + training within 30 minutes on 2 cores (docs/ssd.md).
    "quick": {"architecture": "light", "input_size": 320, "width": 1.0, "batch_size": 16, "steps": 1500,
              "learning_rate": 3e-3, "warmup_steps": 100, "weight_decay": 1e-4, "expand_ratio": 2.0,
              "expand_probability": 0.3, "iou_threshold": 0.5, "checkpoint_every": 250, "sample_every": 250},
    # The paper's SSD300 (VGG16, random initialisation) for a GPU.
    "full": {"architecture": "ssd300", "input_size": 300, "width": 1.0, "batch_size": 32, "steps": 120000,
             "learning_rate": 1e-3, "warmup_steps": 1000, "weight_decay": 5e-4, "expand_ratio": 4.0,
             "expand_probability": 0.5, "iou_threshold": 0.5, "checkpoint_every": 5000, "sample_every": 5000},
}
#: Keys of a run's settings that must not change when it is resumed.
FIXED_SETTINGS = ("architecture", "input_size", "width", "iou_threshold")


@dataclass
class SSDTraining:
    """One ``paz6d train ssd`` run (each field but ``overrides`` is a flag, see :mod:`paz6d.cli_options`)."""

    dataset: Path = option(help="data set folder written by `paz6d generate` (COCO annotations per scene)")
    out: Path = option(help="run directory (re-run the command to resume)")
    split: str | None = option(None, "split folder of the data set (default: train)")
    config: str = option("quick", "network and schedule", choices=tuple(sorted(CONFIGS)))
    seed: int = option(0, "seed of the initialisation and of every batch")
    steps: int | None = option(None, "training steps (default: the config's)")
    batch_size: int | None = option(None, "images per step (default: the config's)")
    progress: bool = option(True, "progress bar")
    overrides: dict = field(default_factory=dict)  # settings replacing the config's (e.g. a tiny network in tests)

    def __post_init__(self):
        self.dataset, self.out = Path(self.dataset), Path(self.out)
        self.settings()

    def settings(self) -> dict:
        """The config's settings with ``overrides``, ``steps`` and ``batch_size`` applied."""
        if self.config not in CONFIGS:
            raise ValueError(f"config: expected one of {sorted(CONFIGS)}, got {self.config!r}")
        settings = {**CONFIGS[self.config], **self.overrides}
        for name in ("steps", "batch_size"):
            value = getattr(self, name)
            if value is not None:
                if int(value) <= 0:
                    raise ValueError(f"{name}: expected a positive integer, got {value}")
                settings[name] = int(value)
        return settings


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``paz6d train ssd`` flags (the fields of :class:`SSDTraining`)."""
    add_config_arguments(parser, SSDTraining, exclude=("overrides",))


def run(args: argparse.Namespace) -> int:
    """Entry point of ``paz6d train ssd``."""
    job = config_from_args(SSDTraining, args, exclude=("overrides",))
    with flags_in_errors(SSDTraining):
        summary = train_ssd(job)
    print(json.dumps(summary, indent=2))
    return 0


def _prepare_run_dir(job: SSDTraining, settings: dict, class_names: tuple[str, ...]) -> None:
    """Writes ``config.json`` or checks that an existing one describes the same run."""
    config = {"dataset": str(job.dataset.resolve()), "split": job.split, "config": job.config, "seed": job.seed,
              "class_names": list(class_names), "settings": settings}
    previous = run_files.read_config(job.out)
    if previous is not None:
        changed = [key for key in ("dataset", "config", "seed", "class_names") if previous.get(key) != config[key]]
        changed += [key for key in FIXED_SETTINGS if previous.get("settings", {}).get(key) != settings.get(key)]
        if changed:
            raise ValueError(f"out: {job.out} holds a different run ({', '.join(changed)} differ); choose another --out")
    run_files.write_config(job.out, config)


def _schedule(keras, settings: dict):
    """Linear warm-up to ``learning_rate`` then cosine decay to 1 % of it."""
    steps, warmup = int(settings["steps"]), min(int(settings["warmup_steps"]), int(settings["steps"]) - 1)
    return keras.optimizers.schedules.CosineDecay(
        0.0 if warmup else settings["learning_rate"], max(steps - warmup, 1), alpha=0.01,
        warmup_target=settings["learning_rate"] if warmup else None, warmup_steps=warmup)


def _sample_drawer(images: list[np.ndarray], spec, class_names: tuple[str, ...], variances):
    """``sample_callback(model, step, path)``: detections (score >= 0.3) on a few training images."""

    def draw(model, step, path):
        from paz6d.ssd.model import normalize_images, priors_for

        priors = priors_for(spec)
        inputs = normalize_images(np.stack([resize(image, (spec.input_size,) * 2) for image in images]))
        outputs = np.asarray(model(inputs, training=False))
        tiles = []
        for image, output in zip(images, outputs):
            boxes, scores, ids = select_detections(*decode_outputs(output, priors, variances), score_threshold=0.3)
            height, width = image.shape[:2]
            pixels = boxes * np.array([width, height, width, height])
            tiles.append(draw_detections(image, ToBoxes2D((BACKGROUND,) + class_names)(pixels, scores, ids), class_names))
        save_image(path, image_grid(tiles, columns=2))

    return draw


def train_ssd(job: SSDTraining) -> dict:
    """Trains (or resumes) one SSD run and writes everything ``DetectSingleShot`` needs.

    Returns:
        A summary (also ``job.out/metrics.json``): steps, seconds, final losses, samples per second.
    Raises:
        ValueError: empty or malformed data set, a different run in ``job.out``.
    """
    from paz6d.ssd.loss import multibox_terms
    from paz6d.ssd.model import build_ssd, keras, normalize_images, priors_for, save_ssd
    from paz6d.training.trainer import Trainer

    settings = job.settings()
    started = time.perf_counter()
    data = load_detection_set(job.dataset, job.split)
    job.out.mkdir(parents=True, exist_ok=True)
    _prepare_run_dir(job, settings, data.class_names)
    keras.utils.set_random_seed(job.seed)
    model, spec = build_ssd(len(data.class_names) + 1, settings["architecture"], settings["input_size"],
                            settings["width"])
    priors = priors_for(spec)
    run_files.write_detector(job.out, settings["architecture"], data.class_names, spec.to_dict(), SSD_VARIANCES)
    optimizer = keras.optimizers.AdamW(_schedule(keras, settings), weight_decay=settings["weight_decay"],
                                       global_clipnorm=10.0)
    augmentation = partial(ssd_augmentation, settings["expand_ratio"], settings["expand_probability"])

    def make_batch(step: int):
        images, targets = training_batch(data, augmentation, job.seed, step, settings["batch_size"],
                                         spec.input_size, priors, settings["iou_threshold"])
        return normalize_images(images), targets

    def loss_fn(model, batch):
        images, targets = batch
        terms = multibox_terms(targets, model(images, training=True))
        return {"loss": terms["classification"] + terms["localization"], **terms}

    sample_images = [load_image(sample.path) for sample in data.samples[:4]]
    trainer = Trainer(model, optimizer, loss_fn, make_batch, job.out, settings["steps"],
                      checkpoint_every=settings["checkpoint_every"], log_every=10,
                      sample_every=settings["sample_every"],
                      sample_callback=_sample_drawer(sample_images, spec, data.class_names, SSD_VARIANCES),
                      progress=job.progress, prefetch=2, prefetch_workers=1)
    training = trainer.fit()
    save_ssd(model, run_files.model_path(job.out))
    summary = {"config": job.config, "architecture": settings["architecture"], "steps": training.final_step,
               "train_seconds": round(time.perf_counter() - started, 1), "images": len(data),
               "class_names": list(data.class_names), "final_losses": training.metrics,
               "loader_samples_per_second": finite_or_none(training.loader_samples_per_second, 1),
               "model_samples_per_second": finite_or_none(training.model_samples_per_second, 1)}
    run_files.write_metrics(job.out, summary)
    return summary
