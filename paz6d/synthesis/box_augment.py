"""SSD's data augmentation (Liu et al. 2016, section 2.2 and the Caffe release) as random processors over
images with boxes: photometric distortion, zoom-out ("expand"), random sample crop and horizontal flip.

Every processor takes and returns an :class:`AnnotatedImage`, so they compose with
:class:`~paz6d.abstract.processor.SequentialProcessor`; :func:`ssd_augmentation` builds the paper's
chain. Boxes are ``xyxy`` pixels (continuous coordinates) and follow every geometric change.

Example:
    >>> import numpy as np
    >>> sample = AnnotatedImage(np.zeros((60, 80, 3), np.uint8), np.array([[10., 10., 30., 40.]]), np.array([1]))
    >>> augment = ssd_augmentation(seed=0)
    >>> augmented = augment(sample)
    >>> augmented.boxes.shape[1]
    4
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from paz6d.abstract.processor import RandomProcessor, SequentialProcessor, reseed
from paz6d.backend import boxes as boxes_backend
from paz6d.backend import image as image_backend

#: SSD's random-crop modes: ``None`` keeps the whole image, a number is the least IoU the crop must
#: have with some box, ``0.0`` any crop.
CROP_MIN_IOUS = (None, 0.1, 0.3, 0.5, 0.7, 0.9, 0.0)
#: Colour (RGB) of the canvas around a zoomed-out or padded image: about the mean of natural images.
FILL = (124, 116, 104)


@dataclass(frozen=True)
class AnnotatedImage:
    """An image with its boxes.

    Attributes:
        image: ``(H, W, 3)`` uint8 RGB.
        boxes: ``(N, 4)`` float64 ``xyxy`` pixels.
        class_ids: ``(N,)`` integers.
    """

    image: np.ndarray
    boxes: np.ndarray
    class_ids: np.ndarray

    def __post_init__(self):
        image = image_backend.as_image(self.image)
        boxes = np.asarray(self.boxes, dtype=np.float64).reshape(-1, 4)
        class_ids = np.asarray(self.class_ids).reshape(-1)
        if len(class_ids) != len(boxes):
            raise ValueError(f"class_ids: expected {len(boxes)} ids matching boxes, got {len(class_ids)}")
        if not np.all(np.isfinite(boxes)):
            raise ValueError("boxes: expected finite xyxy pixel coordinates")
        object.__setattr__(self, "image", image)
        object.__setattr__(self, "boxes", boxes)
        object.__setattr__(self, "class_ids", class_ids)


class PhotometricDistortion(RandomProcessor):
    """SSD's colour distortion: each with probability 1/2, brightness offset in ``±brightness``, contrast
    factor in ``contrast`` (before or after the colour steps, by a coin), saturation factor in
    ``saturation`` and hue rotation in ``±hue_degrees``. Boxes are unchanged."""

    def __init__(self, brightness: float = 32.0, contrast: tuple[float, float] = (0.5, 1.5),
                 saturation: tuple[float, float] = (0.5, 1.5), hue_degrees: float = 18.0, seed=None,
                 name: str | None = None):
        super().__init__(seed, name)
        for argument, (lower, upper) in (("contrast", contrast), ("saturation", saturation)):
            if not 0 <= lower <= upper:
                raise ValueError(f"{argument}: expected 0 <= lower <= upper, got {(lower, upper)}")
        self.brightness, self.contrast, self.saturation = float(brightness), tuple(contrast), tuple(saturation)
        self.hue_degrees = float(hue_degrees)

    def call(self, sample: AnnotatedImage) -> AnnotatedImage:
        draw = self.generator
        image = sample.image
        if draw.random() < 0.5:
            image = image_backend.adjust_brightness(image, draw.uniform(-self.brightness, self.brightness))
        contrast_first = draw.random() < 0.5
        contrast = draw.uniform(*self.contrast) if draw.random() < 0.5 else None
        if contrast is not None and contrast_first:
            image = image_backend.adjust_contrast(image, contrast)
        if draw.random() < 0.5:
            image = image_backend.adjust_saturation(image, draw.uniform(*self.saturation))
        if draw.random() < 0.5:
            image = image_backend.adjust_hue(image, draw.uniform(-self.hue_degrees, self.hue_degrees))
        if contrast is not None and not contrast_first:
            image = image_backend.adjust_contrast(image, contrast)
        return replace(sample, image=image)


class WhiteBalance(RandomProcessor):
    """A colour cast, as from a camera's white balance or a warm or cold light: with ``probability``, the red
    channel times ``t`` and the blue channel times ``1 / t``, ``log t`` uniform in ``±log(1 + strength)``
    (clipped to 0..255). Unlike saturation and hue changes, it tints grey and white surfaces. Boxes are
    unchanged."""

    def __init__(self, strength: float = 0.25, probability: float = 0.5, seed=None, name: str | None = None):
        super().__init__(seed, name)
        if not (np.isfinite(strength) and strength >= 0):
            raise ValueError(f"strength: expected a gain change >= 0 (0.25 = red/blue gains up to 1.25x), got "
                             f"{strength}")
        self.strength, self.probability = float(strength), float(probability)

    def call(self, sample: AnnotatedImage) -> AnnotatedImage:
        if self.generator.random() >= self.probability:
            return sample
        gain = np.exp(self.generator.uniform(-1.0, 1.0) * np.log1p(self.strength))
        image = sample.image.astype(np.float32) * np.array([gain, 1.0, 1.0 / gain], np.float32)
        return replace(sample, image=np.clip(np.rint(image), 0, 255).astype(np.uint8))


class Grayscale(RandomProcessor):
    """With ``probability``, the image's luminance (ITU-R BT.601 weights) in all three channels: the boxes'
    objects must then be told apart by shape and shading, not colour. Boxes are unchanged."""

    def __init__(self, probability: float = 0.2, seed=None, name: str | None = None):
        super().__init__(seed, name)
        if not 0 <= probability <= 1:
            raise ValueError(f"probability: expected a share in [0, 1], got {probability}")
        self.probability = float(probability)

    def call(self, sample: AnnotatedImage) -> AnnotatedImage:
        if self.generator.random() >= self.probability:
            return sample
        grey = image_backend.convert_color_space(sample.image, "RGB", "GRAY")
        return replace(sample, image=image_backend.convert_color_space(grey, "GRAY", "RGB"))


class Expand(RandomProcessor):
    """SSD's zoom-out: with ``probability``, puts the image at a random place in a canvas ``r`` times its
    size (``r`` uniform in ``[1, max_ratio]``) filled with ``fill`` (RGB), and shifts the boxes."""

    def __init__(self, max_ratio: float = 4.0, probability: float = 0.5, fill=FILL, seed=None,
                 name: str | None = None):
        super().__init__(seed, name)
        if not max_ratio >= 1.0:
            raise ValueError(f"max_ratio: expected a canvas/image ratio >= 1, got {max_ratio}")
        self.max_ratio, self.probability = float(max_ratio), float(probability)
        self.fill = np.asarray(fill, dtype=np.uint8).reshape(3)

    def call(self, sample: AnnotatedImage) -> AnnotatedImage:
        if self.generator.random() >= self.probability:
            return sample
        height, width = sample.image.shape[:2]
        ratio = self.generator.uniform(1.0, self.max_ratio)
        canvas_width, canvas_height = int(width * ratio), int(height * ratio)
        left = int(self.generator.integers(0, canvas_width - width + 1))
        top = int(self.generator.integers(0, canvas_height - height + 1))
        canvas = np.empty((canvas_height, canvas_width, 3), np.uint8)
        canvas[:] = self.fill
        canvas[top:top + height, left:left + width] = sample.image
        return AnnotatedImage(canvas, sample.boxes + np.array([left, top, left, top], np.float64), sample.class_ids)


class RandomSampleCrop(RandomProcessor):
    """SSD's patch sampling: picks a mode from :data:`CROP_MIN_IOUS` (``None``: no crop); then up to
    ``trials`` windows of ``scale`` x the image sides with aspect (width/height) in ``aspect_ratio`` are
    drawn until one has IoU at least the mode's value with some box and contains at least one box
    centre. Boxes whose centre lies in the window are kept, clipped and shifted; the others dropped.
    When no window qualifies the sample is returned unchanged."""

    def __init__(self, scale: tuple[float, float] = (0.3, 1.0), aspect_ratio: tuple[float, float] = (0.5, 2.0),
                 trials: int = 50, min_ious=CROP_MIN_IOUS, seed=None, name: str | None = None):
        super().__init__(seed, name)
        if not 0 < scale[0] <= scale[1] <= 1:
            raise ValueError(f"scale: expected 0 < lower <= upper <= 1, got {scale}")
        if not 0 < aspect_ratio[0] <= aspect_ratio[1]:
            raise ValueError(f"aspect_ratio: expected 0 < lower <= upper, got {aspect_ratio}")
        self.scale, self.aspect_ratio, self.trials = tuple(scale), tuple(aspect_ratio), int(trials)
        self.min_ious = tuple(min_ious)

    def call(self, sample: AnnotatedImage) -> AnnotatedImage:
        draw = self.generator
        min_iou = self.min_ious[int(draw.integers(len(self.min_ious)))]
        if min_iou is None or len(sample.boxes) == 0:
            return sample
        height, width = sample.image.shape[:2]
        centres = 0.5 * (sample.boxes[:, :2] + sample.boxes[:, 2:])
        for _ in range(self.trials):
            crop_width = draw.uniform(*self.scale) * width
            crop_height = draw.uniform(*self.scale) * height
            if not self.aspect_ratio[0] <= crop_width / crop_height <= self.aspect_ratio[1]:
                continue
            left = draw.uniform(0, width - crop_width)
            top = draw.uniform(0, height - crop_height)
            window = np.floor([left, top, left + crop_width, top + crop_height])
            if window[2] - window[0] < 1 or window[3] - window[1] < 1:
                continue
            if boxes_backend.iou_matrix(window[None], sample.boxes).max() < min_iou:
                continue
            inside = np.all((centres > window[:2]) & (centres < window[2:]), axis=1)
            if not np.any(inside):
                continue
            x0, y0, x1, y1 = window.astype(int)
            kept = sample.boxes[inside] - np.array([x0, y0, x0, y0], np.float64)
            kept = boxes_backend.clip(kept, (x1 - x0, y1 - y0))
            return AnnotatedImage(np.ascontiguousarray(sample.image[y0:y1, x0:x1]), kept, sample.class_ids[inside])
        return sample


class RandomScaleCrop(RandomProcessor):
    """A ``size × size`` window of the image rescaled by a factor log-uniform in ``scale``: a detector
    trained on these sees the objects near their size in the whole images it will run on (at the
    factor's geometric mean), where resizing whole images to a small square would shrink them. Where the
    rescaled image is smaller than the window, it lies at a random place on a ``fill`` canvas. Boxes
    whose centre lies in the window are kept, clipped and shifted; the others are dropped."""

    def __init__(self, size: int, scale: tuple[float, float] = (0.7, 1.43), fill=FILL, seed=None,
                 name: str | None = None):
        super().__init__(seed, name)
        if int(size) < 1:
            raise ValueError(f"size: expected a positive window side in pixels, got {size}")
        if not 0 < scale[0] <= scale[1]:
            raise ValueError(f"scale: expected 0 < lower <= upper, got {scale}")
        self.size, self.scale = int(size), (float(scale[0]), float(scale[1]))
        self.fill = np.asarray(fill, dtype=np.uint8).reshape(3)

    def call(self, sample: AnnotatedImage) -> AnnotatedImage:
        factor = float(np.exp(self.generator.uniform(np.log(self.scale[0]), np.log(self.scale[1]))))
        height, width = sample.image.shape[:2]
        scaled_width, scaled_height = max(1, round(width * factor)), max(1, round(height * factor))
        image = image_backend.resize(sample.image, (scaled_width, scaled_height))
        boxes = sample.boxes * np.array([scaled_width / width, scaled_height / height] * 2)
        # window origin in the rescaled image (negative: the image starts inside the window)
        left = int(self.generator.integers(min(0, scaled_width - self.size), max(0, scaled_width - self.size) + 1))
        top = int(self.generator.integers(min(0, scaled_height - self.size), max(0, scaled_height - self.size) + 1))
        canvas = np.empty((self.size, self.size, 3), np.uint8)
        canvas[:] = self.fill
        x0, y0 = max(left, 0), max(top, 0)
        x1, y1 = min(left + self.size, scaled_width), min(top + self.size, scaled_height)
        canvas[y0 - top:y1 - top, x0 - left:x1 - left] = image[y0:y1, x0:x1]
        boxes = boxes - np.array([left, top, left, top], np.float64)
        centres = 0.5 * (boxes[:, :2] + boxes[:, 2:])
        inside = np.all((centres > 0) & (centres < self.size), axis=1)
        kept = boxes_backend.clip(boxes[inside], (self.size, self.size))
        return AnnotatedImage(canvas, kept, sample.class_ids[inside])


class RandomFlip(RandomProcessor):
    """Mirrors the image and its boxes left-right with ``probability``."""

    def __init__(self, probability: float = 0.5, seed=None, name: str | None = None):
        super().__init__(seed, name)
        self.probability = float(probability)

    def call(self, sample: AnnotatedImage) -> AnnotatedImage:
        if self.generator.random() >= self.probability:
            return sample
        width = sample.image.shape[1]
        return AnnotatedImage(image_backend.flip_left_right(sample.image),
                              boxes_backend.flip_left_right(sample.boxes, width), sample.class_ids)


def ssd_augmentation(expand_ratio: float = 4.0, expand_probability: float = 0.5, flip: bool = True,
                     white_balance: float = 0.0, grayscale: float = 0.0, scale_crops: tuple | None = None,
                     crop_size: int = 0, seed=None) -> SequentialProcessor:
    """The paper's chain: ``photometric`` → ``expand`` → ``crop`` → ``flip`` (named steps), with a
    ``white_balance`` step (:class:`WhiteBalance` of that strength) and a ``grayscale`` step
    (:class:`Grayscale` with that probability) after ``photometric`` when they are positive. With
    ``scale_crops`` (a factor range), ``expand`` and SSD's ``crop`` give way to ``flip`` then
    :class:`RandomScaleCrop` windows of ``crop_size`` (named ``crop``)."""
    steps = [PhotometricDistortion(name="photometric")]
    if white_balance > 0:
        steps.append(WhiteBalance(white_balance, name="white_balance"))
    if grayscale > 0:
        steps.append(Grayscale(grayscale, name="grayscale"))
    if scale_crops is not None:
        steps += [RandomFlip(name="flip")] if flip else []
        steps.append(RandomScaleCrop(crop_size, tuple(scale_crops), name="crop"))
    else:
        steps += [Expand(expand_ratio, expand_probability, name="expand"), RandomSampleCrop(name="crop")]
        steps += [RandomFlip(name="flip")] if flip else []
    chain = SequentialProcessor(steps, name="ssd_augmentation")
    if seed is not None:
        reseed(chain, seed)
    return chain
