"""The emotion run directory: the only module that knows its file names.

``paz6d train emotion`` writes, and :class:`~paz6d.faces.emotion.DetectEmotion` reads::

    RUN_DIR/model.keras             mini-Xception: grey faces (B, S, S, 1) scaled to [-1, 1] -> class
                                    probabilities (B, C)
    RUN_DIR/classes.json            the C class names in output order (a JSON list)
    RUN_DIR/metrics.json            validation accuracy and confusion matrix
    RUN_DIR/confusion_matrix.png    the validation confusion matrix

plus the shared trainer's ``checkpoints/``, ``log.csv``, ``tensorboard/`` and ``samples/``.
"""

from __future__ import annotations

from pathlib import Path

from paz6d.run_dir import RunDir

CLASSES_FILE = "classes.json"
CONFUSION_PNG = "confusion_matrix.png"


class EmotionRunDir(RunDir):
    """A ``paz6d train emotion`` run directory (files in the module docstring)."""

    KIND = "an emotion"
    MARKER_FILES = (CLASSES_FILE,)
    REQUIRED_FILES = (RunDir.MODEL_FILE, CLASSES_FILE)
    MESH_FIELDS = None


def read_model(run_dir: str | Path):
    """The trained mini-Xception (Keras safe mode; imports TensorFlow).

    Raises:
        ValueError: ``model.keras`` or ``classes.json`` missing, or the model unreadable (naming the file).
    """
    from paz6d.backend.tensorflow_guard import load_keras_model

    return load_keras_model(EmotionRunDir.model_path(EmotionRunDir.validate(run_dir)))
