"""Silhouette anti-aliasing for single-sample renders: fractional coverage at object edges.

A single-sample pass decides each pixel by its centre, so the object's outline is a binary
staircase. :func:`soften_silhouette` replaces it by a coverage estimate: the binary coverage
filtered with a 3×3 tent kernel (weights 1-2-1 per axis). For a straight, axis-aligned edge this
gives 3/4 to the pixel just inside and 1/4 to the one just outside, the mean true coverage of
such pixels. Colour on the band is the coverage-weighted mean of the object colours around it
(normalized convolution), so the pixels outside the old outline take the object's colour, not
the background's. Interior pixels and edges between two objects are left as they are.
"""

from __future__ import annotations

import cv2
import numpy as np

from paz6d.backend.image import nonzero_window

_TENT = np.array([0.25, 0.5, 0.25], dtype=np.float32)


def soften_silhouette(rgb: np.ndarray, alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Anti-aliased ``(rgb, alpha)`` from a single-sample render.

    Args:
        rgb: ``(H, W, 3)`` uint8 colour of the render.
        alpha: ``(H, W)`` uint8 binary coverage (0 or 255).

    Returns:
        ``(rgb, alpha)``, new uint8 arrays: ``alpha`` in 0..255 on a 1-pixel band each side of
        the outline, ``rgb`` there the coverage-weighted object colour.
    """
    rgb, alpha = rgb.copy(), alpha.copy()
    window = nonzero_window(alpha, margin=1)  # the band reaches one pixel beyond the outline
    if window is None:
        return rgb, alpha
    coverage = alpha[window].astype(np.float32) / 255.0
    soft = cv2.sepFilter2D(coverage, -1, _TENT, _TENT, borderType=cv2.BORDER_REPLICATE)
    weighted = cv2.sepFilter2D(rgb[window].astype(np.float32) * coverage[..., None], -1, _TENT, _TENT,
                               borderType=cv2.BORDER_REPLICATE)
    band = (soft > 1e-6) & (soft < 1 - 1e-6)
    colour = weighted[band] / soft[band][:, None]
    rgb[window][band] = np.clip(np.rint(colour), 0, 255).astype(np.uint8)
    alpha[window][band] = np.clip(np.rint(soft[band] * 255.0), 0, 255).astype(np.uint8)
    return rgb, alpha
