"""``paz6d train segmentation``: flags from :class:`~paz6d.segmentation.config.SegmentationTraining`."""

from __future__ import annotations

import argparse

from paz6d.cli_options import add_config_arguments
from paz6d.run_dirs import run_training
from paz6d.segmentation.config import SegmentationTraining


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``paz6d train segmentation`` flags (the fields of :class:`SegmentationTraining`)."""
    add_config_arguments(parser, SegmentationTraining, exclude=("settings",))


def run(args: argparse.Namespace) -> int:
    """Entry point of ``paz6d train segmentation``."""
    from paz6d.segmentation.train import train_segmentation  # here: it loads OpenCV and TensorFlow

    return run_training(SegmentationTraining, args, train_segmentation)
