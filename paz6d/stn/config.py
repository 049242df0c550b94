"""Settings of ``paz6d train stn``: the data, network and schedule (:class:`STNConfig`, presets
:data:`QUICK` and :data:`FULL`) and one run's :class:`STNTraining` (whose fields are the command's flags).
Light: no numpy, no TensorFlow."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from paz6d.cli_options import option
from paz6d.training.settings import Settings, positive, run_settings, setting

#: How the transformer samples outside the canvas: zeros, or the nearest border pixel.
PADDINGS = ("zeros", "border")


@dataclass(frozen=True)
class STNConfig(Settings):
    """Data, network and schedule of a spatial-transformer run.

    Attributes:
        canvas_size: side of the cluttered canvases in pixels.
        crop_size: side of the transformer's output, what the classifier sees (pixels).
        scale: range of the digit's side on the canvas (pixels).
        clutter: digit fragments scattered over each canvas.
        fragment_size: side of each fragment (pixels).
        filters: channels of the classifier's convolutions.
        padding: how the transformer samples outside the canvas.
        theta_scale: scale of the localisation network's affine output.
        batch_size / steps / learning_rate: the schedule (cosine decay).
        test_samples: held-out canvases scored at the end.
        checkpoint_every / sample_every: Trainer intervals in steps (sample_every 0: no samples).
    """

    canvas_size: int = setting(48, minimum=16)
    crop_size: int = setting(24, minimum=16)
    scale: tuple[float, float] = setting((12.0, 24.0), positive=True, ordered=True)
    clutter: int = setting(6, minimum=0)
    fragment_size: int = positive(6)
    filters: int = positive(32)
    padding: str = setting("zeros", choices=PADDINGS)
    theta_scale: float = positive(1.0)
    batch_size: int = positive(64)
    steps: int = positive(2000)
    learning_rate: float = positive(1e-3)
    test_samples: int = positive(2000)
    checkpoint_every: int = positive(500)
    sample_every: int = setting(500, minimum=0)


#: A few minutes per run on 2 CPU cores (docs/stn.md): 48x48 canvases, 6 clutter fragments; the transformer's
#: output (what the classifier sees) is 24x24, so zooming in on the digit pays.
QUICK = STNConfig()
#: Jaderberg et al.'s cluttered-MNIST size (60x60, 8 fragments), longer schedule.
FULL = STNConfig(canvas_size=60, crop_size=30, scale=(12.0, 32.0), clutter=8, batch_size=128, steps=20000,
                 test_samples=5000, checkpoint_every=2000, sample_every=2000)
CONFIGS = {"quick": QUICK, "full": FULL}
#: Settings that must not change when a run is resumed.
FIXED_SETTINGS = ("canvas_size", "crop_size", "scale", "clutter", "fragment_size", "filters", "padding",
                  "theta_scale")


@dataclass
class STNTraining:
    """One ``paz6d train stn`` run (each field but ``settings`` is a flag, see :mod:`paz6d.cli_options`)."""

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
    settings: STNConfig | None = field(default=None)  # replaces the config's preset (e.g. a tiny run in tests)

    def __post_init__(self):
        self.out = Path(self.out)
        self.model_config  # checks the preset and the flags

    @property
    def model_config(self) -> STNConfig:
        """``settings`` (default: the preset ``config``) with ``steps``, ``batch_size`` and ``crop_size`` applied."""
        return run_settings(CONFIGS, self.config, self.settings, steps=self.steps, batch_size=self.batch_size,
                            crop_size=self.crop_size)
