"""Test-time mirror image of the SSD: the prior pairing and a pipeline whose detections mirror with the image."""

from __future__ import annotations

import numpy as np
import pytest

from paz6d.backend import boxes as boxes_backend
from paz6d.ssd.model import build_ssd, paper_priors, priors_for


@pytest.mark.parametrize("architecture, size, canvas", [("light", 320, None), ("light", 128, (128, 192)),
                                                        ("ssd512", None, None)])
def test_each_prior_is_paired_with_its_mirror_image(architecture, size, canvas):
    priors = priors_for(paper_priors(architecture, size), canvas)
    index = boxes_backend.mirrored_prior_index(priors)
    np.testing.assert_allclose(priors[index, 0], 1.0 - priors[:, 0], atol=1e-9)
    np.testing.assert_array_equal(priors[index, 1:], priors[:, 1:])
    np.testing.assert_array_equal(index[index], np.arange(len(priors)))  # mirroring twice is the identity
    assert len(np.unique(index)) == len(priors)


def test_priors_without_mirror_images_are_refused():
    priors = np.array([[0.2, 0.5, 0.1, 0.1], [0.8, 0.5, 0.1, 0.1], [0.3, 0.5, 0.1, 0.1]])
    np.testing.assert_array_equal(boxes_backend.mirrored_prior_index(priors[:2]), [1, 0])
    with pytest.raises(ValueError, match="priors: expected priors that are left-right symmetric"):
        boxes_backend.mirrored_prior_index(priors)
    with pytest.raises(ValueError, match="priors: expected priors that are left-right symmetric"):
        boxes_backend.mirrored_prior_index(priors_for(paper_priors("ssd300")))  # 38 cells of 8 px over 300 px


def _detectors(image_scale: float | None):
    """The pipeline of one random light network with and without ``flip``."""
    from paz6d.ssd.pipeline import DetectSingleShot

    model, spec = build_ssd(3, "light", 128, width=0.25, any_size=image_scale is not None)
    detector = {"architecture": "light", "class_names": ["a", "b"], "priors": spec.to_dict(),
                "variances": list(boxes_backend.SSD_VARIANCES)}
    if image_scale is not None:
        detector["image_scale"] = image_scale
    return tuple(DetectSingleShot.from_model(model, detector, score_threshold=0.0, max_detections=8, flip=flip)
                 for flip in (True, False))


def _rows(detections, mirror_width: int | None = None) -> list[tuple]:
    """``(class, score, box...)`` sorted; the boxes mirrored in an image ``mirror_width`` pixels wide."""
    rows = []
    for box in detections:
        array = box.to_array() if mirror_width is None else boxes_backend.flip_left_right(box.to_array(),
                                                                                           mirror_width)
        rows.append((box.class_name, box.score, *array))
    return sorted(rows, key=lambda row: -row[1])


@pytest.mark.parametrize("image_scale", [None, 1.0])
def test_with_flip_the_detections_of_a_mirror_image_are_the_mirrored_detections(image_scale):
    """Averaging an image's outputs with its mirror image's makes the detector mirror-equivariant: exactly what
    the random network alone is not."""
    image = np.random.default_rng(0).integers(0, 256, (96, 128, 3), dtype=np.uint8)
    mirror = np.ascontiguousarray(image[:, ::-1])
    flipped, plain = _detectors(image_scale)
    assert flipped.names == plain.names == ["check", "resize", "normalize", "predict", "decode", "nms", "to_pixels",
                                            "to_boxes2d"]
    expected, found = _rows(flipped(image), mirror_width=128), _rows(flipped(mirror))
    assert len(found) == len(expected) == 8
    assert [row[0] for row in found] == [row[0] for row in expected]
    np.testing.assert_allclose([row[1:] for row in found], [row[1:] for row in expected], atol=1e-3)
    unflipped, mirrored = _rows(plain(mirror)), _rows(plain(image), mirror_width=128)
    assert not np.allclose([row[1:] for row in unflipped], [row[1:] for row in mirrored], atol=1e-3)


def test_flip_averages_the_mirror_images_outputs_per_prior():
    from paz6d.ssd.pipeline import AverageWithMirror, DecodeBoxes

    spec = paper_priors("light", 128)
    priors = priors_for(spec)
    index = boxes_backend.mirrored_prior_index(priors)
    rng = np.random.default_rng(1)
    outputs = rng.normal(0, 0.5, (2, len(priors), 4 + 3))
    boxes, probabilities = AverageWithMirror(DecodeBoxes(priors))(outputs)
    decode = DecodeBoxes(priors)
    first, second = decode(outputs[0]), decode(outputs[1])
    prior = 17  # brute force for one prior: its own values and those of its mirror prior, flipped back
    mirror_box = second[0][index[prior]]
    np.testing.assert_allclose(boxes[prior], (first[0][prior] + [1 - mirror_box[2], mirror_box[1], 1 - mirror_box[0],
                                                                   mirror_box[3]]) / 2)
    np.testing.assert_allclose(probabilities[prior], (first[1][prior] + second[1][index[prior]]) / 2)
    with pytest.raises(ValueError, match=r"outputs: expected the outputs of an input and its mirror image"):
        AverageWithMirror(DecodeBoxes(priors))(outputs[0])
