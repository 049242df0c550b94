"""Settings of ``paz6d train hrnet``: the network, data and schedule (:class:`HRNetConfig`, presets
:data:`QUICK` and :data:`FULL`) and one run's :class:`HRNetTraining` (whose fields are the command's flags).
Light: no numpy, no TensorFlow."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from paz6d.cli_options import option
from paz6d.training import precision
from paz6d.training.settings import Settings, positive, setting, share
from paz6d.training.source import MeshTraining

#: Heatmap losses: ``"softmax"`` — cross-entropy between the spatial softmax of each map and a normalised
#: Gaussian (maps are logits); ``"mse"`` — HRNet's mean squared error to a Gaussian of peak 1 (maps are values).
LOSSES = ("softmax", "mse")
#: Crop side = ``MARGIN`` × the longer side of the object's box (as KeypointNet).
MARGIN = 1.25
#: Heatmaps have 1/``STRIDE`` of the crop's resolution (HRNet's highest-resolution branch).
STRIDE = 4


@dataclass(frozen=True)
class HRNetConfig(Settings):
    """Network, data and schedule of an HRNet run.

    Attributes:
        num_keypoints: keypoints (farthest-point samples of the mesh surface).
        input_size: side of the square crops in pixels (a multiple of the coarsest branch's stride).
        stem_width / stem_blocks: channels and residual blocks of the stem.
        widths: channels of the branches, finest (stride :data:`STRIDE`) first; each next one halves the
            resolution.
        stage_modules: fusion modules of stages 2, 3, ... (one stage per branch after the first).
        blocks: residual blocks per branch and module.
        precision: compute dtype (:mod:`paz6d.training.precision`).
        loss: heatmap loss, one of :data:`LOSSES`.
        sigma: target Gaussians' standard deviation in heatmap cells.
        views / validation_views / test_images: rendered training and validation views, held-out images.
        batch_size: crops per step (even: each step draws half as many views, twice jittered).
        steps / learning_rate / ema_momentum: the schedule (cosine decay; ``None``: no weight averaging).
        checkpoint_every / sample_every: Trainer intervals in steps (sample_every 0: no samples).
    """

    num_keypoints: int = positive(16)
    input_size: int = positive(128)
    stem_width: int = positive(32)
    stem_blocks: int = setting(1, minimum=0)
    widths: tuple[int, ...] = positive((24, 48, 96))
    stage_modules: tuple[int, ...] = positive((1, 2))
    blocks: int = positive(1)
    precision: str = setting("auto", choices=precision.SETTINGS)
    loss: str = setting("softmax", choices=LOSSES)
    sigma: float = positive(1.0)
    views: int = positive(3000)
    validation_views: int = positive(64)
    test_images: int = positive(300)
    batch_size: int = setting(16, minimum=2)
    steps: int = positive(2500)
    learning_rate: float = positive(3e-3)
    ema_momentum: float | None = share(0.998)
    checkpoint_every: int = positive(500)
    sample_every: int = setting(500, minimum=0)

    def check(self):
        if self.batch_size % 2:
            raise ValueError(f"batch_size: expected an even number >= 2, got {self.batch_size}")
        coarsest = STRIDE * 2 ** (len(self.widths) - 1)
        if self.input_size % coarsest:
            raise ValueError(f"input_size: expected a multiple of {coarsest} (the coarsest branch's stride), got "
                             f"{self.input_size}")


#: CPU budget: rendering + training + evaluation within 20 minutes on 2 shared CPU cores (docs/hrnet.md).
#: Three branches (strides 4, 8, 16), one fusion module in stage 2 and two in stage 3.
QUICK = HRNetConfig()
#: Close to HRNet-W32 (Sun et al. 2019): four branches 32/64/128/256 at strides 4..32, 1/4/3 modules in stages
#: 2/3/4, four residual blocks per branch and module, 256×256 crops, 64×64 heatmaps, MSE to Gaussians of sigma 2
#: heatmap cells as in the paper. For a GPU (or days of CPU).
FULL = HRNetConfig(input_size=256, stem_width=64, stem_blocks=4, widths=(32, 64, 128, 256), stage_modules=(1, 4, 3),
                   blocks=4, precision="float32", loss="mse", sigma=2.0, views=20000, validation_views=200,
                   test_images=1000, batch_size=32, steps=100000, learning_rate=1e-3, ema_momentum=0.999,
                   checkpoint_every=5000, sample_every=5000)
CONFIGS = {"quick": QUICK, "full": FULL}
#: Settings that must not change when a run is resumed.
FIXED_SETTINGS = ("num_keypoints", "input_size", "stem_width", "stem_blocks", "widths", "stage_modules", "blocks",
                  "loss", "sigma")


@dataclass
class HRNetTraining(MeshTraining):
    """One ``paz6d train hrnet`` run (:class:`~paz6d.training.source.MeshTraining`; ``config.json`` in the run
    directory records it)."""

    CONFIGS: ClassVar[dict[str, HRNetConfig]] = CONFIGS

    config: str = option("quick", "network and schedule size", choices=tuple(sorted(CONFIGS)))
    settings: HRNetConfig | None = field(default=None)  # replaces the config's preset (e.g. a tiny network in tests)
