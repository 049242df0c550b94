"""``paz6d train stn``: flags from :class:`~paz6d.stn.config.STNTraining` and the command."""

from __future__ import annotations

import argparse

from paz6d.cli_options import add_config_arguments
from paz6d.run_dirs import run_training
from paz6d.stn.config import STNTraining


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``paz6d train stn`` flags (the fields of :class:`STNTraining`)."""
    add_config_arguments(parser, STNTraining, exclude=("settings",))


def run(args: argparse.Namespace) -> int:
    """Entry point of ``paz6d train stn``."""
    from paz6d.stn.train import train_stn  # here: it loads TensorFlow

    return run_training(STNTraining, args, train_stn)
