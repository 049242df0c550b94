"""Faces: Haar cascade detection, eigen/fisherfaces, emotion (mini-Xception) and head pose. Importing this
package loads nothing heavy; it exports the emotion classifier's record ``METHOD``."""

from __future__ import annotations

from paz6d.faces.emotion_run_dir import EmotionRunDir, read_model
from paz6d.method import Method, NetworkSpec


def load_pipeline(run_dir):
    """The run's :class:`~paz6d.faces.emotion.DetectEmotion` (``image -> [(Box2D, label, scores)]``; imports
    TensorFlow and OpenCV)."""
    from paz6d.faces.emotion import DetectEmotion

    return DetectEmotion(EmotionRunDir.model_path(EmotionRunDir.validate(run_dir)))


#: The emotion classifier's record in :mod:`paz6d.methods`; its network is the mini-Xception (grey faces in
#: -1..1 -> class probabilities), which :class:`~paz6d.faces.emotion.EmotionClassifier` calls itself.
METHOD = Method("emotion", "emotion", EmotionRunDir, load_pipeline, task="classification", options=(),
                network=NetworkSpec(read_model, (-1.0, 1.0), step=None))
