"""The ``paz6d`` command: ``generate``, ``train``, ``detect``, ``estimate``, ``evaluate``, ``demo`` and ``benchmark``.

Each command lives in its own module exposing ``configure(parser)`` and ``run(args) -> int``;
those modules import heavy libraries (TensorFlow, pyrender, trimesh, numba, ...) only inside ``run``.
A command's module is imported only when that command is parsed (:class:`CommandParser`), so
``paz6d --help`` imports none of them and ``paz6d evaluate --help`` only ``evaluation.cli``.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from paz6d.cli_errors import EXPECTED_ERRORS, report, shorten

COMMANDS = {
    "generate": ("data_gen.cli", "render a synthetic BOP-format data set from meshes"),
    "train": ({"aae": ("paz6d.aae.command", "Augmented Autoencoder (implicit 6D pose)"),
               "keypointnet": ("paz6d.keypointnet.command", "KeypointNet keypoint discovery"),
               "emotion": ("paz6d.faces.emotion_command", "mini-Xception emotion classifier"),
               "ssd": ("paz6d.ssd.command", "SSD single-shot object detector"),
               "hrnet": ("paz6d.hrnet.command", "HRNet 2D keypoint heatmaps (keypoints of one object in a box)"),
               "segmentation": ("paz6d.segmentation.command",
                                "instance masks inside detection boxes (crop-then-segment U-Net)"),
               "stn": ("paz6d.stn.command", "spatial transformer digit classifier (cluttered digits)"),
               "probabilistic-keypoints": ("paz6d.probabilistic_keypoints.command",
                                           "KeypointNet keypoints with 2D Gaussian uncertainty (NLL), weighted PnP")},
              "train a model"),
    "evaluate": ("evaluation.cli", "score results against ground truth (bop, coco, voc)"),
    "detect": ("paz6d.ssd.detect", "run a trained SSD over a BOP split or an image folder -> COCO detections JSON"),
    "estimate": ("paz6d.estimate", "run trained pose models on a BOP data set (ground-truth boxes or --detector) "
                                   "or an image folder (--images, --detector) -> BOP results CSV"),
    "calibrate": ("paz6d.calibrate", "camera intrinsics and lens distortion from images of a chessboard or ChArUco "
                                     "board -> camera.json"),
    "export": ("paz6d.export.command", "a run's network as a TensorFlow SavedModel, TFLite or ONNX file, checked "
                                       "against the Keras model"),
    "demo": ("paz6d.demo.command", "end-to-end demo: generate data, train, estimate poses, evaluate"),
    "run": ("paz6d.video.command", "a pipeline (detector, 6D poses, faces) over a video, image folder or camera "
                                   "-> annotated video + JSON lines"),
    "benchmark": ({"lmo": ("paz6d.benchmark.command", "synthetic training only, scored on the real LM-O frames "
                                                      "(detector + one pose model per object; resumable)")},
                  "real-data benchmarks"),
}


class CommandParser(argparse.ArgumentParser):
    """The parser of one command: imports the command's module and adds its flags (``configure``)
    on first use, so that parsing one command never imports the others."""

    def __init__(self, *args, module_name: str | None = None, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.module_name = module_name

    def load_command(self) -> None:
        """Imports the command's module and configures this parser (once; nothing for a group)."""
        if self.module_name is None:
            return
        module, self.module_name = importlib.import_module(self.module_name), None
        module.configure(self)
        self.set_defaults(_run=module.run)

    def parse_known_args(self, args=None, namespace=None):
        self.load_command()
        return super().parse_known_args(args, namespace)

    def error(self, message: str):
        """argparse's usage error (exit code 2), with a value quoted in it shortened (a flag given a
        5 MB value is not echoed whole)."""
        super().error(shorten(message))


def _subparsers(parser: argparse.ArgumentParser, dest: str) -> argparse._SubParsersAction:
    return parser.add_subparsers(dest=dest, required=True, parser_class=CommandParser)


def build_parser(load_commands: bool = False) -> argparse.ArgumentParser:
    """The ``paz6d`` parser; each command's flags are added when it is parsed, or now with
    ``load_commands`` (to inspect every command's flags)."""
    parser = CommandParser(prog="paz6d", description="paz6d: 6D object pose and perception toolkit")
    subparsers = _subparsers(parser, "command")
    commands = []
    for name, (target, help_text) in COMMANDS.items():
        if isinstance(target, dict):
            group = subparsers.add_parser(name, help=help_text, description=help_text)
            inner = _subparsers(group, "model")
            commands += [inner.add_parser(model_name, help=model_help, description=model_help, module_name=module_name)
                         for model_name, (module_name, model_help) in target.items()]
        else:
            commands.append(subparsers.add_parser(name, help=help_text, description=help_text, module_name=target))
    if load_commands:
        for command in commands:
            command.load_command()
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
