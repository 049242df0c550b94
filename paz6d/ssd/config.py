"""Settings of ``paz6d train ssd``: the network, augmentation and schedule (:class:`SSDConfig`, presets
:data:`QUICK` and :data:`FULL`) and one run's :class:`SSDTraining` (whose fields are the command's flags).
Light: no numpy, no TensorFlow."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from paz6d.backbones import BACKBONES
from paz6d.cli_options import option
from paz6d.training.settings import Settings, positive, run_settings, setting, share, with_flags

#: SSD networks: the paper's two VGG16 ones and a light CPU one (:mod:`paz6d.ssd.model`).
ARCHITECTURES = ("ssd300", "ssd512", "light")
#: Input sides of the VGG networks (fixed); the light network takes any :func:`check_light_side` up to
#: :data:`MAX_INPUT_SIZE`, by default :data:`DEFAULT_INPUT_SIZE` (the quick config's; its trade-off is measured in
#: docs/experiments/2026-12-02-ssd-input-resolution.md).
FIXED_INPUT_SIZES = {"ssd300": 300, "ssd512": 512}
DEFAULT_INPUT_SIZE = 448
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
    :data:`MAX_INPUT_SIZE`. The one check of ``input_size`` (:class:`SSDConfig`, :func:`paz6d.ssd.model.paper_priors`).

    Raises:
        error: an unknown ``architecture`` or a size it cannot take (naming the setting).
    """
    if architecture not in ARCHITECTURES:
        raise error(f"architecture: expected one of {ARCHITECTURES}, got {architecture!r}")
    if size is not None and (isinstance(size, bool) or not isinstance(size, int)):
        raise error(f"input_size: expected a whole number of pixels, got {size!r}")
    if architecture in FIXED_INPUT_SIZES:
        fixed = FIXED_INPUT_SIZES[architecture]
        if size is not None and size != fixed:
            raise error(f"input_size: only the light network takes another input size; {architecture} takes "
                        f"{fixed} x {fixed} images, got {size}")
        return fixed
    size = check_light_side(DEFAULT_INPUT_SIZE if size is None else size, error)
    if size > MAX_INPUT_SIZE:
        raise error(f"input_size: expected at most {MAX_INPUT_SIZE} px (a training input side), got {size}")
    return size


#: Settings a backbone brings, applied over the preset's (and under the flags): input 320 px, batch 8 (their
#: cost: docs/backbones.md), the heads' learning rate and the backbone's factor of it, and the stages kept fixed
#: (stem and stages up to stride 4).
BACKBONE_SETTINGS: dict[str, dict] = {
    "efficientnet-lite0": {"backbone": "efficientnet-lite0", "input_size": 320, "batch_size": 8,
                           "learning_rate": 1e-3, "backbone_rate_factor": 0.1, "frozen_stages": 3,
                           "warmup_steps": 100},
}


@dataclass(frozen=True)
class SSDConfig(Settings):
    """Network, augmentation and schedule of an SSD run.

    Attributes:
        architecture: one of :data:`ARCHITECTURES`.
        input_size: side of the square training input in pixels (:func:`check_input_size`).
        width: channel multiplier of the light network.
        top_down: light network only: top-down feature fusion (FPN-style) before the heads.
        backbone: body of the light network, one of :data:`BACKBONES` (``"none"``: its own, from scratch).
        backbone_rate_factor: the backbone's learning rate as a factor of the heads'.
        frozen_stages: backbone stages kept fixed (stem and stages up to stride 4: 3).
        scale_crops: light network only: train on input-sized windows of images rescaled by a factor in this
            range and detect on whole images at the factors' geometric mean (``None``: whole images resized).
        batch_size / steps / learning_rate / warmup_steps / weight_decay: the schedule (linear warm-up, then
            cosine decay; AdamW).
        expand_ratio / expand_probability: zoom-out augmentation (canvas up to ``expand_ratio`` × the image).
        white_balance: strength of the random white-balance shift (0: off).
        grayscale: probability of a grey image.
        iou_threshold: prior-to-box overlap that makes a prior positive.
        checkpoint_every / sample_every: Trainer intervals in steps (sample_every 0: no samples).
    """

    architecture: str = setting("light", choices=ARCHITECTURES)
    input_size: int = DEFAULT_INPUT_SIZE
    width: float = positive(1.0)
    top_down: bool = False
    backbone: str = setting("none", choices=BACKBONES)
    backbone_rate_factor: float = setting(1.0, minimum=0.0)
    frozen_stages: int = setting(3, minimum=0)
    scale_crops: tuple[float, float] | None = setting(None, positive=True, ordered=True)
    batch_size: int = positive(16)
    steps: int = positive(1500)
    learning_rate: float = positive(3e-3)
    warmup_steps: int = setting(100, minimum=0)
    weight_decay: float = setting(1e-4, minimum=0.0)
    expand_ratio: float = setting(2.0, minimum=1.0)
    expand_probability: float = share(0.3)
    white_balance: float = setting(0.0, minimum=0.0)
    grayscale: float = share(0.0)
    iou_threshold: float = share(0.5)
    checkpoint_every: int = positive(250)
    sample_every: int = setting(250, minimum=0)

    def check(self):
        for name, value in (("top_down", self.top_down), ("backbone", self.backbone != "none"),
                            ("scale_crops", self.scale_crops is not None)):
            if value and self.architecture != "light":
                raise ValueError(f"{name}: only the light network takes it (a pretrained body, top-down fusion, "
                                 f"whole images); {self.architecture} does not")
        check_input_size(self.architecture, self.input_size)


#: CPU budget: generation + training within 30 minutes on 2 cores (the light network at
#: :data:`DEFAULT_INPUT_SIZE`).
QUICK = SSDConfig()
#: The paper's SSD300 (VGG16, random initialisation) for a GPU.
FULL = SSDConfig(architecture="ssd300", input_size=300, batch_size=32, steps=120000, learning_rate=1e-3,
                 warmup_steps=1000, weight_decay=5e-4, expand_ratio=4.0, expand_probability=0.5,
                 checkpoint_every=5000, sample_every=5000)
CONFIGS = {"quick": QUICK, "full": FULL}

#: Data set formats ``paz6d train ssd --format`` reads (``paz6d.ssd.dataset.FORMATS``, kept here light).
DATASET_FORMATS = ("auto", "generated", "voc", "coco", "openimages")
#: Keys of a run's settings that must not change when it is resumed.
FIXED_SETTINGS = ("architecture", "input_size", "width", "top_down", "scale_crops", "iou_threshold", "backbone",
                  "frozen_stages")


@dataclass
class SSDTraining:
    """One ``paz6d train ssd`` run (each field but ``settings`` is a flag, see :mod:`paz6d.cli_options`)."""

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
    top_down: bool = option(False, "light network only: add a feature-pyramid top-down path over the stride-8, 16 "
                                   "and 32 maps before the heads (docs/ssd.md; without it: the config's)")
    backbone: str | None = option(None, "body of the light network: efficientnet-lite0 (pretrained on ImageNet, "
                                        "docs/backbones.md; brings its input size, batch size and learning rates "
                                        "unless given) or none (its own, from scratch; default: the config's)",
                                  choices=BACKBONES)
    progress: bool = option(True, "progress bar")
    settings: SSDConfig | None = field(default=None)  # replaces the config's preset (e.g. a tiny network in tests)

    def __post_init__(self):
        self.dataset, self.out = Path(self.dataset), Path(self.out)
        self.model_config  # checks the preset and the flags

    @property
    def model_config(self) -> SSDConfig:
        """``settings`` (default: the preset ``config``) with the backbone's (:data:`BACKBONE_SETTINGS`), then
        ``steps``, ``batch_size``, ``input_size`` and ``scale_crops`` applied, and ``top_down`` when set.

        Raises:
            ValueError: a bad flag value, an ``input_size`` the network cannot take, or a backbone, top-down
                fusion or ``scale_crops`` for another network than the light one.
        """
        settings = run_settings(CONFIGS, self.config, self.settings)
        if self.backbone is not None:
            settings = settings.replace(**BACKBONE_SETTINGS.get(self.backbone, {"backbone": self.backbone}))
        return with_flags(settings, steps=self.steps, batch_size=self.batch_size, input_size=self.input_size,
                          scale_crops=self.scale_crops, top_down=True if self.top_down else None)
