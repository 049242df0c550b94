"""Settings of ``paz6d train ssd``: the quick and full configs and one run's :class:`SSDTraining`
(whose fields are the command's flags). Light: no numpy, no TensorFlow."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from paz6d.cli_options import option
from paz6d.training.presets import apply_positive_integers, preset_settings

CONFIGS: dict[str, dict] = {
    # CPU budget: generation + training within 30 minutes on 2 cores; the input size's trade-off is measured in
    # docs/experiments/2026-12-02-ssd-input-resolution.md.
    "quick": {"architecture": "light", "input_size": 448, "width": 1.0, "batch_size": 16, "steps": 1500,
              "learning_rate": 3e-3, "warmup_steps": 100, "weight_decay": 1e-4, "expand_ratio": 2.0,
              "expand_probability": 0.3, "iou_threshold": 0.5, "checkpoint_every": 250, "sample_every": 250},
    # The paper's SSD300 (VGG16, random initialisation) for a GPU.
    "full": {"architecture": "ssd300", "input_size": 300, "width": 1.0, "batch_size": 32, "steps": 120000,
             "learning_rate": 1e-3, "warmup_steps": 1000, "weight_decay": 5e-4, "expand_ratio": 4.0,
             "expand_probability": 0.5, "iou_threshold": 0.5, "checkpoint_every": 5000, "sample_every": 5000},
}


#: SSD networks: the paper's two VGG16 ones and a light CPU one (:mod:`paz6d.ssd.model`).
ARCHITECTURES = ("ssd300", "ssd512", "light")
#: Input sides of the VGG networks (fixed); the light network takes any :func:`check_light_side` up to
#: :data:`MAX_INPUT_SIZE`, by default :data:`DEFAULT_INPUT_SIZE` (the quick config's).
FIXED_INPUT_SIZES = {"ssd300": 300, "ssd512": 512}
DEFAULT_INPUT_SIZE: int = CONFIGS["quick"]["input_size"]
MAX_INPUT_SIZE = 2048


def check_light_side(size: int, error: type[ValueError] = ValueError) -> int:
    """``size`` when the light network can run on an image side of that many pixels (a multiple of 64, at
    least 128: its coarsest feature map is 1/64 of the input), else raises ``error``."""
    if size < 128 or size % 64:
        raise error(f"input_size: expected a multiple of 64 of at least 128 for 'light', got {size}")
    return size


def check_input_size(architecture: str, size: int | None, error: type[ValueError] = ValueError) -> int:
    """The side in pixels of ``architecture``'s square training input for a requested ``size`` (``None``:
    the default): the VGG networks' fixed side, or for ``light`` a :func:`check_light_side` of at most
    :data:`MAX_INPUT_SIZE`. The one check of ``input_size`` (settings, :func:`paz6d.ssd.model.paper_priors`).

    Raises:
        error: an unknown ``architecture`` or a size it cannot take (naming the setting).
    """
    if architecture not in ARCHITECTURES:
        raise error(f"architecture: expected one of {ARCHITECTURES}, got {architecture!r}")
    if architecture in FIXED_INPUT_SIZES:
        fixed = FIXED_INPUT_SIZES[architecture]
        if size is not None and int(size) != fixed:
            raise error(f"input_size: only the light network takes another input size; {architecture} takes "
                        f"{fixed} x {fixed} images, got {size}")
        return fixed
    size = check_light_side(DEFAULT_INPUT_SIZE if size is None else int(size), error)
    if size > MAX_INPUT_SIZE:
        raise error(f"input_size: expected at most {MAX_INPUT_SIZE} px (a training input side), got {size}")
    return size


#: Pretrained bodies of the light network (``--backbone``; docs/backbones.md); "none": its own, from scratch.
BACKBONES = ("none", "efficientnet-lite0")
#: Settings a backbone brings, applied over the config's (and under ``overrides`` and the flags): input 320 px,
#: batch 8 (their cost: docs/backbones.md), the heads' learning rate and the backbone's factor of it, and the
#: stages kept fixed (stem and stages up to stride 4).
BACKBONE_SETTINGS: dict[str, dict] = {
    "efficientnet-lite0": {"backbone": "efficientnet-lite0", "input_size": 320, "batch_size": 8,
                           "learning_rate": 1e-3, "backbone_rate_factor": 0.1, "frozen_stages": 3,
                           "warmup_steps": 100},
}

#: Data set formats ``paz6d train ssd --format`` reads (``paz6d.ssd.dataset.FORMATS``, kept here light).
DATASET_FORMATS = ("auto", "generated", "voc", "coco", "openimages")
#: Keys of a run's settings that must not change when it is resumed.
FIXED_SETTINGS = ("architecture", "input_size", "width", "top_down", "scale_crops", "iou_threshold", "backbone",
                  "frozen_stages")


@dataclass
class SSDTraining:
    """One ``paz6d train ssd`` run (each field but ``overrides`` is a flag, see :mod:`paz6d.cli_options`)."""

    dataset: Path = option(help="data set: a `paz6d generate` output, a VOC devkit year folder (or folder of "
                                "XML files), a COCO folder (or instances JSON file) or an Open Images folder")
    out: Path = option(help="run directory (re-run the command to resume)")
    split: str | None = option(None, "split of the data set (default: train; VOC: trainval; COCO: the train* file)")
    format: str = option("auto", "data set format (auto: detected from the folder)", choices=DATASET_FORMATS)
    config: str = option("quick", "network and schedule", choices=tuple(sorted(CONFIGS)))
    seed: int = option(0, "seed of the initialisation and of every batch")
    steps: int | None = option(None, "training steps (default: the config's)")
    batch_size: int | None = option(None, "images per step (default: the config's)")
    input_size: int | None = option(None, "side of the square network input in pixels, light network only: a "
                                          "multiple of 64, at least 128 (default: the config's)")
    scale_crops: tuple[float, float] | None = option(
        None, "light network only: train on input-sized windows of images rescaled by a factor in [LOW, HIGH] "
              "and detect on whole images at the factors' geometric mean (default: the config's)",
        metavar=("LOW", "HIGH"))
    backbone: str | None = option(None, "body of the light network: efficientnet-lite0 (pretrained on ImageNet, "
                                        "docs/backbones.md; brings its input size, batch size and learning rates "
                                        "unless given) or none (its own, from scratch; default: the config's)",
                                  choices=BACKBONES)
    progress: bool = option(True, "progress bar")
    overrides: dict = field(default_factory=dict)  # settings replacing the config's (e.g. a tiny network in tests)

    def __post_init__(self):
        self.dataset, self.out = Path(self.dataset), Path(self.out)
        self.settings()

    def settings(self) -> dict:
        """The config's settings with the backbone's (:data:`BACKBONE_SETTINGS`), ``overrides``, ``steps``,
        ``batch_size`` and ``input_size`` applied, in that order.

        Raises:
            ValueError: a non-positive value, an ``input_size`` the network cannot take, or a backbone for
                another network than the light one.
        """
        settings = preset_settings(CONFIGS, self.config, {}, check_overrides=False)
        backbone = self.backbone or self.overrides.get("backbone") or settings.get("backbone") or "none"
        if backbone not in BACKBONES:
            raise ValueError(f"backbone: expected one of {BACKBONES}, got {backbone!r}")
        if backbone != "none":
            if settings["architecture"] != "light":
                raise ValueError(f"backbone: only the light network takes a pretrained body; the {self.config!r} "
                                 f"config's is {settings['architecture']}")
            settings.update(BACKBONE_SETTINGS[backbone])
        settings = apply_positive_integers({**settings, **self.overrides},
                                           {"steps": self.steps, "batch_size": self.batch_size,
                                            "input_size": self.input_size})
        if backbone == "none":
            settings.pop("backbone", None)
        else:
            settings["backbone"] = backbone
        settings["input_size"] = check_input_size(settings["architecture"], settings["input_size"])
        if self.scale_crops is not None:
            settings["scale_crops"] = [float(v) for v in self.scale_crops]
        scale_crops = settings.get("scale_crops")
        if scale_crops is not None:
            if settings["architecture"] != "light":
                raise ValueError(f"scale_crops: only the light network runs on whole images; the {self.config!r} "
                                 f"config's {settings['architecture']} takes square inputs")
            if len(scale_crops) != 2 or not 0 < float(scale_crops[0]) <= float(scale_crops[1]):
                raise ValueError(f"scale_crops: expected a factor range 0 < LOW <= HIGH, got {scale_crops}")
        return settings
