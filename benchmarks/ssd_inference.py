"""DetectSingleShot inference speed on the CPU for a 640x480 image: resize/normalise -> network -> decode ->
per-class NMS -> Box2D (target <= 100 ms for the quick model), against the raw Keras ``model.predict``
call on the already resized input (the ratio says what the pipeline adds or saves).

Without ``--run-dir`` a randomly initialised network of the config is used (speed does not depend on
the weights; NMS does a little, through the number of candidates above the score threshold, so a
trained run's figure is the one to report).

``--flip`` times the pipeline that also runs the network on the mirror image (``DetectSingleShot(flip=True)``);
the raw ``predict`` stays one image, so the ratio shows what the second pass costs.

``--vote-iou IOU`` times the pipeline with box voting (``DetectSingleShot(vote_iou=IOU)``) and, on the same decoded
boxes, its NMS step against plain NMS (``nms_voted_over_plain``).

Run: ``.venv/bin/python benchmarks/ssd_inference.py [--run-dir runs/ssd] [--config quick] [--repeats 20] [--flip]
[--vote-iou 0.5]``.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
from timing import median_seconds


def _random_run(folder: Path, config: str) -> Path:
    """A run directory holding a randomly initialised network of ``config`` for 8 classes."""
    from paz6d.ssd.model import build_ssd, save_ssd
    from paz6d.ssd.config import CONFIGS
    from paz6d.ssd.run_dir import SSDRunDir, write_detector

    settings = CONFIGS[config]
    model, spec = build_ssd(9, settings.architecture, settings.input_size, settings.width)
    save_ssd(model, SSDRunDir.model_path(folder))
    write_detector(folder, settings.architecture, [f"obj_{i:06d}" for i in range(1, 9)], spec.to_dict())
    return folder


def measure(run_dir: Path | None, config: str, repeats: int, score_threshold: float, image: np.ndarray,
            flip: bool = False, vote_iou: float | None = None) -> dict:
    from paz6d.backend.tensorflow_guard import import_keras
    from paz6d.ssd.pipeline import DetectSingleShot

    import_keras().utils.set_random_seed(0)
    with tempfile.TemporaryDirectory() as folder:
        detector = DetectSingleShot(run_dir or _random_run(Path(folder), config), score_threshold=score_threshold,
                                    flip=flip, vote_iou=vote_iou)
    size = detector.input_size
    network_input = detector.run_steps({"image": image}, stop="predict")["input"][None]
    infer = detector["predict"].processor.predict.function
    pipeline_ms = 1000 * median_seconds(lambda: detector(image), repeats)
    predict_ms = 1000 * median_seconds(lambda: detector.model.predict(network_input, verbose=0), repeats)
    return {"run_dir": None if run_dir is None else str(run_dir), "config": config, "input_size": size,
            "image": list(image.shape), "score_threshold": score_threshold, "flip": flip,
            "detections": len(detector(image)),
            "pipeline_ms": round(pipeline_ms, 2),
            "network_compiled_ms": round(1000 * median_seconds(lambda: infer(network_input), repeats), 2),
            "keras_predict_ms": round(predict_ms, 2), "pipeline_over_predict": round(pipeline_ms / predict_ms, 3),
            **({} if vote_iou is None else _nms_times(detector, image, score_threshold, vote_iou, repeats))}


def _nms_times(detector, image: np.ndarray, score_threshold: float, vote_iou: float, repeats: int) -> dict:
    """The NMS step with box voting against plain NMS, on the same decoded boxes of ``image``."""
    from paz6d.ssd.pipeline import NonMaximumSuppression

    decoded = detector.run_steps({"image": image}, stop="nms")
    inputs = (decoded["boxes"], decoded["probabilities"])
    plain = 1000 * median_seconds(lambda: NonMaximumSuppression(score_threshold)(*inputs), repeats)
    voted = 1000 * median_seconds(lambda: NonMaximumSuppression(score_threshold, vote_iou=vote_iou)(*inputs), repeats)
    return {"vote_iou": vote_iou, "nms_plain_ms": round(plain, 3), "nms_voted_ms": round(voted, 3),
            "nms_voted_over_plain": round(voted / plain, 3)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run-dir", type=Path, help="trained SSD run (default: random weights of --config)")
    parser.add_argument("--config", default="quick", help="config of the random network (default: quick)")
    parser.add_argument("--image", type=Path, help="a 640x480 RGB image (default: random pixels)")
    parser.add_argument("--score-threshold", type=float, default=0.3)
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--flip", action="store_true", help="the pipeline also detects on the mirror image")
    parser.add_argument("--vote-iou", type=float, default=None, help="box voting at this IoU (default: off)")
    args = parser.parse_args()
    from paz6d.backend.image import load_image

    image = (load_image(args.image) if args.image is not None
             else np.random.default_rng(1).integers(0, 256, (480, 640, 3), dtype=np.uint8))
    print(json.dumps(measure(args.run_dir, args.config, args.repeats, args.score_threshold, image, args.flip,
                             args.vote_iou), indent=2))


if __name__ == "__main__":
    main()
