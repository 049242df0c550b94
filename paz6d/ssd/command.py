"""``paz6d train ssd``: flags from :class:`~paz6d.ssd.config.SSDTraining` and the command."""

from __future__ import annotations

import argparse

from paz6d.cli_options import add_config_arguments
from paz6d.run_dirs import run_training
from paz6d.ssd.config import SSDTraining


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``paz6d train ssd`` flags (the fields of :class:`SSDTraining`)."""
    add_config_arguments(parser, SSDTraining, exclude=("settings",))


def run(args: argparse.Namespace) -> int:
    """Entry point of ``paz6d train ssd``."""
    from paz6d.ssd.train import train_ssd  # here: it loads OpenCV and TensorFlow

    return run_training(SSDTraining, args, train_ssd)
