"""Settings of ``paz6d train hrnet``: the quick and full configs and one run's :class:`HRNetTraining`
(whose fields are the command's flags). Light: no numpy, no TensorFlow."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from paz6d.cli_options import option
from paz6d.training.presets import apply_steps, preset_settings
from paz6d.training.source import checked_mesh_scale

CONFIGS: dict[str, dict] = {
    # CPU budget: rendering + training + evaluation within 20 minutes on 2 shared CPU cores (docs/hrnet.md).
    # Three branches (strides 4, 8, 16), one fusion module in stage 2 and two in stage 3.
    "quick": {"num_keypoints": 16, "input_size": 128, "stem_width": 32, "stem_blocks": 1, "widths": (24, 48, 96),
              "stage_modules": (1, 2), "blocks": 1, "precision": "auto", "loss": "softmax", "sigma": 1.0,
              "views": 3000, "validation_views": 64, "test_images": 300, "batch_size": 16, "steps": 2500,
              "learning_rate": 3e-3, "ema_momentum": 0.998, "checkpoint_every": 500, "sample_every": 500},
    # Close to HRNet-W32 (Sun et al. 2019): four branches 32/64/128/256 at strides 4..32, 1/4/3 modules in
    # stages 2/3/4, four residual blocks per branch and module, 256×256 crops, 64×64 heatmaps, MSE to
    # Gaussians of sigma 2 heatmap cells as in the paper. For a GPU (or days of CPU).
    "full": {"num_keypoints": 16, "input_size": 256, "stem_width": 64, "stem_blocks": 4, "widths": (32, 64, 128, 256),
             "stage_modules": (1, 4, 3), "blocks": 4, "precision": "float32", "loss": "mse", "sigma": 2.0,
             "views": 20000, "validation_views": 200, "test_images": 1000, "batch_size": 32, "steps": 100000,
             "learning_rate": 1e-3, "ema_momentum": 0.999, "checkpoint_every": 5000, "sample_every": 5000},
}
#: Heatmap losses: ``"softmax"`` — cross-entropy between the spatial softmax of each map and a normalised
#: Gaussian (maps are logits); ``"mse"`` — HRNet's mean squared error to a Gaussian of peak 1 (maps are values).
LOSSES = ("softmax", "mse")
#: Keys of a run's settings that must not change when it is resumed.
FIXED_SETTINGS = ("num_keypoints", "input_size", "stem_width", "stem_blocks", "widths", "stage_modules", "blocks",
                  "loss", "sigma")
#: Crop side = ``MARGIN`` × the longer side of the object's box (as KeypointNet).
MARGIN = 1.25
#: Heatmaps have 1/``STRIDE`` of the crop's resolution (HRNet's highest-resolution branch).
STRIDE = 4


@dataclass
class HRNetTraining:
    """One ``paz6d train hrnet`` run (each field but ``overrides`` is a flag, see :mod:`paz6d.cli_options`;
    ``config.json`` in the run directory records it)."""

    out: Path = option(help="run directory (re-run the command to resume)")
    mesh: Path = option(help="object mesh (PLY/OBJ/GLB); training crops are rendered from it")
    mesh_scale: float = option(1.0, "mesh file units to metres (BOP meshes are millimetres: 0.001)")
    config: str = option("quick", "network and schedule size", choices=tuple(sorted(CONFIGS)))
    seed: int = option(0, "seed of every random choice (held-out renders use other seeds)")
    workers: int = option(2, "rendering worker processes (0: render in this process)")
    steps: int | None = option(None, "training steps (default: the config's)")
    progress: bool = option(True, "progress bars")
    overrides: dict = field(default_factory=dict)  # settings replacing the config's (e.g. a tiny network in tests)

    def __post_init__(self):
        self.out, self.mesh = Path(self.out), Path(self.mesh)
        self.mesh_scale = checked_mesh_scale(self.mesh, None, self.mesh_scale, self.seed, self.workers, None, None)
        self.settings()

    def settings(self) -> dict:
        """The config's settings with ``overrides`` and ``steps`` applied (checked)."""
        settings = apply_steps(preset_settings(CONFIGS, self.config, self.overrides, known="known:"), self.steps)
        if settings["loss"] not in LOSSES:
            raise ValueError(f"loss: expected one of {LOSSES}, got {settings['loss']!r}")
        if settings["batch_size"] < 2 or settings["batch_size"] % 2:
            raise ValueError(f"batch_size: expected an even number >= 2, got {settings['batch_size']}")
        if settings["input_size"] % (STRIDE * 2 ** (len(settings["widths"]) - 1)):
            raise ValueError(f"input_size: expected a multiple of {STRIDE * 2 ** (len(settings['widths']) - 1)} "
                             f"(the coarsest branch's stride), got {settings['input_size']}")
        return settings
