"""Settings of ``paz6d train keypointnet``: the network (:class:`KeypointNetwork`, shared with probabilistic
keypoints), data, losses and schedule (:class:`KeypointConfig`, presets :data:`QUICK`, :data:`FULL`,
:data:`DISCOVERY` and :data:`ROBUST`), loss weights and one run's :class:`KeypointTraining` (whose fields are
the command's flags). Light: no TensorFlow."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from paz6d.backbones import BACKBONES
from paz6d.cli_options import option
from paz6d.datasets.pose_format import POSE_FORMATS, checked_pose_source
from paz6d.keypointnet.orientation import ChartSymmetry, mesh_symmetry
from paz6d.synthesis.lighting import LIGHTING_STYLES
from paz6d.training import precision
from paz6d.training.settings import Settings, positive, run_settings, setting, share
from paz6d.training.source import checked_mesh_scale

MODES = ("discovery", "supervised")
LIFTINGS = ("triangulate", "median")
#: How the bootstrap anchors are lifted to 3D (:meth:`paz6d.keypointnet.train.AnchorSource.lift`).
ANCHOR_LIFTINGS = ("modes", "triangulate")

#: Strides of KeypointNet's probability maps and dilated stack (:func:`paz6d.keypointnet.model.build_keypointnet`).
STRIDES = (1, 2, 4, 8)


@dataclass(frozen=True)
class KeypointNetwork(Settings):
    """KeypointNet's network (:func:`paz6d.keypointnet.model.build_keypointnet`), shared by the settings of
    ``paz6d train keypointnet`` and ``paz6d train probabilistic-keypoints``.

    Attributes:
        num_keypoints: keypoints the network predicts.
        input_size: side of the square crops in pixels.
        filters: channels of the convolutions.
        downsample: stride of the probability maps (one of :data:`STRIDES`).
        context_stride: stride at which the dilated stack runs (``None``: ``downsample``).
        dilations: dilation rate of each convolution of the dilated stack.
        precision: compute dtype (:mod:`paz6d.training.precision`).
    """

    num_keypoints: int = positive(16)
    input_size: int = positive(128)
    filters: int = positive(48)
    downsample: int = setting(4, choices=STRIDES)
    context_stride: int | None = setting(None, choices=STRIDES)
    dilations: tuple[int, ...] = positive((1, 2, 4, 1, 2, 4))
    precision: str = setting("auto", choices=precision.SETTINGS)

    def check(self):
        context = self.downsample if self.context_stride is None else self.context_stride
        if context < self.downsample:
            raise ValueError(f"context_stride: expected at least downsample ({self.downsample}), got {context}")
        if self.input_size < 8 or self.input_size % context:
            raise ValueError(f"input_size: expected a multiple of {context} (the coarsest stride) and >= 8, got "
                             f"{self.input_size}")



@dataclass(frozen=True)
class Augmentation(Settings):
    """Batch-time augmentation strengths.

    Attributes:
        crop_scale: crop zoom factor drawn from ``[1 - crop_scale, 1 + crop_scale]``.
        crop_shift: crop shift drawn from ``±crop_shift`` × crop side.
        colour: apply brightness/contrast/saturation/hue jitter and noise.
        background: composite over random backgrounds (else black).
        relight: strength of the object's image-space re-lighting before compositing
            (:func:`~paz6d.synthesis.augment.relight`: per-channel gains ``1 ± relight/2`` and a brightness
            ramp); 0: none.
        background_noise: on half of the crops, Gaussian pixel noise of a standard deviation uniform in
            ``[0, background_noise]`` grey levels on the background only; 0: none.
        photos: probability that a crop's background is a collage of scikit-image's sample photographs
            (:func:`~paz6d.synthesis.photo_backgrounds.photo_collage`) instead of the procedural style.
    """

    crop_scale: float = setting(0.08, minimum=0.0)
    crop_shift: float = setting(0.05, minimum=0.0)
    colour: bool = True
    background: bool = True
    relight: float = setting(0.0, minimum=0.0)
    background_noise: float = setting(0.0, minimum=0.0)
    photos: float = share(0.0)


@dataclass(frozen=True)
class DiscoveryWeights(Settings):
    """Weights of the discovery losses (coordinates normalised to [-1, 1] as in the paper, 3D in object
    diameters)."""

    consistency: float = setting(1.0, minimum=0.0)
    pose: float = setting(0.2, minimum=0.0)
    separation: float = setting(5.0, minimum=0.0)
    separation_image: float = setting(5.0, minimum=0.0)
    silhouette: float = setting(1.0, minimum=0.0)
    variance: float = setting(0.1, minimum=0.0)


@dataclass(frozen=True)
class KeypointConfig(KeypointNetwork):
    """Network (:class:`KeypointNetwork`), data, losses and schedule of a KeypointNet run.

    Attributes:
        views / validation_views: rendered training and validation views.
        lift_views: views the 3D keypoints are lifted from (:data:`LIFTINGS` ``lifting``).
        steps / pairs / learning_rate: the schedule (cosine decay); ``pairs`` view pairs per step.
        ema_momentum: weight averaging of the optimiser (``None``: none).
        checkpoint_every / sample_every: Trainer intervals in steps (sample_every 0: no samples).
        mode: the mode the preset is made for (:data:`MODES`; ``None``: either).
        pair_angle / pair_angle_ramp: discovery's curriculum (:func:`pair_angle_at`; ``None``: any two views).
        anchor_start / anchor_every / anchor_views / anchor_lifting / anchor_radius / anchor_weight:
            bootstrapping of discovery from the network's own keypoints lifted to 3D (:func:`anchors_due`;
            ``anchor_start`` ``None``: none).
        separation_delta: the separation hinge keeps keypoints this many object diameters apart; with a
            weaker hinge (0.1 diameter, weight 1) every keypoint collapsed onto the object centre, which
            satisfies the consistency loss trivially.
        separation_delta_image: the same hinge on the 2D keypoints ([-1, 1] image units; 0.25: 1/8 of the
            crop side): the network escaped a 3D-only hinge by spreading keypoints along the viewing ray.
        discovery_weights: weights of the discovery losses.
        lighting: light styles of the training views (:class:`~paz6d.keypointnet.views.ViewSampling`).
        augmentation: batch-time augmentation strengths.
        backbone: the network's stem and strided convolutions: ``"none"`` (its own) or ``"efficientnet-lite0"``
            (frozen, pretrained on ImageNet: ``docs/keypointnet.md``, "Pretrained body"; needs
            ``context_stride`` 8 and ``downsample`` of at least 2).
    """

    views: int = positive(4000)
    validation_views: int = positive(100)
    lift_views: int = positive(300)
    steps: int = positive(5000)
    pairs: int = positive(8)
    learning_rate: float = positive(5e-3)
    ema_momentum: float | None = share(None)
    checkpoint_every: int = positive(500)
    sample_every: int = setting(500, minimum=0)
    lifting: str = setting("triangulate", choices=LIFTINGS)
    mode: str | None = setting(None, choices=MODES)
    pair_angle: tuple[float, float] | None = setting(None, positive=True, maximum=180.0, ordered=True)
    pair_angle_ramp: float = share(0.0)
    anchor_start: float | None = share(None)
    anchor_every: int = positive(250)
    anchor_views: int = positive(256)
    anchor_lifting: str = setting("modes", choices=ANCHOR_LIFTINGS)
    anchor_radius: float = positive(0.1)
    anchor_weight: float = setting(1.0, minimum=0.0)
    separation_delta: float = positive(0.25)
    separation_delta_image: float = positive(0.25)
    discovery_weights: DiscoveryWeights = DiscoveryWeights()
    lighting: tuple[str, ...] = setting(("key-fill",), choices=LIGHTING_STYLES)
    augmentation: Augmentation = Augmentation()
    backbone: str = setting("none", choices=BACKBONES)

    def check(self):
        super().check()
        check_backbone_strides(self.backbone, self.context_stride, self.downsample)


def check_backbone_strides(backbone: str, context_stride: int | None, downsample: int) -> None:
    """A pretrained ``backbone`` (not ``"none"``) gives KeypointNet the maps of strides 2 to 8: ValueError unless
    the dilated stack runs at stride 8 (``context_stride``, ``None``: ``downsample``) and ``downsample`` >= 2."""
    context = downsample if context_stride is None else context_stride
    if backbone != "none" and (context != 8 or downsample < 2):
        raise ValueError(f"backbone: {backbone} gives the maps of strides 2 to 8; expected context_stride 8 and "
                         f"downsample at least 2, got {context} and {downsample}")


#: Demo budget (`paz6d demo --keypoints` under 15 minutes on 2 CPU cores): see docs/keypointnet.md.
QUICK = KeypointConfig(context_stride=8, ema_momentum=0.998)
#: Paper-sized network and schedule, for a GPU or a long CPU run.
FULL = KeypointConfig(num_keypoints=10, filters=64, downsample=2, dilations=(1, 1, 2, 4, 8, 16, 1, 2, 4, 8, 16, 1),
                      precision="float32", views=20000, validation_views=200, lift_views=1000, steps=60000,
                      pairs=16, learning_rate=1e-3, ema_momentum=0.999, checkpoint_every=2000, sample_every=2000)
#: Discovery that converges in the CPU budget (measured in docs/keypointnet.md): the quick network, a
#: curriculum on the pair angle and bootstrapping from the network's own lifted keypoints, 14,000 steps
#: (the step counts compared: docs/experiments/2026-11-23-keypointnet-discovery-mode.md).
DISCOVERY = QUICK.replace(num_keypoints=10, steps=14000, mode="discovery", pair_angle=(30.0, 180.0),
                          pair_angle_ramp=0.4, anchor_start=0.2, anchor_every=250, anchor_views=256)
#: The quick network on harder data for twice the steps (~25 minutes on 2 cores): half of the crops over photo
#: collages, Gaussian noise on half of the backgrounds, a third of the views lit from any side. It passes the
#: demo's out-of-distribution check, which quick fails (docs/keypointnet.md#out-of-distribution-check).
ROBUST = QUICK.replace(steps=10000, lighting=("key-fill", "key-fill", "surround"),
                       augmentation=Augmentation(photos=0.5, background_noise=40.0))
CONFIGS = {"quick": QUICK, "full": FULL, "discovery": DISCOVERY, "robust": ROBUST}

#: Test-time crops ``(shift x, shift y, scale)`` of the box, shifts in box widths/heights: the plain box
#: first, then 6 % shifts along each axis, ±6 % scales, 4 % diagonal shifts and ±12 % scales.
CROP_JITTERS = ((0.0, 0.0, 1.0), (0.06, 0.0, 1.0), (-0.06, 0.0, 1.0), (0.0, 0.06, 1.0), (0.0, -0.06, 1.0),
                (0.0, 0.0, 0.94), (0.0, 0.0, 1.06), (0.04, 0.04, 1.0), (-0.04, 0.04, 1.0), (0.04, -0.04, 1.0),
                (-0.04, -0.04, 1.0), (0.0, 0.0, 0.88), (0.0, 0.0, 1.12))


def check_crops(count: int, name: str = "crops") -> int:
    """``int(count)`` test-time crops per box, when ``count`` is 1 to ``len(CROP_JITTERS)``.

    Raises:
        ValueError: naming ``name`` (the option or flag) and the range.
    """
    if not 1 <= count <= len(CROP_JITTERS):
        raise ValueError(f"{name}: expected 1 to {len(CROP_JITTERS)} test-time crops per box, got {count}")
    return int(count)


#: A lifted keypoint is usable when its median re-projection error over the lifting views is below
#: this fraction of the crop side.
MAX_LIFTING_ERROR = 0.1
#: Supervised loss weights (heatmap cross-entropy, coordinates in [-1, 1] units, depth code).
SUPERVISED_WEIGHTS = {"heatmap": 1.0, "coordinates": 2.0, "depth": 1.0}
#: With ``--orientation-network``: weight of the chart cross-entropy, and how often a training view is
#: fed another safe chart than its own (see :mod:`paz6d.keypointnet.orientation`).
ORIENTATION_WEIGHT = 1.0
OTHER_CHART_PROBABILITY = 0.25


@dataclass
class KeypointTraining:
    """One ``paz6d train keypointnet`` run (each field but ``settings`` is a flag, see
    :mod:`paz6d.cli_options`; ``config.json`` in the run directory records it).

    With ``dataset`` (BOP, YCB-Video or FAT: ``format``, detected from its files by default), :func:`run`
    cuts the views from the data set's images and fills in ``mesh`` (``dataset_mesh``, or the data set's model).
    """

    out: Path = option(help="run directory (re-run the command to resume)")
    mesh: Path | None = option(None, "object mesh (PLY/OBJ/GLB); views are rendered on the fly", one_of="source")
    dataset: Path | None = option(None, "data set folder (BOP, YCB-Video or FAT): views are cut from its images",
                                  one_of="source")
    dataset_mesh: Path | None = option(None, "with --dataset: the object's mesh, replacing the data set's model "
                                             "(FAT ships none: required)")
    format: str | None = option(None, "with --dataset: its format (default: detected from its files)",
                                choices=POSE_FORMATS)
    object_id: int | None = option(None, "with --dataset: BOP object id (default: the first), or YCB-Video class "
                                         "index (1-21, as BOP YCB-V)")
    object_class: str | None = option(None, "with a YCB-Video or FAT --dataset: class name (e.g. 003_cracker_box)")
    split: str | None = option(None, "with --dataset: BOP split folder (default: train_pbr, else train), YCB-Video "
                                     "image set (default: train) or FAT folder (default: mixed)")
    mesh_scale: float | None = option(None, "mesh file units to metres (default: 1 with --mesh, --dataset-mesh or a "
                                            "YCB-Video model; 0.001 for BOP models, which are millimetres)")
    config: str = option("quick", "model and schedule size", choices=tuple(sorted(CONFIGS)))
    mode: str = option("supervised", "discovery (the paper's, unsupervised) or supervised (farthest-point "
                                     "keypoints)", choices=MODES)
    orientation_network: bool = option(False, "the object has a half-turn symmetry (symmetries_discrete in the "
                                              "models_info.json beside a BOP mesh): train the orientation network "
                                              "that picks one of its two equivalent poses (score with ADD-S)")
    seed: int = option(0, "seed of every random choice")
    workers: int = option(2, "rendering worker processes (0: render in this process)")
    steps: int | None = option(None, "training steps (default: the config's)")
    backbone: str | None = option(None, "the network's stem and strided convolutions: efficientnet-lite0 (frozen, "
                                        "pretrained on ImageNet; docs/keypointnet.md) or none (its own; default: "
                                        "the config's)", choices=BACKBONES)
    progress: bool = option(True, "progress bars")
    settings: KeypointConfig | None = field(default=None)  # replaces the config's preset (e.g. a tiny network)

    def __post_init__(self):
        self.format, scale = checked_pose_source(self.dataset, self.format, self.dataset_mesh, self.mesh_scale,
                                                 self.object_id, self.object_class, self.split)
        self.mesh_scale = checked_mesh_scale(self.mesh, self.dataset, scale, self.seed, self.workers, self.object_id,
                                             None)
        self.model_config  # checks config, mode and steps
        if self.orientation_network and self.mesh is not None:
            self.symmetry()  # checks the mesh's models_info.json before anything is rendered

    def symmetry(self):
        """With ``orientation_network``: the mesh's half-turn symmetry as an
        :class:`~paz6d.keypointnet.orientation.ChartSymmetry` (``None`` without)."""
        if not self.orientation_network:
            return None
        return ChartSymmetry(mesh_symmetry(self.mesh, self.mesh_scale))

    @property
    def model_config(self) -> KeypointConfig:
        """``settings`` (default: the preset ``config``) with ``steps`` and ``backbone`` applied, made for
        ``mode``."""
        if self.mode not in MODES:
            raise ValueError(f"mode: expected one of {MODES}, got {self.mode!r}")
        settings = run_settings(CONFIGS, self.config, self.settings, steps=self.steps, backbone=self.backbone)
        if settings.mode not in (None, self.mode):
            raise ValueError(f"config: {self.config!r} is a {settings.mode} preset; pass --mode {settings.mode} "
                             f"(got --mode {self.mode})")
        return settings


def pair_angle_at(step: int, settings: KeypointConfig) -> float | None:
    """Curriculum of discovery pairs: the largest rotation (degrees) between the two views of a pair at
    ``step``, going linearly from ``pair_angle[0]`` to ``pair_angle[1]`` over the first
    ``pair_angle_ramp`` × ``steps`` steps; ``None`` (any two views) without a ``pair_angle``."""
    if settings.pair_angle is None:
        return None
    start, end = settings.pair_angle
    ramp = settings.pair_angle_ramp * settings.steps
    fraction = 1.0 if ramp <= 0 else min(1.0, step / ramp)
    return start + (end - start) * fraction


def anchor_start_step(settings: KeypointConfig) -> int | None:
    """First step of bootstrapping (``anchor_start`` × ``steps``), or ``None`` without ``anchor_start``."""
    if settings.anchor_start is None:
        return None
    return int(round(settings.anchor_start * settings.steps))


def anchors_due(step: int, lifted_at: int | None, settings: KeypointConfig) -> bool:
    """Whether the bootstrap anchors (the network's keypoints lifted to 3D) are to be (re-)lifted before
    ``step``: from :func:`anchor_start_step` on, when never lifted or lifted ``anchor_every`` or more
    steps earlier."""
    start = anchor_start_step(settings)
    if start is None or step < start:
        return False
    return lifted_at is None or step - lifted_at >= settings.anchor_every
