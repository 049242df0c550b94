"""Keypoint heatmaps (numpy, light): Gaussian targets and decoding with sub-pixel refinement.

Heatmap cell ``(row, col)`` of a stride-``s`` map covers crop pixels ``[col*s, (col+1)*s)``; with the
pixel-centre convention (pixel ``j`` is at ``u = j``) its centre is at ``u = col*s + (s - 1)/2``, as in
:func:`paz6d.keypointnet.model.cell_centres`. Maps are ``(B, h, w, N)`` (one channel per keypoint).

A map is either *log-domain* (logits of a spatial softmax, or log-probabilities: a Gaussian is a
quadratic there) or *value-domain* (HRNet's maps regressed to a Gaussian of peak 1). Decoders:

- ``"quadratic"``: the most likely cell, refined by one Newton step on the log-map
  (second-order Taylor expansion from central differences, as DARK, Zhang et al. CVPR 2020): exact
  for a Gaussian away from the border;
- ``"quarter"``: the most likely cell, moved a quarter cell towards the larger neighbour on each axis
  (the classic HRNet/SimpleBaselines decoding);
- ``"soft_argmax"`` (:data:`DEFAULT_DECODER`): the expectation over the 5×5 cells around the peak
  (probabilities renormalised; :func:`paz6d.keypointnet.keypoints.local_expectation`). Slightly biased
  for an ideal Gaussian (the window truncates it), but the most accurate on the trained quick network's
  maps, which are not exact Gaussians (docs/hrnet.md: PCK@0.05 93.6 % vs 91.9 % for ``"quadratic"``);
- ``"argmax"``: the most likely cell's centre.
"""

from __future__ import annotations

import numpy as np

from paz6d.keypointnet.keypoints import local_expectation

DECODERS = ("quadratic", "quarter", "soft_argmax", "argmax")
#: The decoder the pipeline and the headline evaluation use.
DEFAULT_DECODER = "soft_argmax"
DOMAINS = ("log", "value")
#: Value-domain maps are clipped to at least this before taking their logarithm.
MIN_VALUE = 1e-6


def _check_maps(heatmaps, name: str = "heatmaps") -> np.ndarray:
    maps = np.asarray(heatmaps, dtype=np.float64)
    if maps.ndim != 4 or min(maps.shape[1:]) < 1:
        raise ValueError(f"{name}: expected shape (B, h, w, N), got {maps.shape}")
    if not np.all(np.isfinite(maps)):
        raise ValueError(f"{name}: expected finite values")
    return maps


def cell_centres(count: int, stride: int) -> np.ndarray:
    """Crop-pixel coordinates ``(count,)`` of the centres of ``count`` cells of a stride-``stride`` map."""
    if count < 1 or stride < 1:
        raise ValueError(f"count/stride: expected positive integers, got {count}, {stride}")
    return np.arange(count, dtype=np.float64) * stride + (stride - 1) / 2.0


def gaussian_heatmaps(uv, height: int, width: int, stride: int, sigma: float) -> np.ndarray:
    """Gaussians of peak 1 ``(B, height, width, N)`` float64 centred at keypoints ``uv (B, N, 2)`` (crop pixels).

    Args:
        sigma: standard deviation in heatmap cells.
    """
    uv = np.asarray(uv, dtype=np.float64)
    if uv.ndim != 3 or uv.shape[-1] != 2:
        raise ValueError(f"uv: expected shape (B, N, 2), got {uv.shape}")
    if not sigma > 0:
        raise ValueError(f"sigma: expected a positive width in heatmap cells, got {sigma}")
    u = cell_centres(width, stride)
    v = cell_centres(height, stride)
    du = (u[None, None, :, None] - uv[:, None, None, :, 0]) / stride
    dv = (v[None, :, None, None] - uv[:, None, None, :, 1]) / stride
    return np.exp(-(du ** 2 + dv ** 2) / (2.0 * sigma ** 2))


def log_maps(heatmaps, domain: str) -> np.ndarray:
    """Log-domain maps ``(B, h, w, N)``: log-domain input unchanged, value-domain input ``log(max(x, 1e-6))``."""
    maps = _check_maps(heatmaps)
    if domain == "log":
        return maps
    if domain == "value":
        return np.log(np.maximum(maps, MIN_VALUE))
    raise ValueError(f"domain: expected one of {DOMAINS}, got {domain!r}")


def _softmax(logits: np.ndarray) -> np.ndarray:
    batch, height, width, count = logits.shape
    flat = logits.reshape(batch, height * width, count)
    flat = np.exp(flat - flat.max(axis=1, keepdims=True))
    return (flat / flat.sum(axis=1, keepdims=True)).reshape(logits.shape)


def _peaks(maps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns ``(B, N)`` of each map's maximum."""
    batch, height, width, count = maps.shape
    flat = maps.transpose(0, 3, 1, 2).reshape(batch, count, height * width)
    return np.divmod(flat.argmax(axis=-1), width)


def _neighbours(maps: np.ndarray, rows: np.ndarray, columns: np.ndarray, dr: int, dc: int) -> np.ndarray:
    """``maps[b, rows + dr, columns + dc, n]`` ``(B, N)``, clamped to the map."""
    batch, height, width, count = maps.shape
    b, n = np.meshgrid(np.arange(batch), np.arange(count), indexing="ij")
    return maps[b, np.clip(rows + dr, 0, height - 1), np.clip(columns + dc, 0, width - 1), n]


def quadratic_offsets(log_heatmaps, rows, columns) -> np.ndarray:
    """Sub-cell offsets ``(B, N, 2)`` (cells, ``(du, dv)``) of each log-map's extremum near ``(rows, columns)``.

    One Newton step ``-H⁻¹ g`` with the gradient and Hessian from central differences; along an axis
    where the peak touches the border, or where the map is not concave, that axis is not moved. Offsets
    are clipped to ±1 cell.
    """
    maps = np.asarray(log_heatmaps, dtype=np.float64)
    _, height, width, _ = maps.shape
    rows, columns = np.asarray(rows), np.asarray(columns)

    def at(dr, dc):
        return _neighbours(maps, rows, columns, dr, dc)

    centre = at(0, 0)
    gu, gv = (at(0, 1) - at(0, -1)) / 2.0, (at(1, 0) - at(-1, 0)) / 2.0
    huu, hvv = at(0, 1) - 2 * centre + at(0, -1), at(1, 0) - 2 * centre + at(-1, 0)
    huv = (at(1, 1) - at(1, -1) - at(-1, 1) + at(-1, -1)) / 4.0
    inside_u = (columns >= 1) & (columns <= width - 2)
    inside_v = (rows >= 1) & (rows <= height - 2)
    determinant = huu * hvv - huv ** 2
    joint = inside_u & inside_v & (huu < 0) & (determinant > 1e-12)
    with np.errstate(divide="ignore", invalid="ignore"):
        du = np.where(joint, -(hvv * gu - huv * gv) / determinant,
                      np.where(inside_u & (huu < 0), -gu / huu, 0.0))
        dv = np.where(joint, -(huu * gv - huv * gu) / determinant,
                      np.where(inside_v & (hvv < 0), -gv / hvv, 0.0))
    offsets = np.stack([du, dv], axis=-1)
    return np.clip(np.nan_to_num(offsets, nan=0.0, posinf=0.0, neginf=0.0), -1.0, 1.0)


def decode_heatmaps(heatmaps, stride: int, method: str = DEFAULT_DECODER, domain: str = "log",
                    sigma: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Keypoints from heatmaps.

    Args:
        heatmaps: ``(B, h, w, N)`` maps (see the module docstring for ``domain``).
        stride: crop pixels per heatmap cell.
        method: one of :data:`DECODERS`.
        domain: ``"log"`` (softmax logits) or ``"value"`` (regressed Gaussians of peak 1).
        sigma: the training Gaussian's width in cells; with ``domain="log"`` the score is then the
            peak probability × ``2π sigma²`` (about 1 for a perfect Gaussian).
    Returns:
        ``uv (B, N, 2)`` in crop pixels and ``scores (B, N)``: the peak value (value domain), the peak
        probability of the spatial softmax (log domain; scaled as above when ``sigma`` is given).
    Raises:
        ValueError: wrong shapes, non-finite maps, unknown method/domain.
    """
    if method not in DECODERS:
        raise ValueError(f"method: expected one of {DECODERS}, got {method!r}")
    if int(stride) < 1:
        raise ValueError(f"stride: expected a positive number of pixels per cell, got {stride}")
    stride = int(stride)
    logs = log_maps(heatmaps, domain)
    rows, columns = _peaks(logs)
    offset = (stride - 1) / 2.0
    if domain == "log":
        probabilities = _softmax(logs)
        scores = _neighbours(probabilities, rows, columns, 0, 0) * (1.0 if sigma is None else 2 * np.pi * sigma ** 2)
    else:
        probabilities = np.maximum(_check_maps(heatmaps), 0.0)
        scores = _neighbours(_check_maps(heatmaps), rows, columns, 0, 0)
    if method == "soft_argmax":
        if domain == "value" and not np.all(probabilities.reshape(len(logs), -1, logs.shape[-1]).sum(axis=1) > 0):
            probabilities = probabilities + 1e-12  # an all-zero map: the plain window mean
        return local_expectation(probabilities, stride), scores
    cells = np.stack([columns, rows], axis=-1).astype(np.float64)
    if method == "quadratic":
        cells = cells + quadratic_offsets(logs, rows, columns)
    elif method == "quarter":
        du = np.sign(_neighbours(logs, rows, columns, 0, 1) - _neighbours(logs, rows, columns, 0, -1))
        dv = np.sign(_neighbours(logs, rows, columns, 1, 0) - _neighbours(logs, rows, columns, -1, 0))
        cells = cells + 0.25 * np.stack([du, dv], axis=-1)
    return cells * stride + offset, scores
