"""``paz6d train segmentation``: flags from :class:`~paz6d.segmentation.config.SegmentationTraining`."""

from __future__ import annotations

import argparse
import json

from paz6d.cli_options import add_config_arguments, config_from_args, flags_in_errors
from paz6d.run_dirs import training_output
from paz6d.segmentation.config import SegmentationTraining


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``paz6d train segmentation`` flags (the fields of :class:`SegmentationTraining`)."""
    add_config_arguments(parser, SegmentationTraining, exclude=("overrides",))


def run(args: argparse.Namespace) -> int:
    """Entry point of ``paz6d train segmentation``."""
    from paz6d.segmentation.train import train_segmentation  # here: it loads OpenCV and TensorFlow

    job = config_from_args(SegmentationTraining, args, exclude=("overrides",))
    with flags_in_errors(SegmentationTraining), training_output(job, "segmentation"):
        summary = train_segmentation(job)
    print(json.dumps(summary, indent=2))
    return 0
