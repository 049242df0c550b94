"""``paz6d train probabilistic-keypoints``: flags from
:class:`~paz6d.probabilistic_keypoints.config.ProbabilisticTraining` and the command."""

from __future__ import annotations

import argparse

from paz6d.cli_options import add_config_arguments
from paz6d.run_dirs import run_training
from paz6d.probabilistic_keypoints.config import ProbabilisticTraining


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the flags (the fields of :class:`ProbabilisticTraining`)."""
    add_config_arguments(parser, ProbabilisticTraining, exclude=("settings",))


def run(args: argparse.Namespace) -> int:
    """Entry point of ``paz6d train probabilistic-keypoints``."""
    from paz6d.probabilistic_keypoints.train import train_probabilistic_keypoints  # here: renderers, TensorFlow

    return run_training(ProbabilisticTraining, args, train_probabilistic_keypoints)
