"""``paz6d train probabilistic-keypoints``: flags from
:class:`~paz6d.probabilistic_keypoints.config.ProbabilisticTraining` and the command."""

from __future__ import annotations

import argparse
import json

from paz6d.backend.paths import check_output_folder
from paz6d.cli_options import add_config_arguments, config_from_args, flags_in_errors
from paz6d.probabilistic_keypoints.config import ProbabilisticTraining


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the flags (the fields of :class:`ProbabilisticTraining`)."""
    add_config_arguments(parser, ProbabilisticTraining, exclude=("overrides",))


def run(args: argparse.Namespace) -> int:
    """Entry point of ``paz6d train probabilistic-keypoints``."""
    from paz6d.probabilistic_keypoints.train import train_probabilistic_keypoints  # here: renderers, TensorFlow

    job = config_from_args(ProbabilisticTraining, args, exclude=("overrides",))
    with flags_in_errors(ProbabilisticTraining):
        check_output_folder(job.out, "out")
        summary = train_probabilistic_keypoints(job)
    print(json.dumps(summary, indent=2))
    return 0
