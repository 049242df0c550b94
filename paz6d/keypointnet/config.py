"""Settings of ``paz6d train keypointnet``: the quick and full configs, loss weights and one run's
:class:`KeypointTraining` (whose fields are the command's flags). Light: no TensorFlow."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from paz6d.cli_options import option
from paz6d.datasets.pose_format import POSE_FORMATS, checked_pose_source
from paz6d.keypointnet.orientation import ChartSymmetry, mesh_symmetry
from paz6d.training.presets import apply_steps, preset_settings
from paz6d.training.source import checked_mesh_scale

CONFIGS: dict[str, dict] = {
    # Demo budget (`paz6d demo --keypoints` under 15 minutes on 2 CPU cores): see docs/keypointnet.md.
    "quick": {"num_keypoints": 16, "input_size": 128, "filters": 48, "downsample": 4, "context_stride": 8,
              "dilations": (1, 2, 4, 1, 2, 4), "precision": "auto", "views": 4000, "validation_views": 100,
              "lift_views": 300, "steps": 5000, "pairs": 8, "learning_rate": 5e-3, "ema_momentum": 0.998,
              "checkpoint_every": 500, "sample_every": 500, "lifting": "triangulate"},
    # Paper-sized network and schedule, for a GPU or a long CPU run.
    "full": {"num_keypoints": 10, "input_size": 128, "filters": 64, "downsample": 2,
             "dilations": (1, 1, 2, 4, 8, 16, 1, 2, 4, 8, 16, 1), "precision": "float32", "views": 20000,
             "validation_views": 200, "lift_views": 1000, "steps": 60000, "pairs": 16, "learning_rate": 1e-3,
             "ema_momentum": 0.999, "checkpoint_every": 2000, "sample_every": 2000, "lifting": "triangulate"},
    # Discovery that converges in the CPU budget (measured in docs/keypointnet.md): the quick network, a
    # curriculum on the pair angle and bootstrapping from the network's own lifted keypoints, 14,000 steps
    # (the step counts compared: docs/experiments/2026-11-23-keypointnet-discovery-mode.md).
    "discovery": {"num_keypoints": 10, "input_size": 128, "filters": 48, "downsample": 4, "context_stride": 8,
                  "dilations": (1, 2, 4, 1, 2, 4), "precision": "auto", "views": 4000, "validation_views": 100,
                  "lift_views": 300, "steps": 14000, "pairs": 8, "learning_rate": 5e-3, "ema_momentum": 0.998,
                  "checkpoint_every": 500, "sample_every": 500, "lifting": "triangulate", "mode": "discovery",
                  "pair_angle": (30.0, 180.0), "pair_angle_ramp": 0.4, "anchor_start": 0.2, "anchor_every": 250,
                  "anchor_views": 256},
}
# The quick network on harder data for twice the steps (~25 minutes on 2 cores): half of the crops over photo
# collages, Gaussian noise on half of the backgrounds, a third of the views lit from any side. It passes the
# demo's out-of-distribution check, which quick fails (docs/keypointnet.md#out-of-distribution-check).
CONFIGS["robust"] = {**CONFIGS["quick"], "steps": 10000, "lighting": ("key-fill", "key-fill", "surround"),
                     "augmentation": {"photos": 0.5, "background_noise": 40.0}}

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


MODES = ("discovery", "supervised")
LIFTINGS = ("triangulate", "median")
#: A lifted keypoint is usable when its median re-projection error over the lifting views is below
#: this fraction of the crop side.
MAX_LIFTING_ERROR = 0.1
#: Discovery loss weights (coordinates normalised to [-1, 1] as in the paper, 3D in object diameters).
#: The separation hinge keeps keypoints ``separation_delta`` object diameters apart; with a weaker
#: hinge (0.1 diameter, weight 1) every keypoint collapsed onto the object centre, which satisfies
#: the consistency loss trivially.
#: The network also escaped a 3D-only hinge by spreading keypoints along the viewing ray (depth) while
#: their 2D positions stayed together, so the same hinge is applied to the 2D keypoints as well
#: (``separation_image``, coordinates in [-1, 1]).
DISCOVERY_WEIGHTS = {"consistency": 1.0, "pose": 0.2, "separation": 5.0, "separation_image": 5.0,
                     "silhouette": 1.0, "variance": 0.1}
SEPARATION_DELTA = 0.25  # object diameters
SEPARATION_DELTA_IMAGE = 0.25  # [-1, 1] image units: 1/8 of the crop side
#: Supervised loss weights (heatmap cross-entropy, coordinates in [-1, 1] units, depth code).
SUPERVISED_WEIGHTS = {"heatmap": 1.0, "coordinates": 2.0, "depth": 1.0}
#: With ``--orientation-network``: weight of the chart cross-entropy, and how often a training view is
#: fed another safe chart than its own (see :mod:`paz6d.keypointnet.orientation`).
ORIENTATION_WEIGHT = 1.0
OTHER_CHART_PROBABILITY = 0.25


@dataclass
class KeypointTraining:
    """One ``paz6d train keypointnet`` run (each field but ``overrides`` is a flag, see
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
    progress: bool = option(True, "progress bars")
    overrides: dict = field(default_factory=dict)  # settings replacing the config's (e.g. a tiny network in tests)

    def __post_init__(self):
        self.format, scale = checked_pose_source(self.dataset, self.format, self.dataset_mesh, self.mesh_scale,
                                                 self.object_id, self.object_class, self.split)
        self.mesh_scale = checked_mesh_scale(self.mesh, self.dataset, scale, self.seed, self.workers, self.object_id,
                                             None)
        self.settings()  # checks config, mode and steps
        if self.orientation_network and self.mesh is not None:
            self.symmetry()  # checks the mesh's models_info.json before anything is rendered

    def symmetry(self):
        """With ``orientation_network``: the mesh's half-turn symmetry as an
        :class:`~paz6d.keypointnet.orientation.ChartSymmetry` (``None`` without)."""
        if not self.orientation_network:
            return None
        return ChartSymmetry(mesh_symmetry(self.mesh, self.mesh_scale))

    def settings(self) -> dict:
        """The config's settings with ``overrides`` and ``steps`` applied."""
        settings = preset_settings(CONFIGS, self.config, self.overrides, check_overrides=False)
        if self.mode not in MODES:
            raise ValueError(f"mode: expected one of {MODES}, got {self.mode!r}")
        if settings.get("mode", self.mode) != self.mode:
            raise ValueError(f"config: {self.config!r} is a {settings['mode']} preset; pass --mode {settings['mode']} "
                             f"(got --mode {self.mode})")
        from paz6d.keypointnet.views import Augmentation  # no TensorFlow

        Augmentation.from_settings(settings.get("augmentation"))  # a bad key or strength fails before rendering
        return apply_steps(settings, self.steps)


def pair_angle_at(step: int, settings: dict) -> float | None:
    """Curriculum of discovery pairs: the largest rotation (degrees) between the two views of a pair at
    ``step``, going linearly from ``pair_angle[0]`` to ``pair_angle[1]`` over the first
    ``pair_angle_ramp`` × ``steps`` steps; ``None`` (any two views) without a ``pair_angle`` setting."""
    if settings.get("pair_angle") is None:
        return None
    start, end = (float(angle) for angle in settings["pair_angle"])
    ramp = float(settings.get("pair_angle_ramp", 0.0)) * int(settings["steps"])
    fraction = 1.0 if ramp <= 0 else min(1.0, step / ramp)
    return start + (end - start) * fraction


def anchor_start_step(settings: dict) -> int | None:
    """First step of bootstrapping (``anchor_start`` × ``steps``), or ``None`` without ``anchor_start``."""
    if settings.get("anchor_start") is None:
        return None
    return int(round(float(settings["anchor_start"]) * int(settings["steps"])))


def anchors_due(step: int, lifted_at: int | None, settings: dict) -> bool:
    """Whether the bootstrap anchors (the network's keypoints lifted to 3D) are to be (re-)lifted before
    ``step``: from :func:`anchor_start_step` on, when never lifted or lifted ``anchor_every`` or more
    steps earlier."""
    start = anchor_start_step(settings)
    if start is None or step < start:
        return False
    return lifted_at is None or step - lifted_at >= int(settings.get("anchor_every", 250))


