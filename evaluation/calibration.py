"""Calibration of predicted 2D Gaussian uncertainties: how often the truth falls inside the ellipses.

A prediction is a mean ``μ`` and a covariance ``Σ`` (pixels²) per keypoint; the squared Mahalanobis
distance of the true keypoint ``x`` is ``d² = (x − μ)ᵀ Σ⁻¹ (x − μ)``. If the predicted Gaussians were
right, ``d²`` would follow a χ² distribution with 2 degrees of freedom, so the truth would lie inside
the ``k``-σ ellipse (``d ≤ k``) with probability ``1 − exp(−k² / 2)``: 39.35 % for 1σ, 86.47 % for 2σ,
98.89 % for 3σ. :func:`ellipse_coverage` measures those fractions; coverage below the expected value
means over-confident covariances, above it under-confident ones.

Example:
    >>> result = ellipse_coverage(true_uv, predicted_uv, covariances)          # doctest: +SKIP
    >>> result.observed[1], result.expected[1]                                # doctest: +SKIP
    (0.41, 0.3935)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from paz6d.backend.files import new_figure, save_figure_atomically

#: Ellipse sizes (standard deviations) reported by default.
LEVELS = (1.0, 2.0, 3.0)


def expected_coverage(level: float) -> float:
    """Probability that a 2D Gaussian sample lies within ``level`` standard deviations (Mahalanobis):
    ``1 − exp(−level² / 2)``."""
    return float(1.0 - np.exp(-0.5 * float(level) ** 2))


def _checked(points, means, covariances) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    points = np.asarray(points, dtype=np.float64)
    means = np.asarray(means, dtype=np.float64)
    covariances = np.asarray(covariances, dtype=np.float64)
    if points.ndim < 1 or points.shape[-1] != 2:
        raise ValueError(f"points: expected (..., 2) pixel coordinates, got shape {points.shape}")
    if means.shape != points.shape:
        raise ValueError(f"means: expected the shape of points {points.shape}, got {means.shape}")
    if covariances.shape != points.shape + (2,):
        raise ValueError(f"covariances: expected shape {points.shape + (2,)} (a 2x2 matrix per point), "
                         f"got {covariances.shape}")
    for name, values in (("points", points), ("means", means), ("covariances", covariances)):
        if not np.all(np.isfinite(values)):
            raise ValueError(f"{name}: expected finite values, got NaN or infinity")
    determinant = covariances[..., 0, 0] * covariances[..., 1, 1] - covariances[..., 0, 1] * covariances[..., 1, 0]
    if np.any(covariances[..., 0, 0] <= 0) or np.any(determinant <= 0):
        raise ValueError("covariances: expected positive-definite 2x2 matrices")
    if not np.allclose(covariances[..., 0, 1], covariances[..., 1, 0], rtol=1e-6, atol=1e-12):
        raise ValueError("covariances: expected symmetric 2x2 matrices")
    return points, means, covariances


def mahalanobis_squared(points, means, covariances) -> np.ndarray:
    """``d² = (x − μ)ᵀ Σ⁻¹ (x − μ)`` for ``points``/``means`` ``(..., 2)`` and ``covariances (..., 2, 2)``;
    returns ``(...)``."""
    points, means, covariances = _checked(points, means, covariances)
    difference = points - means
    a, b, d = covariances[..., 0, 0], covariances[..., 0, 1], covariances[..., 1, 1]
    determinant = a * d - b * b
    dx, dy = difference[..., 0], difference[..., 1]
    return (d * dx * dx - 2.0 * b * dx * dy + a * dy * dy) / determinant


@dataclass(frozen=True)
class CalibrationResult:
    """What :func:`ellipse_coverage` returns.

    Attributes:
        observed: ``{level: fraction of true points within level σ}``.
        expected: ``{level: 1 − exp(−level²/2)}``.
        count: points scored.
        median_mahalanobis_squared: median ``d²`` (a calibrated model: ``2 ln 2 = 1.386``).
        mahalanobis_squared: ``(count,)`` every ``d²`` (flattened).
    """

    observed: dict[float, float]
    expected: dict[float, float]
    count: int
    median_mahalanobis_squared: float
    mahalanobis_squared: np.ndarray = field(repr=False)

    def to_dict(self) -> dict:
        """JSON-ready summary (keys ``"1sigma"``, ``"2sigma"``, ...)."""
        def key(level):
            return f"{level:g}sigma"

        return {"observed": {key(level): round(value, 4) for level, value in self.observed.items()},
                "expected": {key(level): round(value, 4) for level, value in self.expected.items()},
                "count": self.count, "median_mahalanobis_squared": round(self.median_mahalanobis_squared, 4)}


def ellipse_coverage(points, means, covariances, levels=LEVELS, valid=None) -> CalibrationResult:
    """Fractions of true ``points`` inside the predicted ``level``-σ ellipses.

    Args:
        points: ``(..., 2)`` true positions (pixels).
        means: ``(..., 2)`` predicted means.
        covariances: ``(..., 2, 2)`` predicted covariances (pixels²), symmetric positive definite.
        levels: ellipse sizes in standard deviations.
        valid: optional ``(...)`` booleans; only those points are scored.
    Raises:
        ValueError: mismatched shapes, non-finite values, covariances that are not positive definite,
            no point to score.
    """
    squared = mahalanobis_squared(points, means, covariances)
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != squared.shape:
            raise ValueError(f"valid: expected shape {squared.shape}, got {valid.shape}")
        squared = squared[valid]
    squared = squared.ravel()
    if squared.size == 0:
        raise ValueError("points: no point to score")
    levels = tuple(float(level) for level in levels)
    if not levels or any(not level > 0 for level in levels):
        raise ValueError(f"levels: expected positive numbers of standard deviations, got {levels}")
    observed = {level: float(np.mean(squared <= level ** 2)) for level in levels}
    expected = {level: expected_coverage(level) for level in levels}
    return CalibrationResult(observed, expected, int(squared.size), float(np.median(squared)), squared)


def plot_calibration(results: dict[str, CalibrationResult], path: str | Path, title: str = "calibration") -> Path:
    """A PNG of observed against expected coverage of the k-σ ellipses (k from 0 to 3.5) for each named
    result (the diagonal is perfect calibration; below it: over-confident)."""
    levels = np.linspace(0.05, 3.5, 70)
    expected = 1.0 - np.exp(-0.5 * levels ** 2)
    figure = new_figure(5.0, 4.5)
    axis = figure.add_subplot(1, 1, 1)
    axis.plot([0, 1], [0, 1], color="grey", linestyle="--", linewidth=1, label="calibrated")
    for name, result in results.items():
        observed = [np.mean(result.mahalanobis_squared <= level ** 2) for level in levels]
        axis.plot(expected, observed, label=f"{name} (1σ {100 * result.observed.get(1.0, np.nan):.0f} %, "
                                            f"2σ {100 * result.observed.get(2.0, np.nan):.0f} %)")
    for level in (1.0, 2.0):
        axis.axvline(expected_coverage(level), color="lightgrey", linewidth=0.8)
    axis.set_xlabel("expected fraction inside the k-σ ellipse")
    axis.set_ylabel("observed fraction")
    axis.set_xlim(0, 1)
    axis.set_ylim(0, 1)
    axis.set_title(title)
    axis.legend(loc="lower right", fontsize=8)
    figure.tight_layout()
    return save_figure_atomically(figure, path)
