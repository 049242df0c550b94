"""Data-set file output: image encoder settings and clean-up of a killed run's temporaries (atomic writers in
:mod:`paz6d.backend.files`)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from paz6d.backend.files import TEMPORARY_PREFIX
from paz6d.backend.image import encode_image

#: PNG settings (zlib level 1, run-length strategy; deterministic output). On rendered images with sensor
#: noise the "sub" row filter gives smaller RGB files than OpenCV's default filters in less time; masks, which
#: are runs of 0 and 255, compress best unfiltered (``benchmarks/generate.py`` times the whole writer).
_PNG_ZLIB = [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE]
PNG_PARAMETERS = _PNG_ZLIB + [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_SUB]
MASK_PNG_PARAMETERS = _PNG_ZLIB + [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE]
JPEG_PARAMETERS = [cv2.IMWRITE_JPEG_QUALITY, 95]


def image_bytes(image: np.ndarray, image_format: str = "png") -> bytes:
    """``png`` or ``jpg`` file bytes of uint8 RGB ``(H, W, 3)``, uint8/uint16 ``(H, W)`` or bool
    ``(H, W)`` (written as {0, 255}) with the data set's encoder settings."""
    if image_format != "png":
        return encode_image(image, "." + image_format, JPEG_PARAMETERS)
    return encode_image(image, ".png", MASK_PNG_PARAMETERS if image.dtype == bool else PNG_PARAMETERS)


def remove_stale_temporaries(root: Path) -> int:
    """Deletes temporary files left by a killed run under ``root``; returns how many."""
    count = 0
    for path in root.rglob(TEMPORARY_PREFIX + "*"):
        path.unlink(missing_ok=True)
        count += 1
    return count
