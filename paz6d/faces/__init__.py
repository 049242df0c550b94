"""Faces: Haar cascade detection, eigen/fisherfaces, emotion (mini-Xception) and head pose. Importing this
package loads nothing heavy; it exports the emotion classifier's record ``METHOD``."""

from __future__ import annotations

from paz6d.faces.emotion_run_dir import EmotionRunDir
from paz6d.method import Method, NetworkSpec


def load_pipeline(run_dir):
    """The run's :class:`~paz6d.faces.emotion.DetectEmotion` (``image -> [(Box2D, label, scores)]``; imports
    TensorFlow and OpenCV)."""
    from paz6d.faces.emotion import DetectEmotion

    return DetectEmotion(EmotionRunDir.model_path(EmotionRunDir.validate(run_dir)))


def load_network(run_dir):
    """The run's mini-Xception, which :class:`~paz6d.faces.emotion.EmotionClassifier` calls itself (imports
    TensorFlow)."""
    from paz6d.faces.emotion_run_dir import read_model

    return read_model(run_dir)


#: The emotion classifier's record in :mod:`paz6d.methods`.
METHOD = Method("emotion", "emotion", EmotionRunDir, load_pipeline, task="classification", options=(),
                network=NetworkSpec(load_network, (-1.0, 1.0), step=None))
