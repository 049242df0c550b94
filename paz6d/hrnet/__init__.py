"""HRNet-style 2D keypoint estimation: a multi-resolution network trained on renderings of a mesh with
projected farthest-point keypoints as Gaussian heatmap targets, and its ``(image, box) -> Keypoints2D``
pipeline (see docs/hrnet.md)."""

from __future__ import annotations

from paz6d.hrnet.run_dir import HRNetRunDir, read_model
from paz6d.method import Method, NetworkSpec


def load_pipeline(run_dir, camera=None, class_name=None):
    """The run's :class:`~paz6d.hrnet.pipeline.HRNetPose6D` (imports TensorFlow)."""
    from paz6d.hrnet.pipeline import HRNetPose6D

    return HRNetPose6D(run_dir, camera, class_name=class_name)


def load_network(run_dir):
    """The run's network up to its ``heatmaps`` output (crops in 0..255 -> heatmaps), the network of
    ``HRNetPose6D``'s ``predict`` step (imports TensorFlow)."""
    from paz6d.backend.tensorflow_guard import import_keras
    from paz6d.hrnet.model import OUTPUT_NAME

    model = read_model(run_dir)
    return import_keras().Model(model.input, model.output[OUTPUT_NAME], name="hrnet_heatmaps")


#: HRNet's record in :mod:`paz6d.methods`.
METHOD = Method("hrnet", "HRNet", HRNetRunDir, load_pipeline, network=NetworkSpec(load_network, (0.0, 255.0)))
