"""Training pairs for the Augmented Autoencoder: (augmented input crop, clean target crop).

From a pool of clean on-axis views (:mod:`paz6d.aae.views`) a sample picks a view and an
in-plane angle, rotates the view about the principal point, and makes

* the target: :func:`paz6d.aae.model.crop_object` of the clean view (object on black) around its box;
* the input: the object re-lit (per-channel gains, brightness gradient), composited over a random
  procedural background (:class:`paz6d.synthesis.backgrounds.BackgroundBank`, ``"clutter"`` style),
  cropped around a shifted and rescaled box, then (:func:`input_augmentation`, a sequence of
  :mod:`paz6d.synthesis` processors) partly covered by random occluders and colour-jittered (brightness,
  contrast, saturation, hue), blurred and noised.

Every batch is a pure function of ``(seed, step)``, so training resumes on the same data stream.
"""

from __future__ import annotations

import numpy as np

from paz6d.aae.config import Augmentation
from paz6d.aae.model import crop_object
from paz6d.aae.views import coverage_box, rotate_view
from paz6d.abstract.processor import SequentialProcessor
from paz6d.synthesis.augment import (RandomContrastBrightnessNoise, RandomGaussianBlur, RandomHue, RandomSaturation,
                                     relight, share_generator)
from paz6d.synthesis.backgrounds import BackgroundBank
from paz6d.synthesis.occluders import PolygonOccluders


def input_augmentation(augmentation: Augmentation, padding: float) -> SequentialProcessor:
    """What is done to an input crop (object side = crop side / ``padding``) once it is composited:
    random polygon occluders, then the photometric jitter: saturation, hue (when ``hue > 0``), blur
    (sigma 0.4-1.2 px) with ``blur_probability``, then contrast, brightness and noise in float."""
    a = augmentation
    steps = [PolygonOccluders(a.occlusion_probability, a.max_occluders, a.occluder_size, padding, name="occlude"),
             RandomSaturation(*a.saturation)] + ([RandomHue(a.hue)] if a.hue > 0 else [])
    steps += [RandomGaussianBlur((0,), a.blur_probability, sigma=(0.4, 1.2)),
              RandomContrastBrightnessNoise(a.contrast, a.brightness, a.noise)]
    return SequentialProcessor(steps, name="input augmentation")


class ViewSampler:
    """Makes augmented/clean crop pairs from a pool of clean views.

    Args:
        rgb: ``(V, S, S, 3)`` uint8 views on black.
        alpha: ``(V, S, S)`` uint8 coverage.
        K: ``(3, 3)`` intrinsics of the views (principal point = image centre, fx = fy).
        crop_size: side of the crops in pixels.
        padding: crop side / longest box side.
        augmentation: input augmentation strengths.
        seed: base seed of the data stream.
        background_bank: number of procedural backgrounds made once and reused (random crops/flips).
        pairs: optional :class:`~paz6d.aae.dataset.CropPairs` from a data set (input crops of real
            or generated images, clean rendered targets); drawn with probability ``pair_fraction`` and
            then occluded and colour-jittered like the rendered views.
        pair_fraction: share of samples taken from ``pairs``.
    """

    def __init__(self, rgb: np.ndarray, alpha: np.ndarray, K: np.ndarray, crop_size: int, padding: float,
                 augmentation: Augmentation = Augmentation(), seed: int = 0, background_bank: int = 128,
                 pairs=None, pair_fraction: float = 0.5):
        if rgb.ndim != 4 or rgb.shape[-1] != 3 or alpha.shape != rgb.shape[:3]:
            raise ValueError(f"rgb/alpha: expected (V, S, S, 3) and (V, S, S), got {rgb.shape} and {alpha.shape}")
        if len(rgb) == 0:
            raise ValueError("rgb: the view pool is empty")
        if pairs is not None and pairs.inputs.shape[1:3] != (crop_size, crop_size):
            raise ValueError(f"pairs: expected {crop_size}x{crop_size} crops, got {pairs.inputs.shape[1:3]}")
        if not 0.0 <= pair_fraction <= 1.0:
            raise ValueError(f"pair_fraction: expected a fraction in [0, 1], got {pair_fraction}")
        self.pairs, self.pair_fraction = pairs, (pair_fraction if pairs is not None else 0.0)
        self.rgb, self.alpha, self.K = rgb, alpha, np.asarray(K, dtype=np.float64)
        self.crop_size, self.padding, self.augmentation, self.seed = int(crop_size), float(padding), augmentation, seed
        self.backgrounds = BackgroundBank(self.crop_size, background_bank if augmentation.backgrounds else 0,
                                          np.random.default_rng([seed, 7919]), style="clutter")
        self.input_augmentation = input_augmentation(augmentation, self.padding)

    def _augment(self, crop: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        share_generator(self.input_augmentation, rng)
        return self.input_augmentation(crop)

    def sample(self, rng: np.random.Generator, view: int | None = None,
               angle: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """One ``(input, target)`` pair of uint8 crops ``(crop_size, crop_size, 3)``."""
        if view is None and angle is None and self.pair_fraction and rng.random() < self.pair_fraction:
            index = int(rng.integers(len(self.pairs)))
            return self._augment(self.pairs.inputs[index], rng), self.pairs.targets[index]
        view = int(rng.integers(len(self.rgb))) if view is None else view
        angle = float(rng.uniform(0, 2 * np.pi)) if angle is None else angle
        rgb, alpha = rotate_view(self.rgb[view], self.alpha[view], angle, self.K)
        box = coverage_box(alpha)
        if box is None:
            raise ValueError(f"view {view}: the object is not visible in the rendering")
        target = crop_object(rgb, box, self.crop_size, self.padding)
        a = self.augmentation
        centre = 0.5 * (box[:2] + box[2:]) + rng.uniform(-a.shift, a.shift, 2) * max(box[2:] - box[:2])
        extent = (box[2:] - box[:2]) * rng.uniform(*a.scale)
        shifted = np.concatenate([centre - extent / 2, centre + extent / 2])
        rgba = crop_object(np.dstack([rgb, alpha]), shifted, self.crop_size, self.padding)
        weight = rgba[..., 3:].astype(np.float32) / 255.0
        lit = relight(rgba[..., :3], rng, self.augmentation.light, self.padding)
        composited = np.clip(weight * lit + (1 - weight) * self.backgrounds.patch(rng), 0, 255).astype(np.uint8)
        return self._augment(composited, rng), target

    def batch(self, step: int, batch_size: int) -> tuple[np.ndarray, np.ndarray]:
        """Batch number ``step``: float32 ``(inputs, targets)`` of shape ``(B, S, S, 3)`` in [0, 1]."""
        rng = np.random.default_rng([self.seed, int(step)])
        pairs = [self.sample(rng) for _ in range(batch_size)]
        inputs = np.stack([pair[0] for pair in pairs]).astype(np.float32) / 255.0
        targets = np.stack([pair[1] for pair in pairs]).astype(np.float32) / 255.0
        return inputs, targets
