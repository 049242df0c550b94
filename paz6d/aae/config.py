"""Settings of the Augmented Autoencoder: input augmentation strengths (:class:`Augmentation`), the
model/data/schedule presets (:class:`AAEConfig`: :data:`QUICK`, :data:`FULL`) and one
``paz6d train aae`` run (:class:`AAETraining`, one flag per field).

No heavy imports, so that the command line builds fast; the training itself is :mod:`paz6d.aae.train`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

from paz6d.backbones import BACKBONES, check_backbone
from paz6d.backend.checks import (integer_field, is_whole_number, number_field, required_field, short_repr,
                                  unknown_fields)
from paz6d.cli_options import option
from paz6d.datasets.bop.fields import BOX_FIELDS, box_field
from paz6d.datasets.pose_format import POSE_FORMATS, checked_pose_source
from paz6d.training import precision as precision_setting
from paz6d.training.source import checked_mesh_scale
from renderers.platform import PLATFORMS


def check_crop_box(crop_box: str, dataset_format: str | None = None) -> str:
    """``crop_box``, the box a data set's input crops are cut around (a key of
    :data:`~paz6d.datasets.bop.fields.BOX_FIELDS`); ``"visib"`` needs a BOP data set (``dataset_format``
    ``"bop"``, or None when not known yet), the only format with visible-part boxes."""
    box_field(crop_box, "crop_box")
    if crop_box != "obj" and dataset_format not in (None, "bop"):
        raise ValueError(f"crop_box: {crop_box!r} needs a BOP --dataset (visible boxes); got format "
                         f"{dataset_format!r}")
    return crop_box


@dataclass(frozen=True)
class Augmentation:
    """Strengths of the input augmentations (paper: background, occlusion, lighting, colour, crop shift).

    Attributes:
        backgrounds: composite over random procedural backgrounds (else black).
        occlusion_probability: chance that a sample gets 1..``max_occluders`` random occluders.
        occluder_size: occluder size range as fractions of the object box's longest side.
        max_occluders: most occluders per occluded sample.
        shift: crop centre shift, uniform in ``±shift`` × box side.
        scale: crop scale factor range.
        light: strength of the re-lighting (gains ``1 ± light/2``, gradient up to ``± light``).
        brightness: max brightness offset (intensity levels).
        contrast / saturation: factor ranges.
        hue: max hue rotation in degrees.
        blur_probability: chance of a Gaussian blur (sigma 0.4-1.2 px).
        noise: max Gaussian noise std (intensity levels).
    """

    backgrounds: bool = True
    occlusion_probability: float = 0.5
    occluder_size: tuple[float, float] = (0.2, 0.5)
    max_occluders: int = 2
    shift: float = 0.08
    scale: tuple[float, float] = (0.9, 1.1)
    light: float = 0.5
    brightness: float = 30.0
    contrast: tuple[float, float] = (0.6, 1.4)
    saturation: tuple[float, float] = (0.6, 1.4)
    hue: float = 10.0
    blur_probability: float = 0.3
    noise: float = 8.0

    def __post_init__(self):
        fields = vars(self)
        if not isinstance(self.backgrounds, bool):
            raise ValueError(f"Augmentation.backgrounds: expected true or false, got {short_repr(self.backgrounds)}")
        integer_field(fields, "max_occluders", "Augmentation", minimum=1)
        for name in ("occlusion_probability", "blur_probability", "shift", "light", "brightness", "hue", "noise"):
            number_field(fields, name, "Augmentation")
        for name in ("occluder_size", "scale", "contrast", "saturation"):
            required_field(fields, name, "Augmentation", size=2)
        for name in ("occlusion_probability", "blur_probability"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"Augmentation.{name}: expected a probability in [0, 1], got {getattr(self, name)}")
        for name in ("occluder_size", "scale", "contrast", "saturation"):
            low, high = getattr(self, name)
            if not 0.0 < low <= high:
                raise ValueError(f"Augmentation.{name}: expected 0 < low <= high, got {getattr(self, name)}")
        for name in ("shift", "light", "brightness", "hue", "noise"):
            if getattr(self, name) < 0:
                raise ValueError(f"Augmentation.{name}: expected >= 0, got {getattr(self, name)}")


@dataclass(frozen=True)
class AAEConfig:
    """Model, data and schedule of an AAE training run.

    Attributes:
        crop_size: side of the square model input (pixels).
        latent_size: length of the latent code.
        filters: encoder channels per strided convolution (the decoder mirrors them).
        kernel_size: convolution kernel size.
        batch_norm: batch normalisation after every convolution (not in the paper; trains faster).
        padding: crop side / longest side of the object box.
        render_size: side of the on-axis renderings the crops are cut from.
        views: view-sphere directions rendered (training views and codebook share them).
        in_plane: in-plane rotations per view in the codebook (codebook size = views * in_plane).
        steps: optimisation steps.
        batch_size: samples per step.
        learning_rate: Adam learning rate.
        lr_drop_steps: the last this many steps train at ``learning_rate * lr_drop_factor`` (0: one rate
            throughout). Extending a finished run (more ``steps``) moves the drop to the new end.
        lr_drop_factor: the rate's factor for those steps, in (0, 1].
        bootstrap_fraction: fraction of largest pixel errors in the loss (1 = plain L2; paper 0.25).
        precision: compute dtype of the network's convolutions: ``"float32"``, ``"bfloat16"`` (float32
            weights, latent code and reconstruction) or ``"auto"`` (bfloat16 on CPUs that compute it
            natively, :mod:`paz6d.training.precision`). A new run directory records the resolved value;
            runs from before the setting are float32.
        augmentation: input augmentation strengths.
        encoder_backbone: the encoder's body: ``"none"`` (strided convolutions trained from scratch, the paper's)
            or ``"efficientnet-lite0"`` (the ImageNet network of :mod:`paz6d.backbones`, frozen, read at twice
            the crop size up to its stride-16 map; :func:`paz6d.aae.model.build_encoder`).
        checkpoint_every / sample_every / log_every: Trainer intervals in steps.
    """

    crop_size: int = 64
    latent_size: int = 64
    filters: tuple[int, ...] = (32, 64, 64, 128)
    kernel_size: int = 5
    batch_norm: bool = False
    padding: float = 1.2
    render_size: int = 96
    views: int = 1000
    in_plane: int = 36
    steps: int = 3000
    batch_size: int = 32
    learning_rate: float = 1e-3
    lr_drop_steps: int = 0
    lr_drop_factor: float = 0.1
    bootstrap_fraction: float = 0.25
    precision: str = "float32"
    augmentation: Augmentation = field(default_factory=Augmentation)
    encoder_backbone: str = "none"
    checkpoint_every: int = 500
    sample_every: int = 500
    log_every: int = 25

    def __post_init__(self):
        fields = vars(self)
        for name, minimum in (("latent_size", 1), ("kernel_size", 1), ("render_size", 1), ("views", 1),
                              ("in_plane", 1), ("steps", 1), ("batch_size", 1), ("checkpoint_every", 1),
                              ("sample_every", 0), ("log_every", 1)):
            integer_field(fields, name, "AAEConfig", minimum)
        for name in ("padding", "learning_rate"):
            number_field(fields, name, "AAEConfig", positive=True)
        number_field(fields, "bootstrap_fraction", "AAEConfig", maximum=1.0, positive=True)
        if not isinstance(self.batch_norm, bool):
            raise ValueError(f"AAEConfig.batch_norm: expected true or false, got {short_repr(self.batch_norm)}")
        if not (isinstance(self.filters, tuple) and self.filters
                and all(isinstance(channels, int) and not isinstance(channels, bool) and channels > 0
                        for channels in self.filters)):
            raise ValueError(f"AAEConfig.filters: expected a non-empty list of positive channel counts, got "
                             f"{short_repr(self.filters)}")
        stride = 2 ** len(self.filters)  # one strided convolution per entry of filters
        if not (type(self.crop_size) is int and self.crop_size > 0 and self.crop_size % stride == 0):
            raise ValueError(f"AAEConfig.crop_size: expected a positive multiple of 2**len(filters) = {stride} "
                             f"pixels, got {short_repr(self.crop_size)}")
        if not isinstance(self.augmentation, Augmentation):
            raise ValueError(f"AAEConfig.augmentation: expected an Augmentation, got {short_repr(self.augmentation)}")
        if not is_whole_number(self.lr_drop_steps) or not 0 <= self.lr_drop_steps <= self.steps:
            raise ValueError(f"AAEConfig.lr_drop_steps: expected a whole number from 0 to steps ({self.steps}), "
                             f"got {self.lr_drop_steps!r}")
        if not 0.0 < self.lr_drop_factor <= 1.0:
            raise ValueError(f"AAEConfig.lr_drop_factor: expected a factor in (0, 1], got {self.lr_drop_factor!r}")
        precision_setting.check_setting(self.precision, "AAEConfig.precision")
        check_backbone(self.encoder_backbone, "AAEConfig.encoder_backbone")

    def to_dict(self) -> dict:
        data = asdict(self)
        data["filters"] = list(self.filters)
        return data

    @classmethod
    def from_dict(cls, data: dict) -> "AAEConfig":
        """The settings of :meth:`to_dict` (a run's ``config.json``), every field checked.

        Raises:
            ValueError: an unknown field, or one of the wrong type or out of range (naming it).
        """
        if not isinstance(data, dict):
            raise ValueError(f"AAE config: expected an object of settings, got {short_repr(data)}")
        data = dict(data)
        unknown = unknown_fields(cls, data)
        if unknown:
            raise ValueError(f"AAE config: unknown field(s) {unknown}")
        augmentation = data.pop("augmentation", {})
        if not isinstance(augmentation, dict):
            raise ValueError(f"AAEConfig.augmentation: expected an object, got {short_repr(augmentation)}")
        augmentation = dict(augmentation)
        unknown = unknown_fields(Augmentation, augmentation)
        if unknown:
            raise ValueError(f"AAE config: augmentation: unknown field(s) {unknown}")
        for key in ("occluder_size", "scale", "contrast", "saturation"):
            if isinstance(augmentation.get(key), list):
                augmentation[key] = tuple(augmentation[key])
        if isinstance(data.get("filters"), list):
            data["filters"] = tuple(data["filters"])
        return cls(augmentation=Augmentation(**augmentation), **data)

    @property
    def codebook_size(self) -> int:
        return self.views * self.in_plane


#: Sized for a 2-core CPU (the demo): 64x64 crops, batch normalisation (several times faster convergence),
#: latent 128, 1,000 views x 72 in-plane = 72,000-entry codebook, 5,000 steps (~10 minutes); small crop
#: shifts (the demo uses ground-truth boxes; docs/experiments/2026-11-23-aae-demo-quick-config.md). Convolutions
#: in bfloat16 on CPUs that compute it natively (speed: benchmarks/aae_precision.py, docs/aae.md).
QUICK = AAEConfig(latent_size=128, batch_norm=True, in_plane=72, steps=5000, precision="auto",
                  augmentation=Augmentation(shift=0.03, scale=(0.95, 1.05)))
#: The paper's setting: 128x128 crops, latent 128, 30k iterations of 64, 2,562 x 36 = 92,232 codebook views.
FULL = AAEConfig(crop_size=128, latent_size=128, filters=(128, 256, 256, 512), render_size=192, views=2562,
                 in_plane=36, steps=30000, batch_size=64, learning_rate=2e-4, checkpoint_every=1000,
                 sample_every=2000, log_every=50, precision="auto")
CONFIGS = {"quick": QUICK, "full": FULL}


@dataclass(frozen=True)
class AAETraining:
    """One ``paz6d train aae`` run (each field is a flag, see :mod:`paz6d.cli_options`): the object,
    from a mesh or a data set (BOP, YCB-Video or FAT: ``format``, detected from its files by default),
    the run directory, the config preset and how to run."""

    out: Path = option(help="run directory (re-run to resume)")
    mesh: Path | None = option(None, "mesh of the object (PLY/OBJ/GLB)", one_of="source")
    dataset: Path | None = option(None, "data set whose image crops are training inputs: BOP (e.g. from `paz6d "
                                        "generate`; its models/obj_XXXXXX.ply, millimetres, is the object), YCB-Video "
                                        "(models/<class>/textured.obj) or FAT (with --dataset-mesh)", one_of="source")
    dataset_mesh: Path | None = option(None, "with --dataset: the object's mesh, replacing the data set's model "
                                             "(FAT ships none: required)")
    format: str | None = option(None, "format of --dataset (default: detected from its files)", choices=POSE_FORMATS)
    object_id: int | None = option(None, "object of --dataset: BOP object id, or YCB-Video class index (1-21, as BOP "
                                         "YCB-V) (default: the only one)")
    object_class: str | None = option(None, "object of a YCB-Video or FAT --dataset by class name "
                                            "(e.g. 003_cracker_box)")
    split: str | None = option(None, "split of --dataset: BOP split folder, YCB-Video image set or FAT folder "
                                     "(default: train; FAT: mixed)")
    pair_fraction: float = option(0.5, "with --dataset: share of training samples taken from its crops "
                                       "(the rest: rendered views)")
    crop_box: str = option("obj", "with a BOP --dataset: the box each input crop is cut around: obj (the whole "
                                  "object's) or visib (its visible part, as a detector's box); the clean target "
                                  "is always the whole object's view", choices=tuple(sorted(BOX_FIELDS)))
    config: str = option("quick", "quick: 64x64, minutes on a 2-core CPU; full: the paper's 128x128, 30k steps, "
                                  "92,232-view codebook (hours on a CPU)", choices=tuple(sorted(CONFIGS)))
    steps: int | None = option(None, "training steps (default: the config's)")
    precision: str | None = option(None, "compute dtype of the convolutions (default: the config's, auto: bfloat16 "
                                         "on CPUs that compute it natively, else float32); a resumed run keeps its "
                                         "own", choices=precision_setting.SETTINGS)
    encoder_backbone: str | None = option(None, "the encoder's body: none (its own convolutions, trained from "
                                                "scratch) or efficientnet-lite0 (pretrained on ImageNet, frozen; "
                                                "docs/aae.md) (default: the config's, none)", choices=BACKBONES)
    seed: int = option(0, "seed of the model initialisation and of the data stream")
    mesh_scale: float | None = option(None, "mesh units to metres (default: 1 with --mesh, --dataset-mesh or a "
                                            "YCB-Video model; 0.001 for BOP models, which are millimetres)")
    workers: int = option(2, "rendering processes (0: render in this process)")
    platform: str | None = option(None, "OpenGL platform of the renderers (default: auto)", choices=PLATFORMS)
    progress: bool = option(True, "progress bars")

    def __post_init__(self):
        dataset_format, scale = checked_pose_source(self.dataset, self.format, self.dataset_mesh, self.mesh_scale,
                                                    self.object_id, self.object_class, self.split)
        object.__setattr__(self, "format", dataset_format)
        scale = checked_mesh_scale(self.mesh, self.dataset, scale, self.seed, self.workers, self.object_id, None)
        object.__setattr__(self, "mesh_scale", scale)
        if self.config not in CONFIGS:
            raise ValueError(f"config: expected one of {sorted(CONFIGS)}, got {self.config!r}")
        if self.steps is not None and self.steps <= 0:
            raise ValueError(f"steps: expected a positive number of steps, got {self.steps}")
        if not 0.0 <= self.pair_fraction <= 1.0:
            raise ValueError(f"pair_fraction: expected a fraction in [0, 1], got {self.pair_fraction}")
        check_crop_box(self.crop_box, self.format)

    @property
    def model_config(self) -> AAEConfig:
        """The preset :attr:`config` with :attr:`steps`, :attr:`precision` and :attr:`encoder_backbone` applied."""
        preset = CONFIGS[self.config]
        if self.precision is not None:
            preset = replace(preset, precision=self.precision)
        if self.encoder_backbone is not None:
            preset = replace(preset, encoder_backbone=self.encoder_backbone)
        return preset if self.steps is None else replace(preset, steps=self.steps)
