"""Inference speed of a network in Keras (compiled ``tf.function``, as the pipelines run it) against its
TFLite export (and its ONNX export run by onnxruntime), in the same process, with the same thread count.

With ``--run RUN`` the run's network (:func:`paz6d.export.networks.network_of`); without, the networks of
``paz6d benchmark lmo``'s quick settings with random weights (speed does not depend on them): the light
SSD at 320 px and the AAE encoder of the quick config (64 px crops, latent 128, batch norm). For a
detector it also times the whole detection pipeline (``DetectSingleShot``) on a 640 x 480 frame, as it
is and with its ``predict`` step replaced by the TFLite network.

Run: ``.venv/bin/python benchmarks/export_speed.py [--run RUN] [--threads 2] [--batch 8] [--repeats 30]``.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

import numpy as np
from timing import median_seconds


def default_ssd_run(folder: Path) -> Path:
    """A light SSD run directory at 320 px, 8 classes, random weights."""
    from paz6d.backend.tensorflow_guard import import_keras
    from paz6d.ssd.model import build_ssd, save_ssd
    from paz6d.ssd.run_dir import SSDRunDir, write_detector

    import_keras().utils.set_random_seed(0)
    model, spec = build_ssd(9, "light", input_size=320)
    write_detector(folder, "light", [f"obj_{index:06d}" for index in range(1, 9)], spec.to_dict())
    save_ssd(model, SSDRunDir.model_path(folder))
    return folder


def measure_detector(run: Path, folder: Path, threads: int, repeats: int) -> tuple[float, float]:
    """Median milliseconds of ``DetectSingleShot(run)`` on a 640 x 480 frame: as it is, and with its
    ``predict`` step replaced by name with the TFLite network."""
    from paz6d.abstract.processor import KeyedStep
    from paz6d.export.formats import TFLiteFunction, export
    from paz6d.export.networks import network_of
    from paz6d.pipelines import DetectSingleShot
    from paz6d.ssd.pipeline import PredictImage

    path = export(network_of(run).model, folder, "tflite", folder)
    keras_detector, tflite_detector = DetectSingleShot(run), DetectSingleShot(run)
    tflite_detector.replace("predict", KeyedStep(PredictImage(TFLiteFunction(path, threads)), "input", "output",
                                                 name="predict"))
    image = np.random.default_rng(0).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    return (1000 * median_seconds(lambda: keras_detector(image), repeats),
            1000 * median_seconds(lambda: tflite_detector(image), repeats))


def default_networks() -> list:
    from paz6d.aae.config import QUICK
    from paz6d.aae.model import build_encoder
    from paz6d.backend.tensorflow_guard import import_keras
    from paz6d.export.networks import Network
    from paz6d.methods import get
    from paz6d.ssd.model import build_ssd

    import_keras().utils.set_random_seed(0)
    ssd, _ = build_ssd(9, "light", input_size=320)
    encoder = build_encoder(64, QUICK.latent_size, QUICK.filters, QUICK.kernel_size, QUICK.batch_norm, "float32")
    return [Network("ssd", ssd, (320, 320, 3), get("ssd").network.input_range, "predict"),
            Network("aae", encoder, (64, 64, 3), get("aae").network.input_range, "encode")]


def measure(network, folder: Path, threads: int, batch: int, repeats: int, onnx: bool) -> dict[str, float]:
    """Median milliseconds per call of one input and of ``batch`` inputs, per runtime."""
    from paz6d.backend.tensorflow_guard import compiled_inference
    from paz6d.export.formats import export, load_exported

    runners = {"keras": compiled_inference(network.model)}
    for format in ("tflite", "onnx") if onnx else ("tflite",):
        runners[format] = load_exported(export(network.model, folder, format, folder), format, threads)
    low, high = network.input_range
    inputs = np.random.default_rng(0).uniform(low, high, (batch, *network.input_shape)).astype(np.float32)
    found = {}
    for name, runner in runners.items():
        found[f"{name}_1"] = 1000 * median_seconds(lambda: _first(runner(inputs[:1])), repeats)
        found[f"{name}_{batch}"] = 1000 * median_seconds(lambda: _first(runner(inputs)), max(3, repeats // 4))
    return found


def _first(outputs) -> np.ndarray:
    """One output as numpy (forces the computation of a TF tensor)."""
    value = next(iter(outputs.values())) if isinstance(outputs, dict) else outputs
    return np.asarray(value)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", type=Path, help="a run directory of any method (default: the quick benchmark's "
                                                 "SSD and AAE encoder with random weights)")
    parser.add_argument("--threads", type=int, default=2, help="TensorFlow intra-op and TFLite/onnxruntime threads")
    parser.add_argument("--batch", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--no-onnx", action="store_true", help="leave out the ONNX export")
    args = parser.parse_args()
    from paz6d.backend.tensorflow_guard import import_tensorflow
    from paz6d.export.networks import network_of

    tf = import_tensorflow()
    tf.config.threading.set_intra_op_parallelism_threads(args.threads)
    tf.config.threading.set_inter_op_parallelism_threads(1)
    print(f"CPU cores: {os.cpu_count()}, load average (1 min) at start: {os.getloadavg()[0]:.1f}, "
          f"threads: {args.threads}")
    networks = [network_of(args.run)] if args.run else default_networks()
    with tempfile.TemporaryDirectory() as work:
        if args.run is None or networks[0].method == "ssd":
            run = args.run or default_ssd_run(Path(work) / "ssd_run")
            (Path(work) / "pipeline").mkdir()
            keras_ms, tflite_ms = measure_detector(run, Path(work) / "pipeline", args.threads, args.repeats)
            print(f"DetectSingleShot on a 640x480 frame: Keras {keras_ms:.2f} ms ({1000 / keras_ms:.1f} fps), "
                  f"predict step on TFLite {tflite_ms:.2f} ms ({1000 / tflite_ms:.1f} fps) "
                  f"(Keras / TFLite {keras_ms / tflite_ms:.2f}x)")
        for index, network in enumerate(networks):
            folder = Path(work) / str(index)
            folder.mkdir()
            r = measure(network, folder, args.threads, args.batch, args.repeats, not args.no_onnx)
            for size in (1, args.batch):
                line = f"{network.method:6s} input {'x'.join(map(str, network.input_shape))}, batch {size:2d}: " \
                       f"Keras {r[f'keras_{size}']:.2f} ms, TFLite {r[f'tflite_{size}']:.2f} ms " \
                       f"(Keras / TFLite {r[f'keras_{size}'] / r[f'tflite_{size}']:.2f}x)"
                if f"onnx_{size}" in r:
                    line += f", onnxruntime {r[f'onnx_{size}']:.2f} ms " \
                            f"(Keras / onnxruntime {r[f'keras_{size}'] / r[f'onnx_{size}']:.2f}x)"
                print(line)


if __name__ == "__main__":
    main()
