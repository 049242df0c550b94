"""The demo's out-of-distribution check: the OOD views are what each condition says (flat is flat, pixel
noise is noisy, smooth fields are smooth, the object's pixels are untouched, the lighting condition only
changes the light), seeded; no training pipeline uses the OOD styles; the PASS/FAIL rule and the report
fields on hand-made numbers; the table and the chart."""

from __future__ import annotations

import numpy as np
import pytest

from paz6d.backend.camera import Camera
from paz6d.demo import ood_check
from paz6d.demo.ood_set import CONDITIONS, IN_DISTRIBUTION, render_ood_views
from paz6d.synthesis import backgrounds

SMALL_CAMERA = Camera(np.array([[143.1, 0.0, 80.0], [0.0, 143.4, 60.0], [0.0, 0.0, 1.0]]), 160, 120)


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    from paz6d.assets.demo_object import write_demo_object
    from paz6d.keypointnet.views import ViewSampling

    mesh = write_demo_object(tmp_path_factory.mktemp("mesh"))
    sampling = ViewSampling(camera=SMALL_CAMERA)
    return {"mesh": mesh, "sampling": sampling,
            "views": render_ood_views(mesh, 3, 11, sampling, 0.001, workers=0, progress=False)}


def _background_pixels(images: np.ndarray, alpha: np.ndarray) -> list[np.ndarray]:
    return [image[a == 0].astype(np.float64) for image, a in zip(images, alpha)]


def test_each_condition_is_what_it_says_and_the_object_is_untouched(views):
    ood = views["views"]
    assert len(ood) == 3 and ood.rgb.shape == (3, 120, 160, 3) and ood.boxes.shape == (3, 4)
    assert all((ood.alpha == 0).any(axis=(1, 2))) and all((ood.alpha == 255).any(axis=(1, 2)))
    images = {condition: ood.images(condition, "clutter") for condition in CONDITIONS}
    solid = ood.alpha == 255
    for condition, stack in images.items():
        renders = ood.relit if condition == "lighting" else ood.rgb
        np.testing.assert_array_equal(stack[solid], renders[solid], err_msg=condition)
    for pixels in _background_pixels(images["flat"], ood.alpha):
        assert np.all(pixels == pixels[0])
    for pixels in _background_pixels(images["pixel-noise"], ood.alpha):
        assert pixels.std(axis=0).min() > 60  # uniform 0-255: ~74 levels
    smooth = ood.backgrounds("smooth-field", "clutter").astype(np.float64)
    neighbour_steps = np.abs(np.diff(smooth, axis=2)).mean()
    assert smooth.std(axis=(1, 2)).min() > 10 and neighbour_steps < 6
    noise = ood.backgrounds("pixel-noise", "clutter").astype(np.float64)
    assert np.abs(np.diff(noise, axis=2)).mean() > 60
    # the lighting condition: same backgrounds as the reference, another light on the object
    np.testing.assert_array_equal(images["lighting"][ood.alpha == 0], images[IN_DISTRIBUTION][ood.alpha == 0])
    assert np.abs(ood.relit[solid].astype(int) - ood.rgb[solid].astype(int)).mean() > 10
    # the reference is the model's training style, drawn from the documented generator
    expected = backgrounds.procedural_background(np.random.default_rng([11, 0, 1]), 160, 120, "clutter")
    np.testing.assert_array_equal(ood.backgrounds(IN_DISTRIBUTION, "clutter")[1], expected)
    assert not np.array_equal(ood.backgrounds(IN_DISTRIBUTION, "shapes")[1], expected)
    with pytest.raises(ValueError, match="condition: expected one of"):
        ood.images("fog", "clutter")
    with pytest.raises(ValueError, match="in_distribution_style: expected one of"):
        ood.images("flat", "flat")


def test_ood_views_are_deterministic_by_seed(views):
    again = render_ood_views(views["mesh"], 2, 11, views["sampling"], 0.001, workers=0, progress=False)
    first = views["views"]
    np.testing.assert_array_equal(again.rgb, first.rgb[:2])
    np.testing.assert_array_equal(again.relit, first.relit[:2])
    np.testing.assert_array_equal(again.T_model2cam, first.T_model2cam[:2])
    np.testing.assert_array_equal(again.images("smooth-field", "shapes"), first.images("smooth-field", "shapes")[:2])
    other = render_ood_views(views["mesh"], 1, 12, views["sampling"], 0.001, workers=0, progress=False)
    assert not np.allclose(other.T_model2cam[0], first.T_model2cam[0])
    with pytest.raises(ValueError, match="count: expected a positive number"):
        render_ood_views(views["mesh"], 0, 11, views["sampling"], 0.001, workers=0)


def test_no_training_pipeline_uses_an_ood_style():
    from paz6d.keypointnet.views import BACKGROUND

    assert not set(backgrounds.OOD_BACKGROUND_STYLES) & set(backgrounds.BACKGROUND_STYLES)
    for style in (BACKGROUND.style, ood_check.AAE_TRAINING_STYLE):
        assert style in backgrounds.BACKGROUND_STYLES
    # the check's pixel noise (uniform 0-255) is much stronger than the strongest training pixel noise
    check_noise = backgrounds.ood_background(np.random.default_rng(0), 64, 64, "pixel-noise").std()
    assert check_noise > 1.5 * backgrounds.MAX_TRAINING_PIXEL_NOISE
    flat = backgrounds.ood_background(np.random.default_rng(0), 8, 6, "flat")
    assert flat.shape == (6, 8, 3) and flat.flags.writeable and len(np.unique(flat.reshape(-1, 3), axis=0)) == 1
    with pytest.raises(ValueError, match="style: expected one of"):
        backgrounds.ood_background(np.random.default_rng(0), 8, 8, "shapes")


def test_retention_and_pass_fail_rule_on_hand_made_numbers():
    recalls = {IN_DISTRIBUTION: 0.8, "flat": 0.72, "pixel-noise": 0.719, "smooth-field": 0.9, "lighting": None}
    summary = ood_check.check_summary("shapes", recalls)
    assert summary["in_distribution_style"] == "shapes" and summary["in_distribution_recall"] == 0.8
    assert summary["min_retention_required"] == ood_check.MIN_RETENTION == 0.9
    flat, noise, smooth, light = (summary["conditions"][c] for c in ("flat", "pixel-noise", "smooth-field", "lighting"))
    assert flat == {"recall": 0.72, "retention": pytest.approx(0.9), "pass": True}
    assert noise["retention"] == pytest.approx(0.89875) and not noise["pass"]
    assert smooth["retention"] == pytest.approx(1.125) and smooth["pass"]  # better than in-distribution passes
    assert light == {"recall": None, "retention": None, "pass": False}  # unmeasured fails
    assert summary["min_retention"] is None and not summary["pass"]
    passing = ood_check.check_summary("clutter", {**recalls, "pixel-noise": 0.75, "lighting": 0.8})
    assert passing["pass"] and passing["min_retention"] == pytest.approx(0.9)
    nothing = ood_check.check_summary("clutter", {condition: 0.0 for condition in CONDITIONS})
    assert not nothing["pass"] and nothing["conditions"]["flat"]["retention"] is None  # nothing to retain
    assert ood_check.check_summary("clutter", {**recalls, "pixel-noise": 0.75, "lighting": 0.8},
                                   min_retention=0.95)["pass"] is False
    with pytest.raises(ValueError, match="missing \\['lighting'\\]"):
        ood_check.check_summary("shapes", {c: 0.5 for c in CONDITIONS if c != "lighting"})
    with pytest.raises(ValueError, match="kind: expected one of"):
        ood_check.PoseModel("X", "hrnet", "run")


def test_table_and_chart_show_every_condition_and_verdict(tmp_path, capsys):
    from paz6d.demo.report import print_rows

    results = {"AAE": ood_check.check_summary("clutter", {c: 0.8 for c in CONDITIONS}),
               "KeypointNet": ood_check.check_summary("shapes", {**{c: 0.8 for c in CONDITIONS}, "pixel-noise": 0.1})}
    print_rows(ood_check.check_rows(results))
    printed = capsys.readouterr().out
    verdicts = {line.split(":")[0].strip(): line.split()[-1] for line in printed.splitlines() if "OOD check" in line}
    assert verdicts == {"AAE": "PASS", "KeypointNet": "FAIL"}
    noise_rows = [line.split()[-6:] for line in printed.splitlines() if "pixel-noise" in line]
    assert noise_rows == [["80.0", "%", "/", "100.0", "%", "PASS"], ["10.0", "%", "/", "12.5", "%", "FAIL"]]
    for condition in ood_check.OOD_CONDITIONS:
        assert printed.count(f"{condition}: recall / retention") == 2
    path = ood_check.plot_check(tmp_path / "chart.png", results)
    from paz6d.backend.image import load_image

    assert load_image(path).shape[1] >= 600
