"""Settings of ``paz6d train segmentation``: the network, crops and schedule (:class:`SegmentationConfig`,
presets :data:`QUICK` and :data:`FULL`) and one run's :class:`SegmentationTraining` (whose fields are the
command's flags). Light: no numpy, no TensorFlow."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from paz6d.cli_options import option
from paz6d.training.settings import Settings, positive, run_settings, setting


@dataclass(frozen=True)
class SegmentationConfig(Settings):
    """Network, crops and schedule of a mask-head run.

    Attributes:
        input_size: side of the square crops in pixels (a multiple of 2 ^ number of ``widths``).
        widths: channels of the U-Net's levels, finest first.
        margin: crop side / longer side of the instance's box.
        jitter: box shift and scale jitter, as fractions of the box side.
        batch_size / steps / learning_rate: the schedule (cosine decay).
        checkpoint_every / sample_every: Trainer intervals in steps (sample_every 0: no samples).
    """

    input_size: int = positive(64)
    widths: tuple[int, ...] = positive((16, 32, 64))
    margin: float = positive(1.25)
    jitter: float = setting(0.1, minimum=0.0)
    batch_size: int = positive(32)
    steps: int = positive(1500)
    learning_rate: float = positive(3e-3)
    checkpoint_every: int = positive(250)
    sample_every: int = setting(250, minimum=0)

    def check(self):
        if self.input_size % 2 ** len(self.widths):
            raise ValueError(f"input_size: expected a multiple of {2 ** len(self.widths)} (2 ^ number of widths), "
                             f"got {self.input_size}")


#: CPU budget: about 12 minutes (reading the data set + training) on 2 shared CPU cores (docs/segmentation.md).
QUICK = SegmentationConfig()
#: Mask R-CNN's mask branch works at 28x28 on 14x14 RoI features; without a backbone to share, a wider U-Net on
#: 128x128 crops, for a GPU.
FULL = SegmentationConfig(input_size=128, widths=(32, 64, 128, 256), batch_size=64, steps=30000, learning_rate=1e-3,
                          checkpoint_every=2000, sample_every=2000)
CONFIGS = {"quick": QUICK, "full": FULL}
#: Settings that must not change when a run is resumed.
FIXED_SETTINGS = ("input_size", "widths", "margin")


@dataclass
class SegmentationTraining:
    """One ``paz6d train segmentation`` run (each field but ``settings`` is a flag, see :mod:`paz6d.cli_options`)."""

    dataset: Path = option(help="a `paz6d generate` output (BOP layout with mask_visib/ and scene_gt_info.json)")
    out: Path = option(help="run directory (re-run the command to resume)")
    split: str = option("train", "split of the data set to train on")
    config: str = option("quick", "network and schedule", choices=tuple(sorted(CONFIGS)))
    seed: int = option(0, "seed of the initialisation and of every batch")
    steps: int | None = option(None, "training steps (default: the config's)")
    batch_size: int | None = option(None, "crops per step (default: the config's)")
    progress: bool = option(True, "progress bar")
    settings: SegmentationConfig | None = field(default=None)  # replaces the config's preset (e.g. a tiny network)

    def __post_init__(self):
        self.dataset, self.out = Path(self.dataset), Path(self.out)
        self.model_config  # checks the preset and the flags

    @property
    def model_config(self) -> SegmentationConfig:
        """``settings`` (default: the preset ``config``) with ``steps`` and ``batch_size`` applied."""
        return run_settings(CONFIGS, self.config, self.settings, steps=self.steps, batch_size=self.batch_size)
