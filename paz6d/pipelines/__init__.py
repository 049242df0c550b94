"""Application-ready pipelines: an image in, messages (Box2D, Pose6D, ...) out.

Each method keeps its pipeline in its own package (``paz6d.aae``, ``paz6d.keypointnet``,
``paz6d.faces``, ``paz6d.ssd``); this module is the one place to import them from. Importing it is cheap: models
(and TensorFlow) load when a pipeline is created.

Every pipeline is a :class:`~paz6d.abstract.SequentialProcessor` of named steps
(``pipeline.names``; ``pipeline["crop"]``, ``replace``, ``insert`` and ``remove`` by name), built once
(a call does not add steps). The pose pipelines of the methods (:mod:`paz6d.methods`) share one call,
``pipeline(image, box, *, camera=None, depth=None) -> Pose6D``: the camera per call (default: the
constructor's) and an optional depth image (metres) for ICP refinement.
"""

from paz6d.aae.pipeline import ImplicitPose6D
from paz6d.detect_and_estimate import DetectAndEstimatePose6D
from paz6d.faces.emotion import DetectEmotion, EmotionClassifier
from paz6d.faces.haar import HaarCascadeDetector, available_cascades
from paz6d.faces.head_pose import HeadPose6D, draw_axes, yaw_pitch_roll_degrees
from paz6d.hrnet.pipeline import HRNetKeypoints2D, HRNetPose6D
from paz6d.keypointnet.pipeline import KeypointPose6D
from paz6d.probabilistic_keypoints.pipeline import ProbabilisticKeypointPose6D
from paz6d.segmentation.masks import blank_background
from paz6d.segmentation.pipeline import DetectAndSegment, SegmentInstances
from paz6d.ssd.pipeline import DetectSingleShot
from paz6d.stn.pipeline import ClassifyDigit

__all__ = ["DetectAndEstimatePose6D", "DetectEmotion", "DetectSingleShot", "EmotionClassifier", "HaarCascadeDetector",
           "HeadPose6D", "HRNetKeypoints2D", "HRNetPose6D",
           "ImplicitPose6D",
           "KeypointPose6D", "available_cascades", "draw_axes", "yaw_pitch_roll_degrees"]
__all__ += ["ClassifyDigit", "ProbabilisticKeypointPose6D"]
__all__ += ["DetectAndSegment", "SegmentInstances", "blank_background"]
