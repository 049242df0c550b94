"""KeypointNet + PnP (keypoint-based 6D pose): model and losses, training views, trainer, run
directory and the ``KeypointPose6D`` pipeline. Importing this package loads nothing heavy."""
