"""Settings of ``paz6d train segmentation``: the quick and full configs and one run's
:class:`SegmentationTraining` (whose fields are the command's flags). Light: no numpy, no TensorFlow."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from paz6d.cli_options import option
from paz6d.training.presets import apply_positive_integers, preset_settings

CONFIGS: dict[str, dict] = {
    # CPU budget: about 12 minutes (reading the data set + training) on 2 shared CPU cores (docs/segmentation.md).
    "quick": {"input_size": 64, "widths": (16, 32, 64), "margin": 1.25, "jitter": 0.1, "batch_size": 32,
              "steps": 1500, "learning_rate": 3e-3, "checkpoint_every": 250, "sample_every": 250},
    # Mask R-CNN's mask branch works at 28x28 on 14x14 RoI features; without a backbone to share, a wider
    # U-Net on 128x128 crops, for a GPU.
    "full": {"input_size": 128, "widths": (32, 64, 128, 256), "margin": 1.25, "jitter": 0.1, "batch_size": 64,
             "steps": 30000, "learning_rate": 1e-3, "checkpoint_every": 2000, "sample_every": 2000},
}
#: Keys of a run's settings that must not change when it is resumed.
FIXED_SETTINGS = ("input_size", "widths", "margin")


@dataclass
class SegmentationTraining:
    """One ``paz6d train segmentation`` run (each field but ``overrides`` is a flag, see :mod:`paz6d.cli_options`)."""

    dataset: Path = option(help="a `paz6d generate` output (BOP layout with mask_visib/ and scene_gt_info.json)")
    out: Path = option(help="run directory (re-run the command to resume)")
    split: str = option("train", "split of the data set to train on")
    config: str = option("quick", "network and schedule", choices=tuple(sorted(CONFIGS)))
    seed: int = option(0, "seed of the initialisation and of every batch")
    steps: int | None = option(None, "training steps (default: the config's)")
    batch_size: int | None = option(None, "crops per step (default: the config's)")
    progress: bool = option(True, "progress bar")
    overrides: dict = field(default_factory=dict)  # settings replacing the config's (e.g. a tiny network in tests)

    def __post_init__(self):
        self.dataset, self.out = Path(self.dataset), Path(self.out)
        self.settings()

    def settings(self) -> dict:
        """The config's settings with ``overrides``, ``steps`` and ``batch_size`` applied (checked)."""
        settings = apply_positive_integers(preset_settings(CONFIGS, self.config, self.overrides, known="known:"),
                                           {"steps": self.steps, "batch_size": self.batch_size})
        settings["widths"] = tuple(int(width) for width in settings["widths"])
        if settings["input_size"] % 2 ** len(settings["widths"]):
            raise ValueError(f"input_size: expected a multiple of {2 ** len(settings['widths'])} "
                             f"(2 ^ number of widths), got {settings['input_size']}")
        return settings
