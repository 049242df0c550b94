"""KeypointPose6D inference speed on the CPU: crop + KeypointNet + decoding + RANSAC PnP per crop.

For the quick and the full KeypointNet configurations (random weights: speed does not depend on
them) it measures, on a 640x480 image with a 150x120 px box:

* ``KeypointPose6D(image, box)`` end to end, one crop per call (target <= 30 ms), with the network
  run through its compiled ``tf.function`` (what the pipeline does); the same with unweighted PnP
  (``weighted_pnp=False``) and with 13 crops per box (``crops=13``);
* the network alone, compiled vs the obvious alternatives: the eager ``model(x)`` call and Keras'
  ``model.predict(x)``;
* ``estimate_batch`` with 25 crops per call, per crop.

Run: ``.venv/bin/python benchmarks/keypoint_inference.py [--repeats 20]``.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

import numpy as np
from timing import median_seconds


def _random_run(folder: Path, settings) -> Path:
    """A run directory with a randomly initialised KeypointNet of ``settings`` and a random 3D keypoint set."""
    from paz6d.keypointnet.model import build_keypointnet, save_keypointnet
    from paz6d.keypointnet.run_dir import KeypointNetRunDir, write_keypoints
    from paz6d.training.precision import resolve_precision

    model = build_keypointnet(settings.num_keypoints, settings.input_size, settings.filters, settings.downsample,
                              settings.dilations, context_stride=settings.context_stride,
                              compute_dtype=resolve_precision(settings.precision))
    save_keypointnet(model, KeypointNetRunDir.model_path(folder))
    KeypointNetRunDir.write_config(folder, {"input_size": settings.input_size, "margin": 1.25,
                                            "downsample": settings.downsample})
    points = np.random.default_rng(0).uniform(-0.05, 0.05, (settings.num_keypoints, 3))
    write_keypoints(folder, points, np.ones(len(points), bool), "farthest-point")
    return folder


def measure(name: str, repeats: int, batch: int) -> dict:
    from paz6d.backend.tensorflow_guard import import_keras
    from paz6d.keypointnet.pipeline import KeypointPose6D
    from paz6d.keypointnet.views import DEFAULT_CAMERA
    from paz6d.keypointnet.config import CONFIGS

    keras = import_keras()
    keras.utils.set_random_seed(0)
    settings = CONFIGS[name]
    with tempfile.TemporaryDirectory() as folder:
        run_dir = _random_run(Path(folder), settings)
        estimator, unweighted, many_crops = (KeypointPose6D(run_dir, DEFAULT_CAMERA, max_spread=1e9, **options)
                                             for options in ({}, {"weighted_pnp": False}, {"crops": 13}))
    image = np.random.default_rng(1).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    box = (250.0, 180.0, 400.0, 300.0)
    size = settings.input_size
    crop = np.random.default_rng(2).uniform(0, 255, (1, size, size, 3)).astype(np.float32)
    infer = estimator["predict"].processor.function  # the compiled network the pipeline's predict step runs

    def end_to_end(pipeline):
        try:
            pipeline(image, box)
        except ValueError:  # random weights may leave PnP without a solution; the work is done either way
            pass

    result = {"config": name, "input_size": size,
              "end_to_end_ms": 1000 * median_seconds(lambda: end_to_end(estimator), repeats),
              "unweighted_pnp_ms": 1000 * median_seconds(lambda: end_to_end(unweighted), repeats),
              "crops_13_ms": 1000 * median_seconds(lambda: end_to_end(many_crops), repeats),
              "network_compiled_ms": 1000 * median_seconds(lambda: infer(crop), repeats),
              "network_eager_ms": 1000 * median_seconds(lambda: estimator.model(crop, training=False), repeats),
              "network_predict_ms": 1000 * median_seconds(lambda: estimator.model.predict(crop, verbose=0), repeats)}
    images, boxes = [image] * batch, [box] * batch
    result["batch_ms_per_crop"] = 1000 * median_seconds(lambda: estimator.estimate_batch(images, boxes),
                                                         max(3, repeats // 4)) / batch
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--batch", type=int, default=25)
    parser.add_argument("--configs", nargs="+", default=["quick", "full"])
    args = parser.parse_args()
    print(f"CPU cores: {os.cpu_count()}, load average (1 min) at start: {os.getloadavg()[0]:.1f}")
    for name in args.configs:
        r = measure(name, args.repeats, args.batch)
        print(f"{name:5s} {r['input_size']}x{r['input_size']}: end to end {r['end_to_end_ms']:.1f} ms/crop "
              f"(target <= 30; unweighted PnP {r['unweighted_pnp_ms']:.1f}, 13 crops {r['crops_13_ms']:.1f}); "
              f"network compiled {r['network_compiled_ms']:.1f} ms vs eager "
              f"{r['network_eager_ms']:.1f} ms ({r['network_eager_ms'] / r['network_compiled_ms']:.1f}x) vs "
              f"model.predict {r['network_predict_ms']:.1f} ms "
              f"({r['network_predict_ms'] / r['network_compiled_ms']:.1f}x); "
              f"batch of {args.batch}: {r['batch_ms_per_crop']:.1f} ms/crop "
              f"({r['end_to_end_ms'] / r['batch_ms_per_crop']:.1f}x faster than one by one)")


if __name__ == "__main__":
    main()
