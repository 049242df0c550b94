"""AAE training and encoding speed on the CPU: bfloat16 convolutions against float32, in the same run.

For the quick config (64x64, latent 128, batch norm, batches of 32) and the paper's full config (128x128,
batches of 64) it times, with random weights and inputs (speed does not depend on them):

* one optimisation step (forward, bootstrapped L2 loss, backward, Adam), compiled as the Trainer compiles it;
* encoding 256 crops in one call, as the codebook is built.

``precision: auto`` picks bfloat16 only where the CPU computes it natively (``avx512_bf16``/``amx_bf16``);
elsewhere TensorFlow emulates it and the ratio drops below 1. Run: ``.venv/bin/python benchmarks/aae_precision.py``.
"""

from __future__ import annotations

import argparse
import os

import numpy as np
from timing import median_seconds


def measure(config, compute_dtype: str, repeats: int, backbone: str = "none") -> dict:
    """Median seconds of one training step and of encoding 256 crops (``backbone``: the encoder's body)."""
    from paz6d.backend.tensorflow_guard import import_keras, import_tensorflow
    from paz6d.aae.model import build_autoencoder, encode_function, encoder_of, reconstruction_loss

    tf, keras = import_tensorflow(), import_keras()
    keras.utils.set_random_seed(0)
    model = build_autoencoder(config.crop_size, config.latent_size, config.filters, config.kernel_size,
                              config.batch_norm, compute_dtype, backbone)
    optimizer = keras.optimizers.Adam(config.learning_rate)
    rng = np.random.default_rng(0)
    shape = (config.batch_size, config.crop_size, config.crop_size, 3)
    inputs, targets = rng.random(shape, dtype=np.float32), rng.random(shape, dtype=np.float32)

    @tf.function
    def step(inputs, targets):
        with tf.GradientTape() as tape:
            loss = reconstruction_loss(targets, model(inputs, training=True), config.bootstrap_fraction)
        optimizer.apply_gradients(zip(tape.gradient(loss, model.trainable_variables), model.trainable_variables))
        return loss

    encode = encode_function(encoder_of(model))
    crops = rng.random((256, config.crop_size, config.crop_size, 3), dtype=np.float32)
    return {"step": median_seconds(lambda: float(step(inputs, targets)), repeats),
            "encode": median_seconds(lambda: encode(crops), max(3, repeats // 2))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20, help="timed steps per config and precision")
    args = parser.parse_args()
    from paz6d.aae.config import FULL, QUICK
    from paz6d.training.precision import native_bfloat16

    print(f"CPU cores: {os.cpu_count()}, native bfloat16: {native_bfloat16()}, "
          f"load average (1 min) at start: {os.getloadavg()[0]:.1f}")
    for name, config, repeats in (("quick", QUICK, args.repeats), ("full", FULL, max(3, args.repeats // 4))):
        single = measure(config, "float32", repeats)
        half = measure(config, "bfloat16", repeats)
        print(f"{name:5s} {config.crop_size}x{config.crop_size}, batch {config.batch_size}: training step "
              f"float32 {1000 * single['step']:.0f} ms, bfloat16 {1000 * half['step']:.0f} ms "
              f"({single['step'] / half['step']:.2f}x); encoding 256 crops float32 {1000 * single['encode']:.0f} ms, "
              f"bfloat16 {1000 * half['encode']:.0f} ms ({single['encode'] / half['encode']:.2f}x)")


if __name__ == "__main__":
    main()
