"""AAE inference speed on the CPU: encoding + codebook lookup per crop, single and batched.

Measures, for the encoders of the quick config (64x64, latent 128, batch norm), of the quick config on the
frozen pretrained EfficientNet-Lite0 (``encoder_backbone="efficientnet-lite0"``, as ``paz6d benchmark lmo
--quick`` trains them) and of the full, paper config (128x128, latent 128) with a 10,000-entry codebook:

* single crop: ``ImplicitPose6D.encode`` + ``Codebook.nearest`` per crop (target <= 20 ms);
* batched: 64 crops per call;
* the lookup alone as one matrix product vs the obvious alternative, ``scipy.spatial.distance.cdist``
  with the cosine metric + argmin, measured in the same run.

Run: ``.venv/bin/python benchmarks/aae_inference.py``. Weights are random: speed does not depend on them.
"""

from __future__ import annotations

import argparse
import os

import numpy as np
from timing import median_seconds


def measure(config, entries: int, batch: int, repeats: int) -> dict:
    from scipy.spatial.distance import cdist

    from paz6d.backend.tensorflow_guard import import_keras
    from paz6d.aae.model import build_encoder, encode_function, to_model_input
    from paz6d.aae.codebook import Codebook
    from paz6d.training.precision import resolve_precision

    keras = import_keras()
    keras.utils.set_random_seed(0)
    crop_size, latent_size = config.crop_size, config.latent_size
    encoder = encode_function(build_encoder(crop_size, latent_size, config.filters, config.kernel_size,
                                            config.batch_norm, resolve_precision(config.precision),
                                            config.encoder_backbone))  # as trained
    rng = np.random.default_rng(0)
    codebook = Codebook(rng.normal(size=(entries, latent_size)), np.broadcast_to(np.eye(3), (entries, 3, 3)),
                        np.tile([0.0, 0.0, 10.0, 10.0], (entries, 1)), np.eye(3), 1.0)
    crops = rng.integers(0, 256, (batch, crop_size, crop_size, 3), dtype=np.uint8)

    single = median_seconds(lambda: codebook.nearest(encoder(to_model_input(crops[:1]))), repeats)
    batched = median_seconds(lambda: codebook.nearest(encoder(to_model_input(crops))), max(3, repeats // 4)) / batch
    encode_single = median_seconds(lambda: encoder(to_model_input(crops[:1])), repeats)
    codes = np.asarray(encoder(to_model_input(crops)))
    lookup_single = median_seconds(lambda: codebook.nearest(codes[:1]), repeats)
    lookup_matrix = median_seconds(lambda: codebook.nearest(codes), repeats) / batch
    lookup_cdist = median_seconds(lambda: np.argmin(cdist(codes, codebook.codes, "cosine"), axis=1), repeats) / batch
    return {"crop": crop_size, "latent": latent_size, "entries": entries,
            "single_ms": 1000 * single, "batched_ms_per_crop": 1000 * batched, "encode_single_ms": 1000 * encode_single,
            "lookup_single_us": 1e6 * lookup_single, "lookup_matrix_us_per_crop": 1e6 * lookup_matrix,
            "lookup_cdist_us_per_crop": 1e6 * lookup_cdist}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--entries", type=int, default=10_000)
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    print(f"CPU cores: {os.cpu_count()}, load average (1 min) at start: {os.getloadavg()[0]:.1f}")
    from dataclasses import replace

    from paz6d.aae.config import FULL, QUICK

    pretrained = replace(QUICK, encoder_backbone="efficientnet-lite0")
    for name, config in (("quick", QUICK), ("quick, pretrained encoder", pretrained), ("full", FULL)):
        r = measure(config, args.entries, args.batch, args.repeats)
        print(f"{name} {r['crop']}x{r['crop']} latent {r['latent']}, {r['entries']} entries: "
              f"single crop {r['single_ms']:.2f} ms (encode {r['encode_single_ms']:.2f} ms, "
              f"lookup {r['lookup_single_us']:.0f} us), "
              f"batch of {args.batch} {r['batched_ms_per_crop']:.2f} ms/crop "
              f"({r['single_ms'] / r['batched_ms_per_crop']:.1f}x faster than single); "
              f"lookup {r['lookup_matrix_us_per_crop']:.1f} us/crop vs cdist {r['lookup_cdist_us_per_crop']:.1f} "
              f"us/crop "
              f"({r['lookup_cdist_us_per_crop'] / r['lookup_matrix_us_per_crop']:.1f}x)")


if __name__ == "__main__":
    main()
