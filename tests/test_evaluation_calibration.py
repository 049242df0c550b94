"""evaluation.calibration: Mahalanobis distances against hand-computed values, coverage of sampled
Gaussians close to the χ²(2) probabilities, the PNG and the input checks."""

from __future__ import annotations

import numpy as np
import pytest

from evaluation.calibration import (ellipse_coverage, expected_coverage, mahalanobis_squared,
                                    plot_calibration)


def test_expected_coverage_is_the_2d_chi_square_probability():
    assert expected_coverage(1.0) == pytest.approx(0.393469, abs=1e-6)
    assert expected_coverage(2.0) == pytest.approx(0.864665, abs=1e-6)
    assert expected_coverage(3.0) == pytest.approx(0.988891, abs=1e-6)


def test_mahalanobis_squared_matches_hand_computed_values():
    # Σ = diag(4, 9): (2, 3) away is 1 + 1 = 2
    assert mahalanobis_squared([2.0, 3.0], [0.0, 0.0], np.diag([4.0, 9.0])) == pytest.approx(2.0)
    # Σ = [[2, 1], [1, 2]], Σ⁻¹ = [[2, -1], [-1, 2]] / 3; r = (1, 1): (2 - 2 + 2) / 3 = 2/3
    assert mahalanobis_squared([[1.0, 1.0]], [[0.0, 0.0]], [[[2.0, 1.0], [1.0, 2.0]]])[0] == pytest.approx(2 / 3)
    # r = (1, -1): (2 + 2 + 2) / 3 = 2
    assert mahalanobis_squared([3.0, 4.0], [2.0, 5.0], [[2.0, 1.0], [1.0, 2.0]]) == pytest.approx(2.0)


def test_samples_of_the_predicted_gaussians_are_calibrated_and_scaled_ones_are_not():
    generator = np.random.default_rng(0)
    count = 20000
    means = generator.uniform(0, 100, (count, 2))
    factors = generator.normal(size=(count, 2, 2)) * 2.0
    covariances = factors @ np.swapaxes(factors, 1, 2) + 0.1 * np.eye(2)
    points = means + np.einsum("nij,nj->ni", np.linalg.cholesky(covariances), generator.normal(size=(count, 2)))
    result = ellipse_coverage(points, means, covariances)
    for level in (1.0, 2.0, 3.0):
        assert abs(result.observed[level] - expected_coverage(level)) < 0.015, (level, result.observed)
    assert result.median_mahalanobis_squared == pytest.approx(2 * np.log(2), rel=0.05)
    over_confident = ellipse_coverage(points, means, covariances / 4.0)
    assert over_confident.observed[1.0] < 0.15 and over_confident.observed[2.0] < 0.45
    assert set(result.to_dict()["observed"]) == {"1sigma", "2sigma", "3sigma"}
    masked = ellipse_coverage(points[:10], means[:10], covariances[:10], valid=np.arange(10) < 4)
    assert masked.count == 4


def test_plot_and_errors(tmp_path):
    points = np.zeros((5, 2))
    covariances = np.tile(np.eye(2), (5, 1, 1))
    path = plot_calibration({"model": ellipse_coverage(points + 0.5, points, covariances)}, tmp_path / "c.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(ValueError, match="means"):
        ellipse_coverage(points, points[:3], covariances)
    with pytest.raises(ValueError, match="covariances: expected shape"):
        ellipse_coverage(points, points, covariances[:, 0])
    with pytest.raises(ValueError, match="positive-definite"):
        ellipse_coverage(points, points, -covariances)
    with pytest.raises(ValueError, match="symmetric"):
        ellipse_coverage(points, points, covariances + np.array([[0.0, 0.5], [0.0, 0.0]]))
    with pytest.raises(ValueError, match="finite"):
        ellipse_coverage(points + np.nan, points, covariances)
    with pytest.raises(ValueError, match="no point"):
        ellipse_coverage(points, points, covariances, valid=np.zeros(5, bool))
    with pytest.raises(ValueError, match="levels"):
        ellipse_coverage(points, points, covariances, levels=(0.0,))
