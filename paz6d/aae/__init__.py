"""Augmented Autoencoder (implicit 6D pose): model, training views and augmentation, trainer,
run directory and the ``ImplicitPose6D`` pipeline. Importing this package loads nothing heavy."""

from __future__ import annotations

from paz6d.aae.run_dir import AAERunDir
from paz6d.method import Method


def load_pipeline(run_dir, camera=None, class_name=None, box_variants=None, viewpoints=None):
    """The run's :class:`~paz6d.aae.pipeline.ImplicitPose6D` (imports TensorFlow)."""
    from paz6d.aae.pipeline import ImplicitPose6D

    return ImplicitPose6D(run_dir, camera, class_name=class_name, box_variants=box_variants, viewpoints=viewpoints)


#: The AAE's record in :mod:`paz6d.methods`.
METHOD = Method("aae", "AAE", AAERunDir, load_pipeline,
                options=("camera", "class_name", "box_variants", "viewpoints"))
