"""HRNet heatmap decoding: sub-pixel positions of synthetic Gaussians, every decoder, bad input."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from paz6d.hrnet.heatmaps import DECODERS, cell_centres, decode_heatmaps, gaussian_heatmaps, quadratic_offsets


def _maps(uv, size=32, stride=4, sigma=1.5):
    return gaussian_heatmaps(np.asarray(uv, dtype=np.float64)[None], size, size, stride, sigma)


@settings(max_examples=30, deadline=None)
@given(u=st.floats(12.0, 115.0), v=st.floats(12.0, 115.0), sigma=st.floats(0.8, 3.0),
       stride=st.sampled_from([1, 2, 4]), domain=st.sampled_from(["log", "value"]))
def test_quadratic_decoding_recovers_sub_pixel_gaussian_centres(u, v, sigma, stride, domain):
    size = 128 // stride
    maps = _maps([[u, v], [v, u]], size, stride, sigma)
    if domain == "log":  # logits up to a constant: the Gaussian's exponent (its exp underflows far away)
        centres = cell_centres(size, stride)
        heatmaps = np.stack([-(((centres[None, :] - a) ** 2 + (centres[:, None] - b) ** 2)
                               / (2 * (sigma * stride) ** 2))
                             for a, b in ([u, v], [v, u])], axis=-1)[None] - 3.0
    else:
        heatmaps = maps
    uv, scores = decode_heatmaps(heatmaps, stride, "quadratic", domain, sigma)
    np.testing.assert_allclose(uv[0], [[u, v], [v, u]], atol=1e-6 * stride + 1e-6)
    assert np.all(scores > 0)


@settings(max_examples=20, deadline=None)
@given(u=st.floats(20.0, 100.0), v=st.floats(20.0, 100.0))
def test_coarser_decoders_are_within_their_resolution(u, v):
    stride, maps = 4, _maps([[u, v]])
    truth = np.array([u, v])
    errors = {method: np.abs(decode_heatmaps(maps, stride, method, "value")[0][0, 0] - truth) for method in DECODERS}
    assert np.all(errors["argmax"] <= stride / 2 + 1e-9)
    assert np.all(errors["quarter"] <= stride / 2 + 1e-9)
    assert np.all(errors["soft_argmax"] <= 0.2 * stride)  # 5x5 window around the peak cell: truncation bias
    assert np.all(errors["quadratic"] <= 1e-6)


def test_log_domain_scores_are_about_one_for_a_perfect_normalised_gaussian():
    sigma = 1.0
    maps = _maps([[63.3, 40.1]], sigma=sigma)
    _, scores = decode_heatmaps(np.log(maps), 4, "quadratic", "log", sigma)
    assert 0.8 < scores[0, 0] < 1.2
    _, values = decode_heatmaps(maps, 4, "quadratic", "value")
    assert 0.8 < values[0, 0] <= 1.0  # peak value of a peak-1 Gaussian seen at the nearest cell


def test_peaks_at_the_border_and_flat_maps_stay_finite_and_inside():
    maps = _maps([[-10.0, 64.0], [140.0, 140.0]])  # centres outside the crop: peaks on the border cells
    uv, _ = decode_heatmaps(maps, 4, "quadratic", "value")
    assert np.all(np.isfinite(uv))
    np.testing.assert_allclose(uv[0, 0], [1.5, 64.0], atol=1e-6)  # u not moved along the clipped axis
    np.testing.assert_allclose(uv[0, 1], [125.5, 125.5])
    flat = np.zeros((1, 8, 8, 2))
    for method in DECODERS:
        uv, _ = decode_heatmaps(flat, 4, method, "value")
        assert np.all(np.isfinite(uv)), method
    assert np.all(quadratic_offsets(flat, np.zeros((1, 2), int), np.zeros((1, 2), int)) == 0.0)


def test_cell_centres_follow_the_pixel_centre_convention():
    np.testing.assert_allclose(cell_centres(3, 4), [1.5, 5.5, 9.5])
    np.testing.assert_allclose(cell_centres(2, 1), [0.0, 1.0])


def test_bad_input_is_a_clear_error():
    with pytest.raises(ValueError, match=r"heatmaps: expected shape \(B, h, w, N\)"):
        decode_heatmaps(np.zeros((8, 8, 2)), 4)
    with pytest.raises(ValueError, match="heatmaps: expected finite"):
        decode_heatmaps(np.full((1, 4, 4, 1), np.nan), 4)
    with pytest.raises(ValueError, match="method: expected one of"):
        decode_heatmaps(np.zeros((1, 4, 4, 1)), 4, "median")
    with pytest.raises(ValueError, match="domain: expected one of"):
        decode_heatmaps(np.zeros((1, 4, 4, 1)), 4, domain="prob")
    with pytest.raises(ValueError, match="stride"):
        decode_heatmaps(np.zeros((1, 4, 4, 1)), 0)
    with pytest.raises(ValueError, match=r"uv: expected shape \(B, N, 2\)"):
        gaussian_heatmaps(np.zeros((3, 2)), 8, 8, 4, 1.0)
    with pytest.raises(ValueError, match="sigma"):
        gaussian_heatmaps(np.zeros((1, 3, 2)), 8, 8, 4, 0.0)
