"""Cluttered, translated and scaled digits from scikit-learn's bundled 8×8 digits (nothing downloaded).

Each sample is a square grey canvas (values in [0, 1]) holding one 8×8 digit of ``load_digits``
enlarged to a random side (``scale`` pixels, bilinear) at a random position, over ``clutter``
fragments: random ``fragment_size``-pixel square windows of *other* digits enlarged the same way,
placed anywhere (composited with ``max``), as in Jaderberg et al.'s cluttered MNIST (6×6 pieces). The 1,797 digits are
split once into train and test digits
(``test_fraction``, seeded), and a split's canvases draw both the digit and the clutter from that
split only, so no test digit is ever seen in training.

Sample ``i`` of stream ``s`` (0 = train, 1 = test) is drawn from ``default_rng([seed, s, i])``: the
same canvases for any batch size or number of workers.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import lru_cache

import cv2
import numpy as np

CLASS_NAMES = tuple(str(digit) for digit in range(10))
TRAIN, TEST = 0, 1


@dataclass(frozen=True)
class DigitCanvas:
    """How canvases are drawn.

    Attributes:
        canvas_size: side of the square canvas in pixels.
        scale: range of the digit's side in pixels (the 8×8 digit enlarged to it).
        clutter: number of clutter fragments per canvas.
        fragment_size: side of a clutter fragment in canvas pixels.
        test_fraction: share of the 1,797 digits kept for testing.
        split_seed: seed of the train/test split of the digits.
    """

    canvas_size: int = 48
    scale: tuple[float, float] = (12.0, 24.0)
    clutter: int = 6
    fragment_size: int = 6
    test_fraction: float = 0.2
    split_seed: int = 0

    def __post_init__(self):
        low, high = self.scale
        if int(self.canvas_size) < 16:
            raise ValueError(f"canvas_size: expected at least 16 pixels, got {self.canvas_size}")
        if not 4.0 <= low <= high <= self.canvas_size:
            raise ValueError(f"scale: expected 4 <= low <= high <= canvas_size={self.canvas_size} pixels, "
                             f"got {self.scale}")
        if int(self.clutter) < 0:
            raise ValueError(f"clutter: expected a non-negative number of fragments, got {self.clutter}")
        if not 1 <= int(self.fragment_size) <= low:
            raise ValueError(f"fragment_size: expected 1 to the smallest digit side {low} pixels, got "
                             f"{self.fragment_size}")
        if not 0.0 < self.test_fraction < 1.0:
            raise ValueError(f"test_fraction: expected a fraction in (0, 1), got {self.test_fraction}")

    def to_dict(self) -> dict:
        data = asdict(self)
        data["scale"] = list(self.scale)
        return data

    @classmethod
    def from_dict(cls, data: dict) -> "DigitCanvas":
        data = dict(data)
        data["scale"] = tuple(data["scale"])
        return cls(**data)


@lru_cache(maxsize=1)
def load_digit_images() -> tuple[np.ndarray, np.ndarray]:
    """scikit-learn's bundled digits: ``images (1797, 8, 8) float32`` in [0, 1] and ``labels (1797,) int64``.

    Raises:
        ValueError: scikit-learn is not installed.
    """
    try:
        from sklearn.datasets import load_digits  # here: scikit-learn is heavy and only needed for the data
    except ImportError:
        raise ValueError("scikit-learn is needed for the digits data set (`pip install scikit-learn`)") from None
    digits = load_digits()
    images = (np.asarray(digits.images, dtype=np.float32) / 16.0).clip(0.0, 1.0)
    return images, np.asarray(digits.target, dtype=np.int64)


def split_indices(count: int, test_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Disjoint sorted ``(train, test)`` index arrays of ``count`` samples (``test_fraction`` of them for testing)."""
    order = np.random.default_rng(seed).permutation(count)
    test_count = max(1, int(round(count * test_fraction)))
    if test_count >= count:
        raise ValueError(f"test_fraction: leaves no training samples of {count} ({test_fraction})")
    return np.sort(order[test_count:]), np.sort(order[:test_count])


class ClutteredDigits:
    """Train and test canvases of the digits (see the module docstring).

    Args:
        settings: :class:`DigitCanvas`.
        images, labels: the digits (default: :func:`load_digit_images`).
    """

    def __init__(self, settings: DigitCanvas = DigitCanvas(), images: np.ndarray | None = None,
                 labels: np.ndarray | None = None):
        if images is None or labels is None:
            images, labels = load_digit_images()
        images, labels = np.asarray(images, np.float32), np.asarray(labels, np.int64)
        if images.ndim != 3 or images.shape[1:] != (8, 8) or labels.shape != (len(images),):
            raise ValueError(f"images/labels: expected (N, 8, 8) digits and (N,) labels, got {images.shape} "
                             f"and {labels.shape}")
        self.settings, self.images, self.labels = settings, images, labels
        self.splits = split_indices(len(images), settings.test_fraction, settings.split_seed)

    def sample(self, stream: int, index: int, seed: int) -> tuple[np.ndarray, int, np.ndarray]:
        """One canvas: ``image (S, S) float32`` in [0, 1], its label and the digit's box ``(4,)``
        ``(x_min, y_min, x_max, y_max)`` pixels."""
        if stream not in (TRAIN, TEST):
            raise ValueError(f"stream: expected {TRAIN} (train) or {TEST} (test), got {stream}")
        rng = np.random.default_rng([seed, stream, index])
        pool = self.splits[stream]
        size = int(self.settings.canvas_size)
        canvas = np.zeros((size, size), np.float32)
        digit = int(pool[rng.integers(len(pool))])
        piece = int(self.settings.fragment_size)
        for _ in range(int(self.settings.clutter)):
            other = int(pool[rng.integers(len(pool))])
            side = int(round(rng.uniform(*self.settings.scale)))
            enlarged = cv2.resize(self.images[other], (side, side), interpolation=cv2.INTER_LINEAR)
            row, column = rng.integers(0, side - piece + 1, 2)
            top, left = rng.integers(0, size - piece + 1, 2)
            window = canvas[top:top + piece, left:left + piece]
            canvas[top:top + piece, left:left + piece] = np.maximum(window,
                                                                    enlarged[row:row + piece, column:column + piece])
        side = int(round(rng.uniform(*self.settings.scale)))
        patch = cv2.resize(self.images[digit], (side, side), interpolation=cv2.INTER_LINEAR)
        top, left = rng.integers(0, size - side + 1, 2)
        canvas[top:top + side, left:left + side] = np.maximum(canvas[top:top + side, left:left + side], patch)
        box = np.array([left, top, left + side, top + side], np.float32)
        return canvas.clip(0.0, 1.0), int(self.labels[digit]), box

    def batch(self, stream: int, start: int, count: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Samples ``start .. start + count - 1`` of a stream: ``images (B, S, S, 1) float32``,
        ``labels (B,) int64`` and ``boxes (B, 4)``."""
        if int(count) < 1:
            raise ValueError(f"count: expected a positive number of samples, got {count}")
        samples = [self.sample(stream, start + offset, seed) for offset in range(int(count))]
        return (np.stack([image for image, _, _ in samples])[..., None],
                np.array([label for _, label, _ in samples], np.int64), np.stack([box for _, _, box in samples]))
