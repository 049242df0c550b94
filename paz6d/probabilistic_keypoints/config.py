"""Settings of ``paz6d train probabilistic-keypoints``: the quick and full configs and one run's
:class:`ProbabilisticTraining` (whose fields are the command's flags). Light: no numpy, no TensorFlow."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from paz6d.cli_options import option
from paz6d.training.presets import apply_steps, preset_settings
from paz6d.training.source import checked_mesh_scale

_NETWORK = {"num_keypoints": 16, "input_size": 128, "filters": 48, "downsample": 4, "context_stride": 8,
            "dilations": (1, 2, 4, 1, 2, 4), "precision": "auto"}
_OCCLUSION = {"train_occlusion": 0.5, "test_occluders": 3, "occluder_size": (0.3, 0.7)}
CONFIGS: dict[str, dict] = {
    # About 15 minutes on 2 CPU cores (docs/probabilistic_keypoints.md): KeypointNet's quick network,
    # fewer views and steps.
    "quick": {**_NETWORK, **_OCCLUSION, "views": 2000, "validation_views": 200, "test_images": 200, "lift_images": 200,
              "lifting": "triangulate", "steps": 2500,
              "pairs": 8, "learning_rate": 5e-3, "nll_weight": 0.1, "checkpoint_every": 500, "sample_every": 500},
    # KeypointNet's quick schedule (5,000 steps, 4,000 views) with the Gaussian head.
    "full": {**_NETWORK, **_OCCLUSION, "views": 4000, "validation_views": 300, "test_images": 400, "lift_images": 300,
             "lifting": "triangulate", "steps": 5000,
             "pairs": 8, "learning_rate": 5e-3, "nll_weight": 0.1, "checkpoint_every": 500, "sample_every": 500},
}
#: Settings that must not change when a run is resumed.
FIXED_SETTINGS = ("num_keypoints", "input_size", "filters", "downsample", "context_stride", "dilations", "views")
#: Supervised KeypointNet loss weights (heatmap cross-entropy, coordinates in [-1, 1] units, depth code).
SUPERVISED_WEIGHTS = {"heatmap": 1.0, "coordinates": 2.0, "depth": 1.0}
#: RANSAC inlier threshold of both PnP variants, crop pixels (as KeypointPose6D).
RANSAC_THRESHOLD = 5.0
#: Knee of the Huber loss of the weighted refinement, standard deviations.
ROBUST_SCALE = 3.0


@dataclass
class ProbabilisticTraining:
    """One ``paz6d train probabilistic-keypoints`` run (each field but ``overrides`` is a flag)."""

    mesh: Path = option(help="object mesh (PLY/OBJ/GLB); views are rendered on the fly")
    out: Path = option(help="run directory (re-run the command to resume)")
    mesh_scale: float = option(1.0, "mesh file units to metres (0.001 for BOP millimetre meshes)")
    config: str = option("quick", "model and schedule size", choices=tuple(sorted(CONFIGS)))
    seed: int = option(0, "seed of every random choice")
    workers: int = option(2, "rendering worker processes (0: render in this process)")
    steps: int | None = option(None, "training steps (default: the config's)")
    progress: bool = option(True, "progress bars")
    overrides: dict = field(default_factory=dict)  # settings replacing the config's (e.g. a tiny network in tests)

    def __post_init__(self):
        self.mesh, self.out = Path(self.mesh), Path(self.out)
        self.mesh_scale = checked_mesh_scale(self.mesh, None, self.mesh_scale, self.seed, self.workers, None, None)
        self.settings()

    def settings(self) -> dict:
        """The config's settings with ``overrides`` and ``steps`` applied."""
        return apply_steps(preset_settings(CONFIGS, self.config, self.overrides), self.steps)
