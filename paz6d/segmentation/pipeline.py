"""Instance masks inside boxes (Mask R-CNN's mask branch, as crop-then-segment), and detection + masks.

:class:`SegmentInstances` loads a segmentation run directory (:mod:`paz6d.segmentation.run_dir`) and maps
``(image, boxes) -> masks (N, H, W) bool`` with named steps; :class:`DetectAndSegment` runs a detector
(e.g. :class:`~paz6d.ssd.pipeline.DetectSingleShot`) and then the mask head on its boxes.
:func:`~paz6d.segmentation.masks.blank_background` makes a mask usable by the pose pipelines: it blanks
everything outside the object before their crop.

Example:
    >>> segment = SegmentInstances("runs/segmentation")                        # doctest: +SKIP
    >>> masks = segment(image, [Box2D(210, 140, 330, 260, class_name="obj_000005")])   # doctest: +SKIP
    >>> segment.names                                                           # doctest: +SKIP
    ['crop', 'predict', 'pick_class', 'paste', 'threshold']
    >>> detections, masks = DetectAndSegment(DetectSingleShot("runs/ssd"), segment)(image)  # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from paz6d.abstract import Box2D, KeyedStep, Processor, SequentialProcessor
from paz6d.backend.boxes import check_box_in_image
from paz6d.backend.image import as_image
from paz6d.processors.crops import SquareCrop
from paz6d.processors.predict import Predict
from paz6d.segmentation import run_dir as run_files
from paz6d.segmentation.masks import paste_mask


class PickClass(Processor):
    """``(probabilities (S, S, C), class_id) -> (S, S)``: the channel of the box's class."""

    def call(self, probabilities, class_id: int) -> np.ndarray:
        return np.asarray(probabilities)[..., int(class_id)]


class PasteMask(Processor):
    """``(crop_values (S, S), window, box, image_size (W, H)) -> (H, W) float32`` inside the box
    (:func:`~paz6d.segmentation.masks.paste_mask`)."""

    def call(self, crop_values, window, box, image_size) -> np.ndarray:
        return paste_mask(crop_values, window, box, image_size)


class ThresholdMask(Processor):
    """``probabilities (H, W) -> mask (H, W) bool`` (``>= threshold``)."""

    def __init__(self, threshold: float = 0.5, name: str | None = None):
        super().__init__(name)
        if not 0.0 < float(threshold) < 1.0:
            raise ValueError(f"threshold: expected a probability in (0, 1), got {threshold}")
        self.threshold = float(threshold)

    def call(self, probabilities) -> np.ndarray:
        return np.asarray(probabilities) >= self.threshold


class SegmentInstances(SequentialProcessor):
    """``(image, boxes) -> masks (N, H, W) bool``: the visible mask of the object inside each box.

    The steps pass a dict of per-box lists:

    - ``crop``: ``images``, ``boxes`` -> ``crops``, ``windows`` (square window of ``margin`` x the longer box
      side, :class:`~paz6d.processors.crops.SquareCrop`);
    - ``predict``: ``crops`` -> ``probabilities (N, S, S, C)`` (:class:`~paz6d.processors.predict.Predict`);
    - ``pick_class``: ``probabilities``, ``class_ids`` -> ``crop_masks`` (:class:`PickClass`);
    - ``paste``: ``crop_masks``, ``windows``, ``boxes``, ``image_sizes`` -> ``masks`` (:class:`PasteMask`,
      probabilities in the image, 0 outside the box);
    - ``threshold``: ``masks`` -> ``masks`` (:class:`ThresholdMask`).

    Args:
        run_dir: segmentation run directory.
        threshold: mask probability threshold (default: the run's ``segmenter.json``).
        batch_size: crops per network call.
    Raises:
        ValueError: a missing or corrupt run directory (the message names the file).
    """

    def __init__(self, run_dir: str | Path, threshold: float | None = None, batch_size: int = 32):
        from paz6d.segmentation.model import inference_function

        super().__init__(name="SegmentInstances")
        self.run_dir = Path(run_dir)
        self.model, description = run_files.read_model(self.run_dir)
        self.input_size, self.margin = description["input_size"], float(description["margin"])
        self.class_names = tuple(description["class_names"])
        self.threshold = float(description["threshold"] if threshold is None else threshold)
        self.add(KeyedStep(SquareCrop(self.margin, self.input_size), ("images", "boxes"), ("crops", "windows"),
                           "crop", per_sample=True))
        self.add(KeyedStep(Predict(inference_function(self.model), batch_size), "crops", "probabilities", "predict"))
        self.add(KeyedStep(PickClass(), ("probabilities", "class_ids"), "crop_masks", "pick_class", per_sample=True))
        self.add(KeyedStep(PasteMask(), ("crop_masks", "windows", "boxes", "image_sizes"), "masks", "paste",
                           per_sample=True))
        self.add(KeyedStep(ThresholdMask(self.threshold), "masks", "masks", "threshold", per_sample=True))

    def class_index(self, class_name: str | None) -> int:
        """Output channel of ``class_name`` (any name, or None, for a class-agnostic run with one channel)."""
        if len(self.class_names) == 1:
            return 0
        if class_name not in self.class_names:
            raise ValueError(f"class_name: expected one of the run's classes {list(self.class_names)} (the box's "
                             f"class picks the mask channel), got {class_name!r}")
        return self.class_names.index(class_name)

    def probabilities(self, image, boxes: Sequence, class_names: Sequence[str | None] | None = None) -> np.ndarray:
        """``(N, H, W) float32`` mask probabilities (0 outside each box), before the threshold."""
        return self._run(image, boxes, class_names, stop="threshold")

    def _run(self, image, boxes, class_names, stop: str | None) -> np.ndarray:
        image = as_image(image)
        height, width = image.shape[:2]
        boxes = list(boxes) if not isinstance(boxes, np.ndarray) else list(np.asarray(boxes).reshape(-1, 4))
        if class_names is None:
            class_names = [box.class_name if isinstance(box, Box2D) else None for box in boxes]
        if len(class_names) != len(boxes):
            raise ValueError(f"class_names: expected one per box ({len(boxes)}), got {len(class_names)}")
        arrays = [check_box_in_image(Box2D.coordinates_of(box), width, height, f"boxes[{i}]")
                  for i, box in enumerate(boxes)]
        if not arrays:
            return np.zeros((0, height, width), bool if stop is None else np.float32)
        values = {"images": [image] * len(arrays), "boxes": arrays,
                  "class_ids": [self.class_index(name) for name in class_names],
                  "image_sizes": [(width, height)] * len(arrays)}
        return np.stack(self.run_steps(values, stop=stop)["masks"])

    def call(self, image, boxes: Sequence, class_names: Sequence[str | None] | None = None) -> np.ndarray:
        """Masks of the objects in ``image (H, W, 3) uint8``.

        Args:
            boxes: ``Box2D`` messages (their ``class_name`` picks the mask channel) or ``(N, 4)`` xyxy pixels.
            class_names: per-box class names (default: the boxes' ``class_name``).
        Returns:
            ``(N, H, W) bool``; each mask lies inside its box.
        """
        return self._run(image, boxes, class_names, stop=None)


class DetectAndSegment(SequentialProcessor):
    """``image -> (detections list[Box2D], masks (N, H, W) bool)``: a detector then :class:`SegmentInstances`.

    Steps: ``detect`` (``image`` -> ``detections``) and ``segment`` (``image``, ``detections`` -> ``masks``).
    The detector's class names must be the segmenter's (both come from the same ``paz6d generate`` models).

    Args:
        detector: ``image -> list[Box2D]`` (e.g. :class:`~paz6d.ssd.pipeline.DetectSingleShot`).
        segmenter: a :class:`SegmentInstances`.
    """

    def __init__(self, detector: Callable, segmenter: SegmentInstances):
        names = getattr(detector, "class_names", None)
        if names is not None and len(segmenter.class_names) > 1 and set(names) - set(segmenter.class_names):
            raise ValueError(f"detector: classes {sorted(set(names) - set(segmenter.class_names))} are not the "
                             f"segmenter's {list(segmenter.class_names)}")
        super().__init__([KeyedStep(detector, "image", "detections", name="detect"),
                          KeyedStep(segmenter, ("image", "detections"), "masks", name="segment")],
                         name="DetectAndSegment")
        self.detector, self.segmenter = detector, segmenter

    def call(self, image) -> tuple[list[Box2D], np.ndarray]:
        values = self.run_steps({"image": as_image(image)})
        return values["detections"], values["masks"]
