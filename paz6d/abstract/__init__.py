"""Processors and messages: the vocabulary shared by every paz6d layer."""

from paz6d.abstract.messages import Box2D, Keypoints2D, Keypoints3D, Pose6D
from paz6d.abstract.processor import (KeyedStep, Processor, RandomProcessor, SequentialProcessor, random_processors,
                                      reseed)

__all__ = ["Box2D", "KeyedStep", "Keypoints2D", "Keypoints3D", "Pose6D", "Processor", "RandomProcessor",
           "SequentialProcessor", "random_processors", "reseed"]
