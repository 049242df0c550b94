"""Settings of ``paz6d train probabilistic-keypoints``: the network, data and schedule
(:class:`ProbabilisticConfig`, presets :data:`QUICK` and :data:`FULL`) and one run's
:class:`ProbabilisticTraining` (whose fields are the command's flags). Light: no TensorFlow."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from paz6d.cli_options import option
from paz6d.keypointnet.config import KeypointNetwork
from paz6d.training.settings import positive, setting, share
from paz6d.training.source import MeshTraining

#: Where the 3D keypoints PnP uses come from: ``"triangulate"`` (lifted from the network's keypoints on
#: held-out crops, as KeypointNet does) or ``"targets"`` (the farthest-point keypoints it was trained on).
LIFTINGS = ("triangulate", "targets")


@dataclass(frozen=True)
class ProbabilisticConfig(KeypointNetwork):
    """Network (KeypointNet's, :class:`~paz6d.keypointnet.config.KeypointNetwork`, with a Gaussian head),
    data and schedule of a probabilistic-keypoints run.

    Attributes:
        train_occlusion: share of training crops with polygon occluders (1 to 2).
        test_occluders: most occluders per occluded test crop.
        occluder_size: occluder size range, fractions of the object's side.
        views / validation_views: rendered training and validation views.
        test_images / lift_images: held-out whole images scored, and cut for the lifting.
        lifting: one of :data:`LIFTINGS`.
        steps / pairs / learning_rate: the schedule (cosine decay); ``pairs`` views per step, twice jittered.
        nll_weight: weight of the Gaussian negative log-likelihood.
        checkpoint_every / sample_every: Trainer intervals in steps (sample_every 0: no samples).
    """

    train_occlusion: float = share(0.5)
    test_occluders: int = positive(3)
    occluder_size: tuple[float, float] = setting((0.3, 0.7), positive=True, ordered=True)
    views: int = positive(2000)
    validation_views: int = positive(200)
    test_images: int = positive(200)
    lift_images: int = positive(200)
    lifting: str = setting("triangulate", choices=LIFTINGS)
    steps: int = positive(2500)
    pairs: int = positive(8)
    learning_rate: float = positive(5e-3)
    nll_weight: float = setting(0.1, minimum=0.0)
    checkpoint_every: int = positive(500)
    sample_every: int = setting(500, minimum=0)


#: About 15 minutes on 2 CPU cores (docs/probabilistic_keypoints.md): KeypointNet's quick network, fewer views
#: and steps.
QUICK = ProbabilisticConfig(context_stride=8)
#: KeypointNet's quick schedule (5,000 steps, 4,000 views) with the Gaussian head.
FULL = QUICK.replace(views=4000, validation_views=300, test_images=400, lift_images=300, steps=5000)
CONFIGS = {"quick": QUICK, "full": FULL}
#: Settings that must not change when a run is resumed.
FIXED_SETTINGS = ("num_keypoints", "input_size", "filters", "downsample", "context_stride", "dilations", "views")
#: RANSAC inlier threshold of both PnP variants, crop pixels (as KeypointPose6D).
RANSAC_THRESHOLD = 5.0
#: Knee of the Huber loss of the weighted refinement, standard deviations.
ROBUST_SCALE = 3.0


@dataclass
class ProbabilisticTraining(MeshTraining):
    """One ``paz6d train probabilistic-keypoints`` run (:class:`~paz6d.training.source.MeshTraining`)."""

    CONFIGS: ClassVar[dict[str, ProbabilisticConfig]] = CONFIGS

    config: str = option("quick", "network and schedule size", choices=tuple(sorted(CONFIGS)))
    settings: ProbabilisticConfig | None = field(default=None)  # replaces the config's preset (e.g. a tiny network)
