"""Colour adjustments of paz6d.backend.image (256-entry tables) against the per-pixel float rules, same run.

Usage: ``.venv/bin/python benchmarks/photometric.py [--size 640x480] [--repeats 30]``

Each adjustment runs ``repeats`` times alternating with the obvious numpy version (the image to float32,
the rule per pixel, rounded and clipped back to uint8, HSV through OpenCV as paz6d does); the best time of
each is reported with the ratio numpy / paz6d (> 1: paz6d is faster). These are the photometric
distortions of SSD's training augmentation (:mod:`paz6d.synthesis.box_augment`), run on every image.
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np
from backend import best_times

from paz6d.backend import image


def _uint8(values: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(values), 0, 255).astype(np.uint8)


def brightness(picture: np.ndarray, delta: float) -> np.ndarray:
    return _uint8(picture.astype(np.float32) + np.float32(delta))


def contrast(picture: np.ndarray, factor: float) -> np.ndarray:
    values = picture.astype(np.float32)
    mean = values.mean(axis=(0, 1), keepdims=True)
    return _uint8((values - mean) * np.float32(factor) + mean)


def saturation(picture: np.ndarray, factor: float) -> np.ndarray:
    hsv = cv2.cvtColor(picture, cv2.COLOR_RGB2HSV_FULL).astype(np.float32)
    hsv[..., 1] = np.clip(hsv[..., 1] * np.float32(factor), 0, 255)
    return cv2.cvtColor(_uint8(hsv), cv2.COLOR_HSV2RGB_FULL)


def hue(picture: np.ndarray, degrees: float) -> np.ndarray:
    hsv = cv2.cvtColor(picture, cv2.COLOR_RGB2HSV)
    hsv[..., 0] = np.mod(np.rint(hsv[..., 0].astype(np.float32) + np.float32(degrees / 2.0)), 180).astype(np.uint8)
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="640x480", help="image size WxH")
    parser.add_argument("--repeats", type=int, default=30)
    args = parser.parse_args()
    width, height = (int(side) for side in args.size.split("x"))
    picture = np.random.default_rng(0).integers(0, 256, (height, width, 3), dtype=np.uint8)
    print(f"{width}x{height} RGB, best of {args.repeats}")
    print(f"{'adjustment':24s} {'paz6d (ms)':>11s} {'numpy (ms)':>11s} {'numpy/paz6d':>12s} {'max diff':>9s}")
    for name, ours, theirs, amount in (("brightness +20", image.adjust_brightness, brightness, 20.0),
                                       ("contrast x1.3", image.adjust_contrast, contrast, 1.3),
                                       ("saturation x1.2", image.adjust_saturation, saturation, 1.2),
                                       ("hue +12 deg", image.adjust_hue, hue, 12.0)):
        difference = np.abs(ours(picture, amount).astype(int) - theirs(picture, amount)).max()
        ours_time, theirs_time = best_times(lambda: ours(picture, amount), lambda: theirs(picture, amount),
                                            args.repeats)
        print(f"{name:24s} {1000 * ours_time:11.2f} {1000 * theirs_time:11.2f} {theirs_time / ours_time:11.1f}x "
              f"{difference:9d}")


if __name__ == "__main__":
    main()
