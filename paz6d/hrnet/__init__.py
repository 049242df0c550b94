"""HRNet-style 2D keypoint estimation: a multi-resolution network trained on renderings of a mesh with
projected farthest-point keypoints as Gaussian heatmap targets, and its ``(image, box) -> Keypoints2D``
pipeline (see docs/hrnet.md)."""

from __future__ import annotations

from paz6d.hrnet.run_dir import HRNetRunDir
from paz6d.method import Method


def load_pipeline(run_dir, camera=None, class_name=None):
    """The run's :class:`~paz6d.hrnet.pipeline.HRNetPose6D` (imports TensorFlow)."""
    from paz6d.hrnet.pipeline import HRNetPose6D

    return HRNetPose6D(run_dir, camera, class_name=class_name)


#: HRNet's record in :mod:`paz6d.methods`.
METHOD = Method("hrnet", "HRNet", HRNetRunDir, load_pipeline)
