"""AAE training and encoding speed on the CPU: the encoder on the frozen pretrained EfficientNet-Lite0
(``encoder_backbone="efficientnet-lite0"``) against the quick config's own convolutions, in the same run.

Quick config (64x64 crops, latent 128, batches of 32), float32, random weights and inputs: one optimisation
step and encoding 256 crops in one call, as the codebook is built (``aae_precision.measure``).
Run: ``.venv/bin/python benchmarks/aae_encoder_speed.py``.
"""

from __future__ import annotations

import argparse
import os

from aae_precision import measure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20, help="timed steps per encoder")
    args = parser.parse_args()
    from paz6d.aae.config import QUICK

    print(f"CPU cores: {os.cpu_count()}, load average (1 min) at start: {os.getloadavg()[0]:.1f}")
    own = measure(QUICK, "float32", args.repeats)
    pretrained = measure(QUICK, "float32", args.repeats, backbone="efficientnet-lite0")
    for key, what in (("step", "training step (batch 32)"), ("encode", "encoding 256 crops")):
        print(f"{what}: own {own[key] * 1000:.1f} ms, pretrained {pretrained[key] * 1000:.1f} ms, "
              f"pretrained / own {pretrained[key] / own[key]:.2f}")
    print(f"per crop when encoding: own {own['encode'] / 256 * 1000:.2f} ms, "
          f"pretrained {pretrained['encode'] / 256 * 1000:.2f} ms")


if __name__ == "__main__":
    main()
