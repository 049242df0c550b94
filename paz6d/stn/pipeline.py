"""Digit classification with (or without) a spatial transformer: ``image -> class name, score, crop``.

:class:`ClassifyDigit` loads a ``paz6d train stn`` run directory (:mod:`paz6d.stn.run_dir`) and is a
:class:`~paz6d.abstract.SequentialProcessor` of named steps (``to_grey``, ``resize``, ``normalize``,
``predict``, ``label``) that can be read, replaced, inserted or removed.

Example:
    >>> classify = ClassifyDigit("runs/stn")                     # doctest: +SKIP
    >>> result = classify(canvas)                                # doctest: +SKIP
    >>> result.class_name, result.score, result.crop.shape       # doctest: +SKIP
    ('7', 0.98..., (48, 48))
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from paz6d.abstract import KeyedStep, Processor, SequentialProcessor
from paz6d.backend.image import convert_color_space, resize
from paz6d.processors.predict import Predict
from paz6d.stn import run_dir as run_files


@dataclass(frozen=True)
class DigitPrediction:
    """What :class:`ClassifyDigit` returns.

    Attributes:
        class_name: the most probable class; score: its probability.
        probabilities: ``(C,)`` in ``class_names`` order.
        crop: ``(h, w)`` uint8, what the classifier saw (the transformer's output, or the resized input
            without a transformer).
        theta: ``(2, 3)`` the transformer's affine map (normalised coordinates), ``None`` without one.
    """

    class_name: str
    score: float
    probabilities: np.ndarray
    crop: np.ndarray
    theta: np.ndarray | None


class ToGrey(Processor):
    """``image (H, W)``, ``(H, W, 1)`` or RGB ``(H, W, 3)`` uint8 (or float in [0, 1]) -> grey ``(H, W)`` uint8."""

    def call(self, image) -> np.ndarray:
        image = np.asarray(image)
        if image.ndim == 3 and image.shape[2] == 1:
            image = image[..., 0]
        if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] != 3) or 0 in image.shape:
            raise ValueError(f"image: expected a grey (H, W) or RGB (H, W, 3) image, got shape {image.shape}")
        if image.dtype != np.uint8:
            if not np.issubdtype(image.dtype, np.floating) or not np.all(np.isfinite(image)):
                raise ValueError(f"image: expected uint8 or float values in [0, 1], got {image.dtype}")
            image = np.round(np.clip(image, 0.0, 1.0) * 255.0).astype(np.uint8)
        return convert_color_space(image, "RGB", "GRAY") if image.ndim == 3 else image


class ResizeSquare(Processor):
    """Grey ``(H, W)`` -> ``(size, size)`` (area interpolation when shrinking, linear otherwise)."""

    def __init__(self, size: int, name: str | None = None):
        super().__init__(name)
        self.size = int(size)

    def call(self, grey: np.ndarray) -> np.ndarray:
        if grey.shape == (self.size, self.size):
            return grey
        shrink = max(grey.shape) > self.size
        return resize(grey, (self.size, self.size), "area" if shrink else "linear")


class ToInputBatch(Processor):
    """Grey ``(S, S)`` uint8 -> network input ``(1, S, S, 1)`` float32 in [0, 1]."""

    def call(self, grey: np.ndarray) -> np.ndarray:
        return (grey.astype(np.float32) / 255.0)[None, :, :, None]


class LabelDigit(Processor):
    """Network outputs of one image (+ the input) -> :class:`DigitPrediction`."""

    def __init__(self, class_names, name: str | None = None):
        super().__init__(name)
        self.class_names = tuple(class_names)

    def call(self, outputs: dict, inputs: np.ndarray) -> DigitPrediction:
        probabilities = np.asarray(outputs["probabilities"][0], dtype=np.float64)
        index = int(np.argmax(probabilities))
        crop = np.asarray(outputs["crop"][0, ..., 0]) if "crop" in outputs else inputs[0, ..., 0]
        theta = np.asarray(outputs["theta"][0], dtype=np.float64) if "theta" in outputs else None
        crop = np.round(np.clip(crop, 0.0, 1.0) * 255.0).astype(np.uint8)
        return DigitPrediction(self.class_names[index], float(probabilities[index]), probabilities, crop, theta)


class ClassifyDigit(SequentialProcessor):
    """``image -> DigitPrediction`` with a trained ``paz6d train stn`` run.

    Steps (each a :class:`~paz6d.abstract.KeyedStep` over a dict of named values): ``to_grey``
    (``image`` -> ``grey``), ``resize`` (``grey`` -> ``canvas``, the run's canvas size), ``normalize``
    (``canvas`` -> ``inputs``), ``predict`` (``inputs`` -> ``outputs``) and ``label``
    (``outputs``, ``inputs`` -> ``prediction``).

    Args:
        run_dir: a spatial-transformer run directory.
    Raises:
        ValueError: missing or corrupt run files (the message names the file).
    """

    def __init__(self, run_dir: str | Path):
        super().__init__(name="ClassifyDigit")
        from paz6d.stn.model import inference_function

        self.run_dir = Path(run_dir)
        self.model, classifier = run_files.read_model(self.run_dir)
        self.class_names = tuple(classifier["class_names"])
        self.canvas_size, self.transformer = int(classifier["canvas_size"]), bool(classifier["transformer"])
        self.add(KeyedStep(ToGrey(), "image", "grey", "to_grey"))
        self.add(KeyedStep(ResizeSquare(self.canvas_size), "grey", "canvas", "resize"))
        self.add(KeyedStep(ToInputBatch(), "canvas", "inputs", "normalize"))
        self.add(KeyedStep(Predict(inference_function(self.model)), "inputs", "outputs", "predict"))
        self.add(KeyedStep(LabelDigit(self.class_names), ("outputs", "inputs"), "prediction", "label"))

    def call(self, image) -> DigitPrediction:
        """The class of the digit in ``image`` (grey or RGB, uint8 or float in [0, 1], any size)."""
        return self.run_steps({"image": image})["prediction"]
