"""``paz6d train aae``: flags from :class:`~paz6d.aae.config.AAETraining` and the command.

Light on purpose: building the parser imports only this module and the settings; the trainer
(:mod:`paz6d.aae.train`: renderers, augmentation, TensorFlow) is imported when the command runs.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from paz6d.aae.config import AAETraining
from paz6d.backend.paths import check_output_folder
from paz6d.cli_options import add_config_arguments, config_from_args, flags_in_errors


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``paz6d train aae`` flags (the fields of :class:`AAETraining`)."""
    add_config_arguments(parser, AAETraining)


def _dataset_mesh(dataset: Path, object_id: int | None) -> tuple[Path, int]:
    models = sorted((dataset / "models").glob("obj_*.ply"))
    if not models:
        raise ValueError(f"--dataset: {dataset / 'models'} holds no obj_XXXXXX.ply meshes")
    if object_id is None:
        if len(models) > 1:
            raise ValueError(f"--dataset: {len(models)} objects in {dataset / 'models'}; choose one with --object-id")
        return models[0], int(models[0].stem.split("_")[1])
    path = dataset / "models" / f"obj_{object_id:06d}.ply"
    if not path.exists():
        raise ValueError(f"--object-id: {path} does not exist")
    return path, object_id


def run(args: argparse.Namespace) -> int:
    """Runs ``paz6d train aae``."""
    from paz6d.aae.train import train_aae  # here: the trainer loads the renderers and TensorFlow
    from paz6d.datasets.bop.reader import check_object_in_split

    job = config_from_args(AAETraining, args)
    with flags_in_errors(AAETraining):
        check_output_folder(job.out, "out")
        mesh, object_id = (job.mesh, 1) if job.dataset is None else _dataset_mesh(job.dataset, job.object_id)
        if job.dataset is not None:  # before any view is rendered
            check_object_in_split(job.dataset, job.split, object_id)
        summary = train_aae(mesh, job.out, job.model_config, job.mesh_scale, job.seed, job.workers, job.platform,
                            job.progress, dataset=job.dataset, object_id=object_id, split=job.split,
                            pair_fraction=job.pair_fraction)
    print(json.dumps(summary, indent=2))
    return 0
