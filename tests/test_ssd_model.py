"""SSD builders, prior layouts, target encoding, detection decoding and the model file round trip."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from paz6d.backend import boxes as boxes_backend
from paz6d.ssd.encoding import decode_outputs, encode_targets, select_detections, softmax
from paz6d.ssd.model import (L2Normalization, PriorSpec, SSDModelError, build_ssd, light_feature_maps, load_ssd,
                             paper_priors, priors_for, save_ssd)


@pytest.mark.parametrize("architecture, priors, maps", [("ssd300", 8732, (38, 19, 10, 5, 3, 1)),
                                                         ("ssd512", 24564, (64, 32, 16, 8, 4, 2, 1))])
def test_vgg_builders_have_the_papers_layout(architecture, priors, maps):
    model, spec = build_ssd(21, architecture)
    assert spec.feature_map_sizes == maps
    assert model.output_shape == (None, priors, 4 + 21)
    assert len(priors_for(spec)) == priors
    assert isinstance(model.get_layer("conv4_3_norm"), L2Normalization)
    assert model.get_layer("fc6").dilation_rate == (6, 6)


def test_light_priors_of_the_first_layer_match_hand_computed_values():
    spec = paper_priors("light", 320)
    assert spec.feature_map_sizes == (40, 20, 10, 5, 3, 1)
    priors = priors_for(spec)
    first_map = priors[:40 * 40 * 4]
    small, large = spec.min_sizes[0], spec.max_sizes[0]
    assert (small, large) == (14.1, 30.1)
    # cell (row 2, column 3): centre ((3 + 0.5) * 8, (2 + 0.5) * 8) pixels, four shapes
    cell = first_map[(2 * 40 + 3) * 4:(2 * 40 + 4) * 4] * 320
    root = np.sqrt(2.0)
    expected = [[28, 20, 14.1, 14.1], [28, 20, np.sqrt(14.1 * 30.1), np.sqrt(14.1 * 30.1)],
                [28, 20, 14.1 * root, 14.1 / root], [28, 20, 14.1 / root, 14.1 * root]]
    np.testing.assert_allclose(cell, expected, atol=1e-9)
    model, _ = build_ssd(3, "light", 320, width=0.25)
    assert model.output_shape == (None, len(priors), 7)


@pytest.mark.parametrize("top_down", [False, True])
def test_top_down_path_gives_the_finest_map_context_beyond_its_receptive_field(top_down):
    model, spec = build_ssd(3, "light", 256, width=0.25, top_down=top_down)
    assert model.output_shape == (None, len(priors_for(spec)), 7)
    assert any(layer.name.startswith("topdown_") for layer in model.layers) == top_down
    images = np.random.default_rng(0).normal(size=(1, 256, 256, 3)).astype(np.float32)
    changed = images.copy()
    changed[0, 70:90, 70:90] += 3.0  # about 80 px from the first cell: outside the stride-8 map's own field
    first_cell = slice(0, spec.priors_per_cell[0])
    before = np.asarray(model(images, training=False))[0, first_cell]
    after = np.asarray(model(changed, training=False))[0, first_cell]
    # without the path the first cell cannot see the change at all (exactly equal); with it, it moves by more
    # than float round-off (activations are small at initialisation, so the bound is relative)
    assert (np.abs(after - before).max() > 1e-6 * np.abs(before).max()) == top_down


def test_l2_normalization_scales_unit_vectors():
    layer = L2Normalization(20.0)
    values = np.array([[[[3.0, 4.0]]]], np.float32)
    np.testing.assert_allclose(np.asarray(layer(values)), [[[[12.0, 16.0]]]], rtol=1e-5)


def test_builder_errors_name_the_argument():
    with pytest.raises(SSDModelError, match="num_classes"):
        build_ssd(1)
    with pytest.raises(SSDModelError, match="architecture"):
        build_ssd(3, "yolo")
    with pytest.raises(SSDModelError, match="input_size"):
        build_ssd(3, "ssd300", 320)
    with pytest.raises(SSDModelError, match="input_size"):
        build_ssd(3, "light", 300)
    with pytest.raises(SSDModelError, match="top_down"):
        build_ssd(3, "ssd300", top_down=True)
    with pytest.raises(SSDModelError, match="priors"):
        PriorSpec.from_dict({"input_size": 320})


def test_save_load_round_trip_gives_identical_outputs(tmp_path):
    model, spec = build_ssd(4, "light", 128, width=0.25)
    images = np.random.default_rng(0).normal(size=(2, 128, 128, 3)).astype(np.float32)
    path = save_ssd(model, tmp_path / "model.keras")
    loaded = load_ssd(path, PriorSpec.from_dict(spec.to_dict()), 4)
    np.testing.assert_array_equal(np.asarray(model(images, training=False)), np.asarray(loaded(images, training=False)))
    with pytest.raises(SSDModelError, match="expected an SSD"):
        load_ssd(path, spec, 5)
    (tmp_path / "broken.keras").write_bytes(b"not a zip")
    with pytest.raises(SSDModelError, match="broken.keras: not a readable"):
        load_ssd(tmp_path / "broken.keras", spec, 4)


def test_encode_targets_marks_matched_priors_and_decodes_back():
    priors = priors_for(paper_priors("light", 128))
    truth = np.array([[0.1, 0.2, 0.3, 0.5], [0.6, 0.55, 0.9, 0.8]])
    targets = encode_targets(truth, [2, 1], priors, num_classes=3)
    positive = targets[:, 4] == 0
    matched = boxes_backend.match(truth, priors)
    np.testing.assert_array_equal(positive, matched >= 0)
    np.testing.assert_array_equal(targets[positive, 4:].sum(axis=1), 1)
    np.testing.assert_array_equal(np.argmax(targets[positive, 4:], axis=1), np.array([2, 1])[matched[positive]])
    np.testing.assert_allclose(boxes_backend.decode(targets[positive, :4], priors[positive]), truth[matched[positive]],
                               atol=1e-5)
    assert np.all(targets[~positive, :4] == 0)
    empty = encode_targets(np.zeros((0, 4)), np.zeros(0, int), priors, 3)
    assert np.all(empty[:, 4] == 1)
    with pytest.raises(ValueError, match=r"class_ids: expected integers in \[1, 3\)"):
        encode_targets(truth, [0, 1], priors, 3)


def _random_candidates(seed: int, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``count`` random normalised boxes ``(count, 4)`` and class probabilities ``(count, 4)`` (background first)."""
    generator = np.random.default_rng(seed)
    corners = generator.uniform(0, 0.8, (count, 2))
    boxes = np.concatenate([corners, corners + generator.uniform(0.02, 0.2, (count, 2))], axis=1)
    return boxes, softmax(generator.normal(size=(count, 4)) * 2)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2 ** 31 - 1), st.integers(1, 40), st.sampled_from([0.3, 0.45, 0.7]))
def test_select_detections_matches_a_brute_force_loop(seed, count, threshold):
    boxes, probabilities = _random_candidates(seed, count)
    kept_boxes, scores, class_ids = select_detections(boxes, probabilities, 0.05, threshold, max_detections=1000)
    expected = []
    for class_id in range(1, 4):  # greedy NMS per class, written out
        order = sorted((i for i in range(count) if probabilities[i, class_id] >= 0.05),
                       key=lambda i: -probabilities[i, class_id])
        kept: list[int] = []
        for i in order:
            if all(boxes_backend.iou_matrix(boxes[[i]], boxes[[j]])[0, 0] <= threshold for j in kept):
                kept.append(i)
        expected += [(probabilities[i, class_id], class_id, tuple(boxes[i])) for i in kept]
    expected.sort(key=lambda row: -row[0])
    got = sorted(zip(scores, class_ids, map(tuple, kept_boxes)), key=lambda row: -row[0])
    assert len(got) == len(expected)
    for (score, class_id, box), (score_e, class_e, box_e) in zip(got, expected):
        assert class_id == class_e and score == pytest.approx(score_e)
        np.testing.assert_allclose(box, box_e)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2 ** 31 - 1), st.integers(1, 40), st.sampled_from([0.3, 0.5, 0.7]))
def test_box_voting_averages_each_winners_class_neighbours_by_score(seed, count, vote_iou):
    boxes, probabilities = _random_candidates(seed, count)
    plain = select_detections(boxes, probabilities, 0.05, 0.45, max_detections=1000)
    voted = select_detections(boxes, probabilities, 0.05, 0.45, max_detections=1000, vote_iou=vote_iou)
    np.testing.assert_array_equal(voted[1], plain[1])  # the same winners, scores and classes
    np.testing.assert_array_equal(voted[2], plain[2])
    for box, winner, class_id in zip(voted[0], plain[0], plain[2]):  # the weighted mean, written out
        total, weight = np.zeros(4), 0.0
        for i in range(count):
            score = probabilities[i, class_id]
            overlap = boxes_backend.iou_matrix(boxes[[i]], winner[None])[0, 0]
            if score >= 0.05 and (overlap >= vote_iou or np.array_equal(boxes[i], winner)):
                total, weight = total + score * boxes[i], weight + score
        np.testing.assert_allclose(box, total / weight)


def test_box_voting_moves_a_winner_towards_its_neighbours_only():
    boxes = np.array([[0.1, 0.1, 0.3, 0.3], [0.12, 0.12, 0.32, 0.32], [0.6, 0.6, 0.8, 0.8]])
    probabilities = np.array([[0.2, 0.8], [0.4, 0.6], [0.3, 0.7]])
    kept, scores, _ = select_detections(boxes, probabilities, 0.1, 0.45, vote_iou=0.5)
    np.testing.assert_allclose(scores, [0.8, 0.7])
    np.testing.assert_allclose(kept[0], (0.8 * boxes[0] + 0.6 * boxes[1]) / 1.4)
    np.testing.assert_allclose(kept[1], boxes[2])  # nothing overlaps it
    with pytest.raises(ValueError, match="iou_threshold: expected a value in"):
        boxes_backend.vote_boxes([0], boxes, [1.0, 1.0, 1.0], [0, 0, 0], 1.5)
    from paz6d.ssd.pipeline import NonMaximumSuppression

    voting = NonMaximumSuppression(0.1, vote_iou=0.5)  # the pipeline's step votes as select_detections does
    np.testing.assert_allclose(voting(boxes, probabilities)[0], kept)
    for bad in (1.5, float("nan"), "0.5", True):
        with pytest.raises(ValueError, match="vote_iou: expected a number in"):
            NonMaximumSuppression(vote_iou=bad)


def test_decode_outputs_inverts_the_encoding_and_checks_shapes():
    priors = priors_for(paper_priors("light", 128))
    truth = np.array([[0.2, 0.2, 0.5, 0.6]])
    targets = encode_targets(truth, [1], priors, 2)
    outputs = np.concatenate([targets[:, :4], np.where(targets[:, 4:] > 0, 10.0, -10.0)], axis=1)
    boxes, probabilities = decode_outputs(outputs, priors)
    positive = targets[:, 4] == 0
    np.testing.assert_allclose(boxes[positive], np.repeat(truth, positive.sum(), axis=0), atol=1e-5)
    assert probabilities.shape == (len(priors), 2)
    kept, scores, ids = select_detections(boxes, probabilities, 0.5, 0.45)
    assert len(kept) == 1 and ids[0] == 1
    np.testing.assert_allclose(kept[0], truth[0], atol=1e-5)
    with pytest.raises(ValueError, match="outputs: expected shape"):
        decode_outputs(outputs[:, :5], priors)


def test_an_any_size_light_model_runs_on_whole_images_with_priors_of_their_shape(tmp_path):
    model, spec = build_ssd(3, "light", 128, width=0.25, any_size=True)
    assert priors_for(spec, (128, 128)).tolist() == priors_for(spec).tolist()
    for height, width in ((128, 192), (192, 320)):
        output = np.asarray(model(np.zeros((1, height, width, 3), np.float32)))
        priors = priors_for(spec, (height, width))
        assert output.shape == (1, len(priors), 7)
        rows, cols = light_feature_maps(height, width)[0]
        assert (rows, cols) == (height // 8, width // 8)
        # first cell of the first map: centre (4, 4) pixels; sides stay the trained ones in pixels
        np.testing.assert_allclose(priors[0] * [width, height, width, height],
                                   [4, 4, spec.min_sizes[0], spec.min_sizes[0]])
    loaded = load_ssd(save_ssd(model, tmp_path / "any.keras"), spec, 3)
    np.testing.assert_allclose(np.asarray(loaded(np.ones((1, 128, 192, 3), np.float32))),
                               np.asarray(model(np.ones((1, 128, 192, 3), np.float32))), atol=1e-5)
    with pytest.raises(SSDModelError, match="any_size: only the light network"):
        build_ssd(3, "ssd300", any_size=True)
    with pytest.raises(SSDModelError, match="input_size: expected a multiple of 64"):
        priors_for(spec, (100, 128))
