"""``paz6d train hrnet``: flags from :class:`~paz6d.hrnet.config.HRNetTraining` and the command.

Light on purpose: building the parser imports only this module and the settings; the trainer
(:mod:`paz6d.hrnet.train`, OpenCV, then TensorFlow and the renderers) loads when it runs.
"""

from __future__ import annotations

import argparse

from paz6d.cli_options import add_config_arguments
from paz6d.run_dirs import run_training
from paz6d.hrnet.config import HRNetTraining


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``paz6d train hrnet`` flags (the fields of :class:`HRNetTraining`)."""
    add_config_arguments(parser, HRNetTraining, exclude=("settings",))


def run(args: argparse.Namespace) -> int:
    """Entry point of ``paz6d train hrnet``."""
    from paz6d.hrnet.train import train_hrnet  # here: it loads OpenCV (then TensorFlow and the renderers)

    return run_training(HRNetTraining, args, train_hrnet)
