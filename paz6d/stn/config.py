"""Settings of ``paz6d train stn``: the quick and full configs and one run's :class:`STNTraining`
(whose fields are the command's flags). Light: no numpy, no TensorFlow."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from paz6d.cli_options import option
from paz6d.training.presets import apply_positive_integers, preset_settings

CONFIGS: dict[str, dict] = {
    # A few minutes per run on 2 CPU cores (docs/stn.md): 48x48 canvases, 6 clutter fragments; the
    # transformer's output (what the classifier sees) is 24x24, so zooming in on the digit pays.
    "quick": {"canvas_size": 48, "crop_size": 24, "scale": (12.0, 24.0), "clutter": 6, "fragment_size": 6,
              "filters": 32, "padding": "zeros", "theta_scale": 1.0, "batch_size": 64, "steps": 2000,
              "learning_rate": 1e-3, "test_samples": 2000, "checkpoint_every": 500, "sample_every": 500},
    # Jaderberg et al.'s cluttered-MNIST size (60x60, 8 fragments), longer schedule.
    "full": {"canvas_size": 60, "crop_size": 30, "scale": (12.0, 32.0), "clutter": 8, "fragment_size": 6,
             "filters": 32, "padding": "zeros", "theta_scale": 1.0, "batch_size": 128, "steps": 20000,
             "learning_rate": 1e-3, "test_samples": 5000, "checkpoint_every": 2000, "sample_every": 2000},
}
#: Settings that must not change when a run is resumed.
FIXED_SETTINGS = ("canvas_size", "crop_size", "scale", "clutter", "fragment_size", "filters", "padding",
                  "theta_scale")


@dataclass
class STNTraining:
    """One ``paz6d train stn`` run (each field but ``overrides`` is a flag, see :mod:`paz6d.cli_options`)."""

    out: Path = option(help="run directory (re-run the command to resume)")
    config: str = option("quick", "network and schedule", choices=tuple(sorted(CONFIGS)))
    transformer: bool = option(True, "put the spatial transformer in front of the classifier "
                                     "(--no-transformer: the same classifier alone, for comparison)")
    seed: int = option(0, "seed of the initialisation and of every canvas")
    steps: int | None = option(None, "training steps (default: the config's)")
    batch_size: int | None = option(None, "canvases per step (default: the config's)")
    crop_size: int | None = option(None, "side in pixels of the transformer's output, what the classifier sees "
                                         "(default: the config's)")
    progress: bool = option(True, "progress bar")
    overrides: dict = field(default_factory=dict)  # settings replacing the config's (e.g. a tiny run in tests)

    def __post_init__(self):
        self.out = Path(self.out)
        self.settings()

    def settings(self) -> dict:
        """The config's settings with ``overrides``, ``steps``, ``batch_size`` and ``crop_size`` applied."""
        settings = apply_positive_integers(preset_settings(CONFIGS, self.config, self.overrides),
                                           {"steps": self.steps, "batch_size": self.batch_size})
        if self.crop_size is not None:
            if int(self.crop_size) < 16:
                raise ValueError(f"crop_size: expected at least 16 pixels, got {self.crop_size}")
            settings["crop_size"] = int(self.crop_size)
        return settings
