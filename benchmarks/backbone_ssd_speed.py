"""Detector inference time per 640x480 image on the CPU (DetectSingleShot: resize, normalise, network,
decode, NMS): the SSD on the pretrained EfficientNet-Lite0 (``paz6d train ssd --backbone efficientnet-lite0``
settings) against the from-scratch light SSD of the ``quick`` config, in the same process; the ratio is
backbone over light. Target: at most 100 ms per image.

Networks are built for 8 classes with the backbone's ImageNet weights and random heads (the network's
speed does not depend on the weights; NMS's share does a little, through the candidates above the score
threshold).

Run: ``.venv/bin/python benchmarks/backbone_ssd_speed.py [--repeats 20] [--threads 2]``.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
from timing import median_seconds


def _run_dir(folder: Path, backbone: str) -> Path:
    """A run directory with a network of the ``quick`` settings (with ``backbone``) for 8 classes."""
    from paz6d.ssd.config import SSDTraining
    from paz6d.ssd.model import build_ssd, input_normalization, save_ssd
    from paz6d.ssd.run_dir import SSDRunDir, write_detector

    settings = SSDTraining(dataset=folder, out=folder, backbone=backbone).model_config
    model, spec = build_ssd(9, settings.architecture, settings.input_size, settings.width, backbone=settings.backbone,
                            frozen_stages=settings.frozen_stages)
    save_ssd(model, SSDRunDir.model_path(folder))
    write_detector(folder, settings.architecture, [f"obj_{i:06d}" for i in range(1, 9)], spec.to_dict(),
                   normalization=input_normalization(settings.backbone))
    return folder


def measure(backbone: str, image: np.ndarray, repeats: int, score_threshold: float) -> dict:
    """Median pipeline milliseconds per image and the network's share (its compiled call alone)."""
    from paz6d.ssd.pipeline import DetectSingleShot

    with tempfile.TemporaryDirectory() as folder:
        detector = DetectSingleShot(_run_dir(Path(folder), backbone), score_threshold=score_threshold)
    network_input = detector.run_steps({"image": image}, stop="predict")["input"][None]
    infer = detector["predict"].processor.predict.function
    return {"backbone": backbone, "input_size": detector.input_size,
            "pipeline_ms": round(1000 * median_seconds(lambda: detector(image), repeats), 2),
            "network_ms": round(1000 * median_seconds(lambda: infer(network_input), repeats), 2)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--threads", type=int, default=2, help="TensorFlow CPU threads")
    parser.add_argument("--score-threshold", type=float, default=0.3)
    args = parser.parse_args()
    from paz6d.backend.tensorflow_guard import import_keras, import_tensorflow

    import_tensorflow(args.threads)
    import_keras().utils.set_random_seed(0)
    image = np.random.default_rng(1).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    backbone = measure("efficientnet-lite0", image, args.repeats, args.score_threshold)
    light = measure("none", image, args.repeats, args.score_threshold)
    print(json.dumps({"image": list(image.shape), "threads": args.threads, "score_threshold": args.score_threshold,
                      "backbone": backbone, "light": light,
                      "backbone_over_light": round(backbone["pipeline_ms"] / light["pipeline_ms"], 3)}, indent=2))


if __name__ == "__main__":
    main()
