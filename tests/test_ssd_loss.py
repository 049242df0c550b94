"""The multibox loss against values computed by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from paz6d.ssd.loss import MultiboxLoss, multibox_terms


def _cross_entropy(logits, label):
    logits = np.asarray(logits, dtype=np.float64)
    return math.log(np.exp(logits).sum()) - logits[label]


def _smooth_l1(values):
    values = np.abs(np.asarray(values, dtype=np.float64))
    return float(np.where(values < 1, 0.5 * values ** 2, values - 0.5).sum())


def _example():
    """One image, 6 priors, 3 classes (background + 2): priors 0 (class 1) and 1 (class 2) are positive."""
    y_true = np.zeros((1, 6, 7), np.float32)
    y_true[0, 0, :4] = [0.5, -0.2, 1.5, 0.0]
    y_true[0, 0, 5] = 1
    y_true[0, 1, :4] = [0.0, 0.0, -2.0, 0.3]
    y_true[0, 1, 6] = 1
    y_true[0, 2:, 4] = 1
    y_pred = np.zeros((1, 6, 7), np.float32)
    y_pred[0, 0] = [0.1, 0.1, 0.2, 0.0, 0.0, 2.0, 0.0]
    y_pred[0, 1] = [0.0, 0.5, 0.0, 0.0, 1.0, 0.0, 1.0]
    y_pred[0, 2, 4:] = [0.0, 3.0, 0.0]   # a confident false positive: the hardest negative
    y_pred[0, 3, 4:] = [2.0, 0.0, 0.0]   # an easy negative
    y_pred[0, 4, 4:] = [0.0, 0.0, 1.0]
    y_pred[0, 5, 4:] = [1.0, 1.0, 0.0]
    return y_true, y_pred


def test_loss_matches_hand_computed_values():
    y_true, y_pred = _example()
    # Hand computation: positives 0 and 1; 4 negatives, at most 3 * 2 = 6 kept, so all 4 count.
    positives = _cross_entropy([0, 2, 0], 1) + _cross_entropy([1, 0, 1], 2)
    negatives = sum(_cross_entropy(y_pred[0, i, 4:], 0) for i in range(2, 6))
    localization = _smooth_l1([0.5 - 0.1, -0.2 - 0.1, 1.5 - 0.2, 0.0]) + _smooth_l1([0.0, -0.5, -2.0, 0.3])
    terms = multibox_terms(y_true, y_pred)
    assert float(terms["positives"]) == 2
    np.testing.assert_allclose(float(terms["classification"]), (positives + negatives) / 2, rtol=1e-6)
    np.testing.assert_allclose(float(terms["localization"]), localization / 2, rtol=1e-6)
    loss = MultiboxLoss(alpha=1.0)(y_true, y_pred)
    np.testing.assert_allclose(float(loss), (positives + negatives + localization) / 2, rtol=1e-6)


def test_hard_negative_mining_keeps_the_worst_negatives():
    y_true, y_pred = _example()
    # One positive (prior 0) and a 1:1 ratio: only the hardest negative (prior 2) counts.
    y_true[0, 1] = 0
    y_true[0, 1, 4] = 1
    terms = multibox_terms(y_true, y_pred, neg_pos_ratio=1.0)
    ce = [_cross_entropy(y_pred[0, i, 4:], 0) for i in range(1, 6)]
    assert int(np.argmax(ce)) + 1 == 2
    expected = _cross_entropy([0, 2, 0], 1) + max(ce)
    np.testing.assert_allclose(float(terms["classification"]), expected, rtol=1e-6)
    # Two negatives per positive: priors 2 and the next hardest.
    terms = multibox_terms(y_true, y_pred, neg_pos_ratio=2.0)
    expected = _cross_entropy([0, 2, 0], 1) + sum(sorted(ce)[-2:])
    np.testing.assert_allclose(float(terms["classification"]), expected, rtol=1e-6)


def test_an_image_without_objects_trains_its_hardest_negatives():
    y_true = np.zeros((2, 6, 7), np.float32)
    y_true[..., 4] = 1
    y_pred = np.zeros((2, 6, 7), np.float32)
    y_pred[0, 2, 5] = 4.0
    terms = multibox_terms(y_true, y_pred)
    # no positive: 3 * max(0, 1) = 3 negatives per image, normalised by max(N, 1) = 1
    hard = _cross_entropy([0, 4, 0], 0) + 2 * _cross_entropy([0, 0, 0], 0)
    expected = hard + 3 * _cross_entropy([0, 0, 0], 0)
    np.testing.assert_allclose(float(terms["classification"]), expected, rtol=1e-6)
    assert float(terms["localization"]) == 0.0


def test_bad_loss_settings_are_refused():
    with pytest.raises(ValueError, match="neg_pos_ratio/alpha"):
        MultiboxLoss(neg_pos_ratio=0)
