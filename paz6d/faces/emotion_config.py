"""Settings of one ``paz6d train emotion`` run; no heavy imports, so the command line builds fast."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from paz6d.backend.checks import is_whole_number
from paz6d.cli_options import option

#: Largest side of the network's square input (pixels); FER-2013 faces are 48.
MAX_INPUT_SIZE = 512
#: FERPlus label modes (``paz6d.datasets.ferplus.LABEL_MODES``, kept here light).
LABEL_MODES = ("majority", "probability")


@dataclass(frozen=True)
class EmotionTraining:
    """One ``paz6d train emotion`` run (each field is a flag, see :mod:`paz6d.cli_options`)."""

    data: Path = option(help="FER-2013 CSV file (or the folder holding fer2013.csv) or image folder DIR/<class>/*")
    out: Path = option(help="run folder (created; an existing run resumes)")
    ferplus: Path | None = option(None, "FERPlus votes (fer2013new.csv) for the rows of the --data CSV: trains "
                                        "on the 8 FERPlus classes")
    label_mode: str = option("majority", "FERPlus targets: majority (one label; ties, unknown and not-a-face "
                                         "dropped) or probability (vote distributions, soft labels)",
                             choices=LABEL_MODES)
    epochs: int = option(30, "passes over the training set")
    batch_size: int = option(32, "faces per step")
    learning_rate: float = option(1e-3, "Adam learning rate")
    input_size: int = option(48, "square network input side (pixels)")
    val_fraction: float = option(0.1, "held-out fraction when the data has no validation split")
    checkpoint_every: int = option(500, "steps between checkpoints")
    validate_every: int = option(500, "steps between validation confusion matrices (0: only at the end)")
    augment: bool = option(True, "augment the training faces (brightness, contrast, flip, rotation/zoom/shift)")
    seed: int = option(0, "seed of the validation split, the augmentation and the initialisation")
    eager: bool = option(False, "run steps eagerly (no tf.function compile): for debugging and tiny runs")
    progress: bool = option(True, "progress bar")

    def __post_init__(self):
        for name in ("epochs", "batch_size", "input_size", "checkpoint_every"):
            value = getattr(self, name)
            if not is_whole_number(value) or value < 1:
                raise ValueError(f"{name}: expected a positive integer, got {value!r}")
        if self.validate_every < 0:
            raise ValueError(f"validate_every: expected 0 (only at the end) or a number of steps, "
                             f"got {self.validate_every}")
        if not math.isfinite(self.learning_rate) or self.learning_rate <= 0:
            raise ValueError(f"learning_rate: expected a positive number, got {self.learning_rate}")
        if self.input_size > MAX_INPUT_SIZE:
            raise ValueError(f"input_size: expected at most {MAX_INPUT_SIZE} pixels, got {self.input_size}")
        if not 0.0 < self.val_fraction < 1.0:
            raise ValueError(f"val_fraction: expected a fraction in (0, 1), got {self.val_fraction}")
        if self.label_mode not in LABEL_MODES:
            raise ValueError(f"label_mode: expected one of {LABEL_MODES}, got {self.label_mode!r}")
        if self.seed < 0:
            raise ValueError(f"seed: expected a non-negative integer, got {self.seed}")
