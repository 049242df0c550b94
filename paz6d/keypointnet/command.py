"""``paz6d train keypointnet``: flags from :class:`~paz6d.keypointnet.config.KeypointTraining` and the command.

Light on purpose: building the parser imports only this module and the settings; the trainer
(:mod:`paz6d.keypointnet.train`) loads the renderers and TensorFlow only when it trains.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace

from paz6d.cli_options import add_config_arguments, config_from_args, flags_in_errors
from paz6d.run_dirs import training_output
from paz6d.keypointnet.config import KeypointTraining
from paz6d.keypointnet.train import train_keypointnet


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``paz6d train keypointnet`` flags (the fields of :class:`KeypointTraining`)."""
    add_config_arguments(parser, KeypointTraining, exclude=("settings",))


def run(args: argparse.Namespace) -> int:
    """Entry point of ``paz6d train keypointnet``."""
    job = config_from_args(KeypointTraining, args, exclude=("settings",))
    with flags_in_errors(KeypointTraining), training_output(job, "keypointnet"):
        views = None
        if job.dataset is not None:
            from paz6d.keypointnet.dataset import bop_object_views, sample_object_views

            if job.format == "bop":
                views, mesh, scale = bop_object_views(job.dataset, job.object_id, job.split,
                                                      job.model_config.input_size, job.mesh_scale)
                mesh, scale = (mesh, scale) if job.dataset_mesh is None else (job.dataset_mesh, job.mesh_scale)
            else:
                views, mesh, scale = sample_object_views(job.dataset, job.format, job.split, job.object_class,
                                                         job.object_id, job.dataset_mesh, job.mesh_scale,
                                                         job.model_config.input_size, progress=job.progress)
            job = replace(job, mesh=mesh, mesh_scale=scale, dataset=None, format=None, object_id=None,
                          object_class=None, split=None, dataset_mesh=None)
        summary = train_keypointnet(job, views=views)
    print(json.dumps(summary, indent=2))
    return 0
