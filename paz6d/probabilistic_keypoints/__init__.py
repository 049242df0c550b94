"""Probabilistic keypoints: a 2D Gaussian (mean + Cholesky covariance) per KeypointNet keypoint, trained
with the negative log-likelihood, and covariance-weighted PnP (``paz6d train probabilistic-keypoints``;
see docs/probabilistic_keypoints.md)."""

from __future__ import annotations

from paz6d.method import Method, NetworkSpec
from paz6d.probabilistic_keypoints.run_dir import ProbabilisticKeypointsRunDir, read_model


def load_pipeline(run_dir, camera=None, class_name=None):
    """The run's :class:`~paz6d.probabilistic_keypoints.pipeline.ProbabilisticKeypointPose6D` (imports
    TensorFlow)."""
    from paz6d.probabilistic_keypoints.pipeline import ProbabilisticKeypointPose6D

    return ProbabilisticKeypointPose6D(run_dir, camera, class_name=class_name)


#: The probabilistic keypoints' record in :mod:`paz6d.methods`; its network is the whole network (crops in
#: 0..255 -> ``uv``, ``depth``, ``probabilities``, ``cholesky``), what ``ProbabilisticKeypointPose6D``'s
#: ``predict`` step runs.
METHOD = Method("probabilistic-keypoints", "probabilistic-keypoints", ProbabilisticKeypointsRunDir, load_pipeline,
                network=NetworkSpec(read_model, (0.0, 255.0)))
