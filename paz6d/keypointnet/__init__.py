"""KeypointNet + PnP (keypoint-based 6D pose): model and losses, training views, trainer, run
directory and the ``KeypointPose6D`` pipeline. Importing this package loads nothing heavy."""

from __future__ import annotations

from paz6d.keypointnet.run_dir import KeypointNetRunDir, read_model
from paz6d.method import Method, NetworkSpec


def load_pipeline(run_dir, camera=None, class_name=None, keypoint_crops: int = 1):
    """The run's :class:`~paz6d.keypointnet.pipeline.KeypointPose6D` with ``keypoint_crops`` crops per box
    (imports TensorFlow)."""
    from paz6d.keypointnet.pipeline import KeypointPose6D

    return KeypointPose6D(run_dir, camera, crops=keypoint_crops, class_name=class_name)


#: KeypointNet's record in :mod:`paz6d.methods`; its network is the whole KeypointNet (crops in 0..255 ->
#: ``uv``, ``depth``, ``probabilities``), what ``KeypointPose6D``'s ``predict`` step runs.
METHOD = Method("keypointnet", "KeypointNet", KeypointNetRunDir, load_pipeline,
                options=("camera", "class_name", "keypoint_crops"), aliases=("keypoints",),
                network=NetworkSpec(read_model, (0.0, 255.0)))
