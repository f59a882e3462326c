"""Metrics against definitions computed the slow way."""

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aeb_radar_camera.tools.eval import metrics


def brute_auc(scores, labels):
    pos = [s for s, y in zip(scores, labels, strict=True) if y]
    neg = [s for s, y in zip(scores, labels, strict=True) if not y]
    wins = sum(1.0 if p > n else 0.5 if p == n else 0.0
               for p, n in itertools.product(pos, neg))
    return wins / (len(pos) * len(neg))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.sampled_from([0.0, 0.01, 0.02, 0.05, 0.1, 0.3]), st.booleans()),
                min_size=2, max_size=40))
def test_auc_is_the_mann_whitney_statistic_with_ties_counted_half(pairs):
    scores = [s for s, _ in pairs]
    labels = [y for _, y in pairs]
    if all(labels) or not any(labels):
        with pytest.raises(ValueError):
            metrics.auc(scores, labels)
        return
    assert metrics.auc(scores, labels) == pytest.approx(brute_auc(scores, labels))
    # ... and the trapezoidal area under the ROC through every distinct score.
    r = metrics.roc(scores, labels)
    assert np.trapezoid(r.tpr, r.fpr) == pytest.approx(r.auc)
    assert r.tpr[0] == 0 and r.fpr[0] == 0 and r.tpr[-1] == 1 and r.fpr[-1] == 1


def test_confusion_ratios_and_the_rule_score_at_least_tau():
    scores = [0.01, 0.025, 0.03, 0.2, 0.024, 0.5]
    labels = [False, True, False, True, True, False]
    c = metrics.at_threshold(scores, labels, 0.025)
    assert (c.tp, c.fp, c.tn, c.fn) == (2, 2, 1, 1)       # 0.025 passes, 0.024 does not
    assert c.precision == 0.5 and c.recall == pytest.approx(2 / 3)
    assert c.f1 == pytest.approx(2 * 2 / (2 * 2 + 2 + 1))
    assert c.accuracy == 0.5 and c.fpr == pytest.approx(2 / 3)
    nothing = metrics.at_threshold(scores, labels, 1.0)
    assert math.isnan(nothing.precision) and nothing.as_dict()["precision"] is None


def test_youden_takes_the_best_j_and_of_equals_the_lowest_threshold():
    scores = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6]
    labels = [False, False, True, False, True, True]
    tau, j = metrics.youden(scores, labels)
    assert tau == 0.3 and j == pytest.approx(1 - 1 / 3)
    tied = metrics.youden([0.1, 0.2, 0.3, 0.4], [False, True, False, True])
    assert tied[0] == 0.2             # J = 0.5 at 0.2 and at 0.4: the lower threshold


def test_bootstrap_interval_covers_the_auc_and_groups_widen_it():
    rng = np.random.default_rng(1)
    n = 400
    labels = rng.random(n) < 0.5
    # Frames of 20 ROIs that share an offset: ROIs of one frame are not independent.
    frame = np.repeat(np.arange(n // 20), 20)
    offset = rng.normal(0, 0.6, n // 20)[frame]
    scores = labels * 0.8 + offset + rng.normal(0, 0.5, n)
    a = metrics.auc(scores, labels)
    per_roi = metrics.bootstrap_auc(scores, labels, None, n_boot=800, seed=2)
    per_frame = metrics.bootstrap_auc(scores, labels, frame, n_boot=800, seed=2)
    assert per_roi.low < a < per_roi.high and per_frame.low < a < per_frame.high
    assert per_frame.groups == n // 20 and per_roi.groups == n
    assert (per_frame.high - per_frame.low) > 1.2 * (per_roi.high - per_roi.low)
    same = metrics.bootstrap_auc(scores, labels, frame, n_boot=800, seed=2)
    assert (same.low, same.high) == (per_frame.low, per_frame.high)


def test_weighted_auc_matches_duplicating_samples():
    scores = np.array([0.1, 0.4, 0.35, 0.8, 0.8, 0.2])
    labels = np.array([False, True, False, True, False, True])
    weights = np.array([[2.0, 1.0, 0.0, 3.0, 1.0, 1.0]])
    dup_s = np.repeat(scores, weights[0].astype(int))
    dup_y = np.repeat(labels, weights[0].astype(int))
    assert metrics._weighted_auc(scores, labels, weights)[0] == pytest.approx(
        brute_auc(dup_s.tolist(), dup_y.tolist()))


def test_bad_input_is_a_clear_error():
    with pytest.raises(ValueError, match="2 scores but 3 labels"):
        metrics.auc([0.1, 0.2], [True, False, True])
    with pytest.raises(ValueError, match="finite"):
        metrics.auc([0.1, float("nan")], [True, False])
