"""``paz6d export --run RUN --format saved_model|tflite|onnx --out DIR``: a run's network in other formats.

The network is the one the method's pipeline runs, found through the method's record in the registry
(:func:`paz6d.export.networks.network_of`). Each
exported model is run on ``--inputs`` random inputs in the range its pipeline feeds it (one batch of
one, then the rest in one batch), and its outputs are compared with the Keras model's:
``export.json`` records the largest difference per format and output, and the command fails when one
exceeds :data:`TOLERANCE` (relative to the output's largest magnitude when that is above 1).
"""

from __future__ import annotations

import argparse
import importlib.metadata
import tempfile
import time
from pathlib import Path

import numpy as np

from paz6d.backend.files import write_json_atomically
from paz6d.backend.paths import check_output_folder, check_outputs_apart

#: Largest accepted difference between exported and Keras outputs (absolute; relative above magnitude 1).
TOLERANCE = 1e-4
EXPORT_FILE = "export.json"


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``paz6d export`` flags."""
    from paz6d.export.formats import FORMATS
    from paz6d.export.networks import exporting_methods

    parser.add_argument("--run", type=Path, required=True,
                        help=f"a run directory of any method with a network "
                             f"({', '.join(method.name for method in exporting_methods())})")
    parser.add_argument("--format", nargs="+", choices=FORMATS, required=True,
                        help="one or more formats: saved_model (folder), tflite (model.tflite), onnx (model.onnx, "
                             "through tf2onnx, run by onnxruntime)")
    parser.add_argument("--out", type=Path, required=True, help="output folder: the exported files and export.json")
    parser.add_argument("--inputs", type=int, default=20,
                        help="random inputs the exported outputs are checked on (default 20, at least 2)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random inputs (default 0)")


def _as_dict(outputs) -> dict:
    return {name: np.asarray(value) for name, value in outputs.items()} if isinstance(outputs, dict) \
        else {"output": np.asarray(outputs)}


def differences(reference: dict, exported: dict) -> dict[str, dict[str, float]]:
    """Per output name: ``max_abs`` difference, the reference's ``magnitude`` (largest absolute value) and
    ``scaled``: ``max_abs / max(1, magnitude)``.

    Raises:
        ValueError: the outputs' names or shapes differ.
    """
    if set(reference) != set(exported):
        raise ValueError(f"exported outputs {sorted(exported)} are not the Keras model's {sorted(reference)}")
    found = {}
    for name, expected in reference.items():
        actual = exported[name]
        if actual.shape != expected.shape:
            raise ValueError(f"output {name}: exported shape {actual.shape}, Keras shape {expected.shape}")
        max_abs = float(np.max(np.abs(actual.astype(np.float64) - expected)))
        magnitude = float(np.max(np.abs(expected)))
        found[name] = {"max_abs": max_abs, "magnitude": magnitude, "scaled": max_abs / max(1.0, magnitude)}
    return found


def check_exported(network, runner, count: int, seed: int) -> dict[str, dict[str, float]]:
    """:func:`differences` between ``network.model`` and an exported ``runner`` on ``count`` random inputs
    (uniform in ``network.input_range``), the exported model called on one input and then on the rest."""
    low, high = network.input_range
    inputs = np.random.default_rng(seed).uniform(low, high, (count, *network.input_shape)).astype(np.float32)
    reference = _as_dict(network.model(inputs, training=False))
    first, rest = _as_dict(runner(inputs[:1])), _as_dict(runner(inputs[1:]))
    exported = {name: np.concatenate([first[name], rest[name]]) for name in first}
    return differences({name: np.asarray(value, np.float64) for name, value in reference.items()}, exported)


def _versions(formats: list[str]) -> dict[str, str]:
    packages = ["tensorflow-cpu", "keras"] + (["tf2onnx", "onnx", "onnxruntime"] if "onnx" in formats else [])
    found = {}
    for package in packages:
        try:
            found[package] = importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            continue
    return found


def run(args: argparse.Namespace) -> int:
    """Runs ``paz6d export``; bad input raises ``ValueError`` naming the flag or file."""
    from paz6d.export.formats import ExportError, export, load_exported, onnx_modules
    from paz6d.export.networks import network_of

    if args.inputs < 2:
        raise ValueError(f"--inputs: expected at least 2 random inputs, got {args.inputs}")
    formats = list(dict.fromkeys(args.format))
    if "onnx" in formats:  # fail before the slow work when the converter is missing
        onnx_modules()
    check_output_folder(args.out, "--out")
    check_outputs_apart({"--out": args.out}, {"--run": args.run})
    network = network_of(args.run)
    args.out.mkdir(parents=True, exist_ok=True)
    results, failed = {}, []
    with tempfile.TemporaryDirectory(dir=args.out, prefix=".export-") as work:
        for format in sorted(formats, key=["saved_model", "tflite", "onnx"].index):
            started = time.perf_counter()
            path = export(network.model, args.out, format, work)
            seconds = time.perf_counter() - started
            found = check_exported(network, load_exported(path, format), args.inputs, args.seed)
            worst = max(value["scaled"] for value in found.values())
            results[format] = {"path": path.name, "export_seconds": round(seconds, 2), "outputs": found,
                               "max_difference": worst, "passed": worst <= TOLERANCE}
            if worst > TOLERANCE:
                failed.append(f"{format} {worst:.3g}")
            print(f"{format}: {path} (exported in {seconds:.1f} s); largest difference from Keras on "
                  f"{args.inputs} inputs {worst:.3g}" + ("" if worst <= TOLERANCE else f" > {TOLERANCE}"))
    write_json_atomically(args.out / EXPORT_FILE, {
        "run": str(args.run), "method": network.method, "pipeline_step": network.step,
        "input_shape": list(network.input_shape), "input_range": list(network.input_range),
        "inputs": args.inputs, "seed": args.seed, "tolerance": TOLERANCE, "formats": results,
        "versions": _versions(formats)}, indent=2)
    if failed:
        raise ExportError(f"exported outputs differ from the Keras model's by more than {TOLERANCE}: "
                          f"{', '.join(failed)} (see {args.out / EXPORT_FILE})")
    print(f"wrote {args.out / EXPORT_FILE}")
    return 0
