"""The ``paz6d`` command: ``generate``, ``train``, ``detect``, ``estimate``, ``evaluate`` and ``demo``.

Each command lives in its own module exposing ``configure(parser)`` and ``run(args) -> int``;
those modules import heavy libraries (TensorFlow, pyrender) only inside ``run``.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from paz6d.cli_errors import EXPECTED_ERRORS, report

COMMANDS = {
    "generate": ("data_gen.cli", "render a synthetic BOP-format data set from meshes"),
    "train": ({"aae": ("paz6d.aae.train", "Augmented Autoencoder (implicit 6D pose)"),
               "keypointnet": ("paz6d.keypointnet.train", "KeypointNet keypoint discovery"),
               "emotion": ("paz6d.faces.emotion_train", "mini-Xception emotion classifier"),
               "ssd": ("paz6d.ssd.train", "SSD single-shot object detector")},
              "train a model"),
    "evaluate": ("evaluation.cli", "score results against ground truth (bop, coco, voc)"),
    "detect": ("paz6d.ssd.detect", "run a trained SSD over a BOP split or an image folder -> COCO detections JSON"),
    "estimate": ("paz6d.estimate", "run a trained pose model on a BOP data set (ground-truth boxes) -> BOP results CSV"),
    "demo": ("paz6d.demo.command", "end-to-end demo: generate data, train, estimate poses, evaluate"),
}


def _add_module_command(subparsers, name: str, module_name: str, help_text: str) -> None:
    module = importlib.import_module(module_name)
    parser = subparsers.add_parser(name, help=help_text, description=help_text)
    module.configure(parser)
    parser.set_defaults(_run=module.run)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="paz6d", description="paz6d: 6D object pose and perception toolkit")
    subparsers = parser.add_subparsers(dest="command", required=True)
    for name, (target, help_text) in COMMANDS.items():
        if isinstance(target, dict):
            group = subparsers.add_parser(name, help=help_text, description=help_text)
            inner = group.add_subparsers(dest="model", required=True)
            for model_name, (module_name, model_help) in target.items():
                _add_module_command(inner, model_name, module_name, model_help)
        else:
            _add_module_command(subparsers, name, target, help_text)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Runs ``paz6d``; bad input (:data:`paz6d.cli_errors.EXPECTED_ERRORS`) prints one line
    ``paz6d <command>: error: ...`` and returns 2, without a traceback."""
    args = build_parser().parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except EXPECTED_ERRORS as error:
        command = " ".join(filter(None, (args.command, getattr(args, "model", None),
                                         getattr(args, "evaluate_command", None))))
        print(report(command, error), file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
