"""Single-shot detection: ``DetectSingleShot(run_dir)(image) -> list[Box2D]``.

:class:`DetectSingleShot` loads an SSD run directory (:mod:`paz6d.ssd.run_dir`) and is a
:class:`~paz6d.abstract.SequentialProcessor` of named steps that pass a dict of values along (each a
:class:`~paz6d.abstract.KeyedStep`), so steps can be read, replaced, inserted or removed.

Example:
    >>> detect = DetectSingleShot("runs/ssd")                        # doctest: +SKIP
    >>> detect(image)[0]                                              # doctest: +SKIP
    Box2D(x_min=210.4, y_min=140.0, x_max=330.2, y_max=260.9, score=0.93, class_name='obj_000005')
    >>> detect.names                                                  # doctest: +SKIP
    ['check', 'resize', 'normalize', 'predict', 'decode', 'nms', 'to_pixels', 'to_boxes2d']
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from paz6d.abstract import Box2D, KeyedStep, Processor, SequentialProcessor
from paz6d.backend import boxes as boxes_backend
from paz6d.backend.checks import is_whole_number
from paz6d.backend.draw import draw_box, keypoint_colors
from paz6d.backend.image import as_image, resize
from paz6d.processors.boxes import ToBoxes2D
from paz6d.processors.image import NormalizeImage, ResizeImage
from paz6d.processors.predict import Predict
from paz6d.ssd import run_dir as run_files
from paz6d.ssd.encoding import BACKGROUND, decode_outputs, select_detections
from paz6d.synthesis.box_augment import FILL


class CheckImage(Processor):
    """``image -> (image, (width, height))`` for an RGB ``uint8`` ``(H, W, 3)`` image.

    Raises:
        ValueError: another shape or dtype (the message names ``image`` and the expected shape).
    """

    def call(self, image) -> tuple[np.ndarray, tuple[int, int]]:
        array = np.asarray(image)
        if array.ndim != 3 or array.shape[2] != 3 or 0 in array.shape:
            raise ValueError(f"image: expected an RGB image of shape (H, W, 3), got shape {array.shape}")
        image = as_image(array)
        return image, (image.shape[1], image.shape[0])


class PredictImage(Processor):
    """One network input ``(S, S, 3)`` -> its output ``(P, 4 + C)`` (a batch of one through :class:`Predict`)."""

    def __init__(self, function: Callable, name: str | None = None):
        super().__init__(name)
        self.predict = Predict(function, batch_size=1)

    def call(self, values: np.ndarray) -> np.ndarray:
        return self.predict(np.asarray(values, np.float32)[None])[0]


class PredictImageAndMirror(Processor):
    """One network input ``(S, S, 3)`` -> outputs ``(2, P, 4 + C)`` of it and of its left-right mirror image,
    in one batch of two (the test-time mirror image, :class:`AverageWithMirror`)."""

    def __init__(self, function: Callable, name: str | None = None):
        super().__init__(name)
        self.predict = Predict(function, batch_size=2)

    def call(self, values: np.ndarray) -> np.ndarray:
        values = np.asarray(values, np.float32)
        return self.predict(np.stack([values, values[:, ::-1]]))


class DecodeBoxes(Processor):
    """Network output ``(P, 4 + C)`` -> normalised ``xyxy`` boxes ``(P, 4)`` and class probabilities
    ``(P, C)`` (:func:`paz6d.ssd.encoding.decode_outputs`)."""

    def __init__(self, priors, variances=boxes_backend.SSD_VARIANCES, name: str | None = None):
        super().__init__(name)
        self.priors, self.variances = np.asarray(priors, np.float64), tuple(variances)

    def priors_of(self) -> np.ndarray:
        """The priors ``(P, 4)`` the outputs are decoded against."""
        return self.priors

    def call(self, outputs) -> tuple[np.ndarray, np.ndarray]:
        return decode_outputs(outputs, self.priors, self.variances)


class ScaleAndPad(Processor):
    """``image (H, W, 3) -> (canvas, canvas_size)``: the image scaled by ``scale`` (aspect kept), then
    padded right and below with :data:`~paz6d.synthesis.box_augment.FILL` to multiples of ``multiple``
    pixels, at least ``minimum``; ``canvas_size = (width, height)`` of the canvas. The input of a light
    network built with ``any_size`` (trained on :class:`~paz6d.synthesis.box_augment.RandomScaleCrop`
    windows)."""

    def __init__(self, scale: float, multiple: int = 64, minimum: int = 128, name: str | None = None):
        super().__init__(name)
        if not scale > 0:
            raise ValueError(f"scale: expected a positive factor, got {scale}")
        self.scale, self.multiple, self.minimum = float(scale), int(multiple), int(minimum)

    def call(self, image) -> tuple[np.ndarray, tuple[int, int]]:
        height, width = image.shape[:2]
        size = (max(1, round(width * self.scale)), max(1, round(height * self.scale)))
        scaled = image if size == (width, height) else resize(image, size)
        canvas_width, canvas_height = (max(self.minimum, -(-side // self.multiple) * self.multiple) for side in size)
        canvas = np.empty((canvas_height, canvas_width, 3), np.uint8)
        canvas[:] = FILL
        canvas[:size[1], :size[0]] = scaled
        return canvas, (canvas_width, canvas_height)


class DecodeCanvasBoxes(Processor):
    """``(outputs (P, 4 + C), canvas_size) -> (boxes (P, 4), probabilities (P, C))``: as
    :class:`DecodeBoxes` with the priors of a ``canvas_size`` input (:func:`paz6d.ssd.model.priors_for`,
    computed once per size); boxes normalised by the canvas."""

    def __init__(self, spec, variances=boxes_backend.SSD_VARIANCES, name: str | None = None):
        super().__init__(name)
        self.spec, self.variances, self.priors = spec, tuple(variances), {}

    def priors_of(self, canvas_size) -> np.ndarray:
        """The priors ``(P, 4)`` of a ``canvas_size`` input."""
        from paz6d.ssd.model import priors_for

        width, height = canvas_size
        if (width, height) not in self.priors:
            self.priors[(width, height)] = priors_for(self.spec, (height, width))
        return self.priors[(width, height)]

    def call(self, outputs, canvas_size) -> tuple[np.ndarray, np.ndarray]:
        return decode_outputs(outputs, self.priors_of(canvas_size), self.variances)


class AverageWithMirror(Processor):
    """``(outputs (2, P, 4 + C), *decode inputs) -> (boxes (P, 4), probabilities (P, C))``: the outputs of an
    input and of its mirror image (:class:`PredictImageAndMirror`) decoded by ``decode``; the mirror image's
    boxes flipped back and each moved to the prior it mirrors (:func:`paz6d.backend.boxes.mirrored_prior_index`),
    then boxes and probabilities averaged per prior.

    Args:
        decode: :class:`DecodeBoxes` or :class:`DecodeCanvasBoxes` (its ``priors_of`` gives the priors).
    Raises:
        ValueError: priors without mirror images (SSD300's: its 38 cells of 8 px span 304 of its 300 px); the
            fixed priors of a :class:`DecodeBoxes` are checked here, a canvas's at its first call.
    """

    def __init__(self, decode: Processor, name: str | None = None):
        super().__init__(name)
        self.decode, self.mirrors = decode, {}
        if isinstance(decode, DecodeBoxes):
            self.mirrors[()] = boxes_backend.mirrored_prior_index(decode.priors_of())

    def call(self, outputs, *inputs) -> tuple[np.ndarray, np.ndarray]:
        outputs = np.asarray(outputs)
        if outputs.ndim != 3 or len(outputs) != 2:
            raise ValueError(f"outputs: expected the outputs of an input and its mirror image (2, P, 4 + C), "
                             f"got shape {outputs.shape}")
        boxes, probabilities = self.decode(outputs[0], *inputs)
        mirror_boxes, mirror_probabilities = self.decode(outputs[1], *inputs)
        key = tuple(inputs)
        if key not in self.mirrors:
            self.mirrors[key] = boxes_backend.mirrored_prior_index(self.decode.priors_of(*inputs))
        index = self.mirrors[key]
        mirror_boxes = boxes_backend.flip_left_right(mirror_boxes, 1.0)[index]
        return (boxes + mirror_boxes) / 2, (probabilities + mirror_probabilities[index]) / 2


class CanvasToPixels(Processor):
    """``(boxes (K, 4) normalised by the canvas, canvas_size, image_size) -> boxes (K, 4)`` in pixels of
    the image that :class:`ScaleAndPad` scaled by ``scale``, clipped to it."""

    def __init__(self, scale: float, name: str | None = None):
        super().__init__(name)
        self.scale = float(scale)

    def call(self, boxes, canvas_size, image_size) -> np.ndarray:
        pixels = boxes_backend.denormalize(np.asarray(boxes, np.float64).reshape(-1, 4), canvas_size) / self.scale
        return boxes_backend.clip(pixels, image_size)


class NonMaximumSuppression(Processor):
    """``(boxes (P, 4), probabilities (P, C)) -> (boxes (K, 4), scores (K,), class_ids (K,))``: per-class
    NMS (:func:`paz6d.ssd.encoding.select_detections`); with ``vote_iou`` each kept box is the score-weighted
    mean of its class's candidates overlapping it by at least that IoU (box voting)."""

    def __init__(self, score_threshold: float = 0.3, iou_threshold: float = 0.45, max_detections: int = 100,
                 vote_iou: float | None = None, name: str | None = None):
        super().__init__(name)
        check_detection_settings(score_threshold, iou_threshold, max_detections, vote_iou)
        self.score_threshold, self.iou_threshold = float(score_threshold), float(iou_threshold)
        self.max_detections = int(max_detections)
        self.vote_iou = None if vote_iou is None else float(vote_iou)

    def call(self, boxes, probabilities) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return select_detections(boxes, probabilities, self.score_threshold, self.iou_threshold, self.max_detections,
                                 vote_iou=self.vote_iou)


class DenormalizeBoxes(Processor):
    """Normalised ``xyxy`` boxes ``(K, 4)`` and the image size ``(width, height)`` -> pixel boxes."""

    def call(self, boxes, image_size) -> np.ndarray:
        return boxes_backend.denormalize(np.asarray(boxes, np.float64).reshape(-1, 4), image_size)


def check_detection_settings(score_threshold: float, iou_threshold: float, max_detections: int,
                             vote_iou: float | None = None) -> None:
    """``ValueError`` naming the argument unless both thresholds (and ``vote_iou`` unless ``None``) are numbers
    in [0, 1] and ``max_detections`` a whole number >= 1 (``"0.5"``, NaN, ``inf`` and ``2.7`` are refused)."""
    values = [("score_threshold", score_threshold), ("iou_threshold", iou_threshold)]
    for name, value in values + ([("vote_iou", vote_iou)] if vote_iou is not None else []):
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                or not 0.0 <= value <= 1.0:
            raise ValueError(f"{name}: expected a number in [0, 1], got {value!r:.40}")
    if not is_whole_number(max_detections) or max_detections < 1:
        raise ValueError(f"max_detections: expected a whole number >= 1, got {max_detections!r:.40}")


class DetectSingleShot(SequentialProcessor):
    """``image (H, W, 3) uint8 RGB -> list[Box2D]`` (pixel boxes, score, class name) with a trained SSD.

    ==============  ==============================  ====================================  =========================
    step            reads                           writes                                processor
    ==============  ==============================  ====================================  =========================
    ``check``       ``image``                       ``image``, ``image_size``             :class:`CheckImage`
    ``resize``      ``image``                       ``resized``                           :class:`ResizeImage`
    ``normalize``   ``resized``                     ``input``                             :class:`NormalizeImage`
    ``predict``     ``input``                       ``output``                            :class:`PredictImage`
    ``decode``      ``output``                      ``boxes``, ``probabilities``          :class:`DecodeBoxes`
    ``nms``         ``boxes``, ``probabilities``    ``boxes``, ``scores``, ``class_ids``  :class:`NonMaximumSuppression`
    ``to_pixels``   ``boxes``, ``image_size``       ``boxes``                             :class:`DenormalizeBoxes`
    ``to_boxes2d``  ``boxes``, ``scores``,          ``detections``                        :class:`ToBoxes2D`
                    ``class_ids``
    ==============  ==============================  ====================================  =========================

    A run trained on :class:`~paz6d.synthesis.box_augment.RandomScaleCrop` windows (``image_scale`` in
    ``detector.json``) runs on the whole image instead: ``resize`` is :class:`ScaleAndPad` (also writes
    ``canvas_size``), ``decode`` :class:`DecodeCanvasBoxes` and ``to_pixels`` :class:`CanvasToPixels`.

    With ``flip=True`` the network also sees the input's left-right mirror image: ``predict`` is
    :class:`PredictImageAndMirror` and ``decode`` averages both (:class:`AverageWithMirror`). That costs a
    second network pass (what it gains on real LM-O frames: ``docs/ssd.md``).

    Args:
        run_dir: SSD run directory (:mod:`paz6d.ssd.run_dir`).
        score_threshold: detections scoring below it are dropped (use ~0.01 for mAP evaluation).
        iou_threshold: per-class NMS threshold.
        max_detections: most boxes per image.
        flip: average with the detections of the mirror image (test-time augmentation).
        vote_iou: ``None`` keeps each NMS winner's box; a number in [0, 1] makes it the score-weighted mean of the
            boxes of its class overlapping it by at least this IoU (box voting, ``docs/ssd.md``).
    Raises:
        ValueError: missing or corrupt run directory (message names the file); a threshold that is no
            number in [0, 1] or a ``max_detections`` that is no whole number >= 1 (checked first).
    """

    def __init__(self, run_dir: str | Path, score_threshold: float = 0.3, iou_threshold: float = 0.45,
                 max_detections: int = 100, flip: bool = False, vote_iou: float | None = None):
        check_detection_settings(score_threshold, iou_threshold, max_detections, vote_iou)
        if not isinstance(run_dir, (str, Path)) or not str(run_dir):
            raise ValueError(f"run_dir: expected the path of an SSD run directory, got {run_dir!r:.60}")
        model, detector = run_files.read_model(run_dir)
        self.run_dir = Path(run_dir)
        self._build(model, detector, score_threshold, iou_threshold, max_detections, flip, vote_iou)

    @classmethod
    def from_model(cls, model, detector: dict, score_threshold: float = 0.3, iou_threshold: float = 0.45,
                   max_detections: int = 100, flip: bool = False, vote_iou: float | None = None
                   ) -> "DetectSingleShot":
        """The pipeline of a network in memory (e.g. during training) and its ``detector.json`` contents
        (checked by :func:`paz6d.ssd.run_dir.check_detector`)."""
        check_detection_settings(score_threshold, iou_threshold, max_detections, vote_iou)
        run_files.check_detector(detector, "detector")
        pipeline = cls.__new__(cls)
        pipeline.run_dir = None
        pipeline._build(model, detector, score_threshold, iou_threshold, max_detections, flip, vote_iou)
        return pipeline

    def _build(self, model, detector: dict, score_threshold: float, iou_threshold: float, max_detections: int,
               flip: bool, vote_iou: float | None):
        from paz6d.ssd.model import PriorSpec, inference_function, input_normalization, priors_for

        spec = PriorSpec.from_dict(detector["priors"])
        self.model, self.class_names = model, tuple(detector["class_names"])
        self.input_size, self.image_scale, self.flip = spec.input_size, detector.get("image_scale"), bool(flip)
        if self.image_scale is None:  # the whole image squeezed into the square input
            resize_step = KeyedStep(ResizeImage((spec.input_size, spec.input_size)), "image", "resized", name="resize")
            decoder, decode_inputs = DecodeBoxes(priors_for(spec), detector["variances"]), ("output",)
            to_pixels = KeyedStep(DenormalizeBoxes(), ("boxes", "image_size"), "boxes", name="to_pixels")
        else:  # the whole image at the training windows' scale, padded
            resize_step = KeyedStep(ScaleAndPad(self.image_scale), "image", ("resized", "canvas_size"), name="resize")
            decoder, decode_inputs = DecodeCanvasBoxes(spec, detector["variances"]), ("output", "canvas_size")
            to_pixels = KeyedStep(CanvasToPixels(self.image_scale), ("boxes", "canvas_size", "image_size"), "boxes",
                                  name="to_pixels")
        normalization = detector.get("normalization") or input_normalization()
        predict = (PredictImageAndMirror if self.flip else PredictImage)(inference_function(model))
        decoder = AverageWithMirror(decoder) if self.flip else decoder
        SequentialProcessor.__init__(self, [
            KeyedStep(CheckImage(), "image", ("image", "image_size"), name="check"),
            resize_step,
            KeyedStep(NormalizeImage(normalization["mean"], normalization["std"]), "resized", "input",
                      name="normalize"),
            KeyedStep(predict, "input", "output", name="predict"),
            KeyedStep(decoder, decode_inputs, ("boxes", "probabilities"), name="decode"),
            KeyedStep(NonMaximumSuppression(score_threshold, iou_threshold, max_detections, vote_iou),
                      ("boxes", "probabilities"), ("boxes", "scores", "class_ids"), name="nms"),
            to_pixels,
            KeyedStep(ToBoxes2D((BACKGROUND,) + self.class_names), ("boxes", "scores", "class_ids"), "detections",
                      name="to_boxes2d"),
        ], name="DetectSingleShot")

    def call(self, image) -> list[Box2D]:
        return self.run_steps({"image": image})["detections"]


def draw_detections(image, detections: list[Box2D], class_names: tuple[str, ...] = ()) -> np.ndarray:
    """A copy of ``image`` with each box drawn (one colour per class of ``class_names``) and labelled."""
    canvas = as_image(image).copy()
    colors = keypoint_colors(max(len(class_names), 1))
    for box in detections:
        index = class_names.index(box.class_name) if box.class_name in class_names else 0
        color = tuple(int(c) for c in colors[index])
        canvas = draw_box(canvas, box.to_array(), color, thickness=2)
        label = f"{box.class_name or ''} {box.score:.2f}".strip()
        cv2.putText(canvas, label, (int(box.x_min), max(int(box.y_min) - 3, 10)), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                    color, 1, cv2.LINE_AA)
    return canvas
