"""Augmented Autoencoder (implicit 6D pose): model, training views and augmentation, trainer,
run directory and the ``ImplicitPose6D`` pipeline. Importing this package loads nothing heavy."""

from __future__ import annotations

from paz6d.aae.run_dir import AAERunDir, read_model
from paz6d.method import Method, NetworkSpec


def load_pipeline(run_dir, camera=None, class_name=None, box_variants=None, viewpoints=None):
    """The run's :class:`~paz6d.aae.pipeline.ImplicitPose6D` (imports TensorFlow)."""
    from paz6d.aae.pipeline import ImplicitPose6D

    return ImplicitPose6D(run_dir, camera, class_name=class_name, box_variants=box_variants, viewpoints=viewpoints)


def load_network(run_dir):
    """The run's encoder (crops in 0..1 -> latent codes), the network of ``ImplicitPose6D``'s ``encode`` step
    (imports TensorFlow)."""
    from paz6d.aae.model import encoder_of

    return encoder_of(read_model(run_dir))


#: The AAE's record in :mod:`paz6d.methods`.
METHOD = Method("aae", "AAE", AAERunDir, load_pipeline,
                options=("camera", "class_name", "box_variants", "viewpoints"),
                network=NetworkSpec(load_network, (0.0, 1.0), step="encode"))
