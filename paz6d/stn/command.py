"""``paz6d train stn``: flags from :class:`~paz6d.stn.config.STNTraining` and the command."""

from __future__ import annotations

import argparse
import json

from paz6d.backend.paths import check_output_folder
from paz6d.cli_options import add_config_arguments, config_from_args, flags_in_errors
from paz6d.stn.config import STNTraining


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``paz6d train stn`` flags (the fields of :class:`STNTraining`)."""
    add_config_arguments(parser, STNTraining, exclude=("overrides",))


def run(args: argparse.Namespace) -> int:
    """Entry point of ``paz6d train stn``."""
    from paz6d.stn.train import train_stn  # here: it loads TensorFlow

    job = config_from_args(STNTraining, args, exclude=("overrides",))
    with flags_in_errors(STNTraining):
        check_output_folder(job.out, "out")
        summary = train_stn(job)
    print(json.dumps(summary, indent=2))
    return 0
