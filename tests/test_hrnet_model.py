"""The HRNet builder: output and per-branch shapes for several branch configurations, save/load round trip,
clear errors, and the heatmap losses."""

import numpy as np
import pytest

from paz6d.hrnet import model as hr
from paz6d.hrnet.heatmaps import gaussian_heatmaps

TINY = {"widths": (4, 8), "stage_modules": (1,), "blocks": 1, "stem_width": 4, "stem_blocks": 0}


@pytest.mark.parametrize("widths, stage_modules", [((4, 8), (1,)), ((4, 8, 16), (1, 2)), ((4, 6, 8, 10), (1, 1, 1))])
def test_output_and_branch_shapes_per_configuration(widths, stage_modules):
    size, count = 64, 5
    model = hr.build_hrnet(count, size, widths, stage_modules, blocks=1, stem_width=6, stem_blocks=1)
    assert model.output["heatmaps"].shape == (None, size // 4, size // 4, count)
    branches = len(widths)
    for stage, modules in enumerate(stage_modules, start=2):
        for module in range(modules):
            last = stage == branches and module == modules - 1
            for branch in range(stage):  # stage k runs k branches, at strides 4 * 2^branch
                name = f"stage{stage}_module{module}_fuse{branch}"
                if last and branch > 0:  # the final module fuses into the highest resolution only
                    with pytest.raises(ValueError):
                        model.get_layer(name)
                    continue
                side = size // (4 * 2 ** branch)
                assert model.get_layer(name).output.shape == (None, side, side, widths[branch]), name
    heatmaps = model(np.zeros((2, size, size, 3), np.float32))["heatmaps"]
    assert heatmaps.shape == (2, size // 4, size // 4, count) and heatmaps.dtype == "float32"


def test_bfloat16_body_keeps_a_float32_head():
    model = hr.build_hrnet(3, 32, **TINY, compute_dtype="bfloat16")
    assert model(np.zeros((1, 32, 32, 3), np.float32))["heatmaps"].dtype == "float32"


def test_save_load_round_trip_gives_identical_outputs(tmp_path):
    model = hr.build_hrnet(3, 32, **TINY)
    images = np.random.default_rng(0).uniform(0, 255, (2, 32, 32, 3)).astype(np.float32)
    expected = np.asarray(model(images, training=False)["heatmaps"])
    path = hr.save_hrnet(model, tmp_path / "model.keras")
    loaded = hr.load_hrnet(path)
    np.testing.assert_array_equal(np.asarray(loaded(images, training=False)["heatmaps"]), expected)
    np.testing.assert_allclose(np.asarray(hr.inference_function(loaded)(images)), expected, atol=1e-5)
    (tmp_path / "broken.keras").write_bytes(b"not a model")
    with pytest.raises(hr.HRNetError, match="broken.keras"):
        hr.load_hrnet(tmp_path / "broken.keras")
    with pytest.raises(hr.HRNetError, match="file not found"):
        hr.load_hrnet(tmp_path / "missing.keras")
    other = hr.keras.Model(model.input, {"uv": model.output["heatmaps"]})
    hr.save_hrnet(other, tmp_path / "other.keras")
    with pytest.raises(hr.HRNetError, match="expected an HRNet"):
        hr.load_hrnet(tmp_path / "other.keras")


@pytest.mark.parametrize("arguments, message", [
    ({"num_keypoints": 0}, "num_keypoints"),
    ({"widths": (8,), "stage_modules": ()}, "widths: expected at least 2"),
    ({"stage_modules": (1, 1)}, r"stage_modules: expected 1 positive"),
    ({"input_size": 36}, "input_size: expected a multiple of 8"),
    ({"blocks": 0}, "blocks"),
    ({"compute_dtype": "float16"}, "compute_dtype"),
])
def test_bad_arguments_are_clear_errors(arguments, message):
    with pytest.raises(ValueError, match=message):
        hr.build_hrnet(**{"num_keypoints": 3, "input_size": 32, **TINY, **arguments})


def test_gaussian_targets_match_numpy_and_losses_are_smallest_at_the_target():
    uv = np.array([[[10.3, 20.7], [3.0, 30.2]]])
    targets = np.asarray(hr.gaussian_targets(uv, 8, 8, 4, 1.5))
    np.testing.assert_allclose(targets, gaussian_heatmaps(uv, 8, 8, 4, 1.5), atol=1e-6)
    perfect = np.log(targets + 1e-30)
    shifted = np.roll(perfect, 1, axis=2)
    assert float(hr.softmax_heatmap_loss(perfect, targets)) < float(hr.softmax_heatmap_loss(shifted, targets))
    assert float(hr.mse_heatmap_loss(targets, targets)) == 0.0
    # cross-entropy of a target with itself is its entropy: compute it by hand for the first map
    normalised = targets[0, ..., 0] / targets[0, ..., 0].sum()
    entropy = -(normalised * np.log(normalised + 1e-30)).sum()
    one = hr.softmax_heatmap_loss(perfect[..., :1], targets[..., :1])
    np.testing.assert_allclose(float(one), entropy, rtol=1e-4)
    np.testing.assert_allclose(np.asarray(hr.argmax_keypoints(targets, 4)), [[[9.5, 21.5], [1.5, 29.5]]])
