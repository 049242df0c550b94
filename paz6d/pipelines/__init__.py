"""Application-ready pipelines: an image in, messages (Box2D, Pose6D, ...) out.

Importing this package is cheap: models (and TensorFlow) load when a pipeline is created.
"""

from paz6d.pipelines.emotion import DetectEmotion, EmotionClassifier
from paz6d.pipelines.haar import HaarCascadeDetector, available_cascades
from paz6d.pipelines.head_pose import HeadPose6D, draw_axes, yaw_pitch_roll_degrees
from paz6d.pipelines.implicit_pose import ImplicitPose6D
from paz6d.pipelines.keypoint_pose import KeypointPose6D

__all__ = ["DetectEmotion", "EmotionClassifier", "HaarCascadeDetector", "HeadPose6D", "ImplicitPose6D",
           "KeypointPose6D", "available_cascades", "draw_axes", "yaw_pitch_roll_degrees"]
