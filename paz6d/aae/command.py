"""``paz6d train aae``: flags from :class:`~paz6d.aae.config.AAETraining` and the command.

Light on purpose: building the parser imports only this module and the settings; the trainer
(:mod:`paz6d.aae.train`: renderers, augmentation, TensorFlow) is imported when the command runs.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from paz6d.aae.config import AAETraining
from paz6d.cli_options import add_config_arguments, config_from_args, flags_in_errors
from paz6d.run_dirs import training_output


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``paz6d train aae`` flags (the fields of :class:`AAETraining`)."""
    add_config_arguments(parser, AAETraining)


def _dataset_mesh(dataset: Path, object_id: int | None) -> tuple[Path, int]:
    from paz6d.datasets.bop.models import model_meshes

    models = model_meshes(dataset / "models")
    if not models:
        raise ValueError(f"--dataset: {dataset / 'models'} holds no obj_XXXXXX.ply meshes")
    if object_id is None:
        if len(models) > 1:
            raise ValueError(f"--dataset: {len(models)} objects in {dataset / 'models'}; choose one with --object-id")
        return next(iter(models.values())), next(iter(models))
    path = dataset / "models" / f"obj_{object_id:06d}.ply"
    if not path.exists():
        raise ValueError(f"--object-id: {path} does not exist")
    return path, object_id


def run(args: argparse.Namespace) -> int:
    """Runs ``paz6d train aae``."""
    from paz6d.aae.train import train_aae  # here: the trainer loads the renderers and TensorFlow
    from paz6d.datasets.bop.reader import check_object_in_split

    job = config_from_args(AAETraining, args)
    with flags_in_errors(AAETraining), training_output(job, "aae"):
        mesh, object_id, object_class, scale = job.mesh, 1, None, job.mesh_scale
        split = job.split or "train"
        if job.format == "bop":
            found, object_id = _dataset_mesh(job.dataset, job.object_id)
            mesh = found if job.dataset_mesh is None else job.dataset_mesh
            check_object_in_split(job.dataset, split, object_id)  # before any view is rendered
        elif job.format is not None:
            from paz6d.datasets.pose_crops import pose_dataset  # here: reads YCB-Video / FAT files (scipy, OpenCV)

            source = pose_dataset(job.dataset, job.format, job.split, job.object_class, job.object_id,
                                  job.dataset_mesh, job.mesh_scale)
            mesh, object_class, scale, split = source.mesh_path, source.class_name, source.mesh_scale, source.split
        summary = train_aae(mesh, job.out, job.model_config, scale, job.seed, job.workers, job.platform,
                            job.progress, dataset=job.dataset, object_id=object_id, split=split,
                            pair_fraction=job.pair_fraction, dataset_format=job.format or "bop",
                            object_class=object_class, crop_box=job.crop_box)
    print(json.dumps(summary, indent=2))
    return 0
