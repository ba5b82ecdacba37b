"""Metrics and figures of the evaluation report."""

from __future__ import annotations

import numpy as np
import pytest

from iloci.evaluation.metrics import (auroc, backward_moving_average, confidence_matrix,
                                      confusion_matrix, correct_classification_rate,
                                      majority_names, matched_names, mean_std, purity)


def test_backward_moving_average_window_7():
    x = np.array([1, -1, 1, 1, 1, 1, 1, 1, -1])
    y = backward_moving_average(x, 7)
    assert y[0] == 1 and y[1] == 0
    assert y[6] == pytest.approx(np.mean(x[:7]))
    assert y[8] == pytest.approx(np.mean(x[2:9]))
    assert backward_moving_average([], 7).shape == (0,)


def test_confusion_and_confidence():
    concepts = ["a", "b", "c"]
    true = ["a", "a", "b", "b", "b"]
    pred = ["a", "b", "b", "b", "a"]
    conf = [0.9, 0.2, 0.8, 0.6, 0.1]
    m = confusion_matrix(true, pred, concepts)
    np.testing.assert_allclose(m[0], [0.5, 0.5, 0])
    np.testing.assert_allclose(m[1], [1 / 3, 2 / 3, 0])
    assert np.all(np.isnan(m[2]))
    c = confidence_matrix(true, pred, conf, concepts)
    assert c[1, 1] == pytest.approx(0.7) and c[0, 1] == pytest.approx(0.2)
    assert np.isnan(c[0, 2])
    assert correct_classification_rate(true, pred) == pytest.approx(0.6)
    assert mean_std([0.9, 1.0]) == pytest.approx((0.95, 0.05))


def test_figures_write_pngs(tmp_path):
    pytest.importorskip("matplotlib")
    from iloci.evaluation import figures
    rng = np.random.default_rng(0)
    paths = [
        figures.plot_matrix(rng.uniform(size=(3, 3)), ["a", "b", "c"], tmp_path / "m.png",
                            title="t", cbar_label="l"),
        figures.plot_reinforcement([[1, -1, 1], [1, 1]], tmp_path / "r.png"),
        figures.plot_first_guess([[True, False], [True]], tmp_path / "f.png"),
        figures.plot_shapes({"a": rng.normal(size=(10, 2))}, tmp_path / "s.png"),
    ]
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


#: A memory whose teacher erred: c1 merged Angle into GShape, Sine was split in two.
MEMBERS = {"c1": ["GShape", "GShape", "Angle"], "c2": ["Sine", "Sine"], "c3": ["Sine"],
           "c4": [None]}


def test_majority_names_forgive_a_split_and_name_a_merge_by_its_majority():
    assert majority_names(MEMBERS) == {"c1": "GShape", "c2": "Sine", "c3": "Sine", "c4": None}


def test_matched_names_are_one_to_one():
    names = matched_names(MEMBERS)
    assert names["c1"] == "GShape" and names["c2"] == "Sine"
    assert names["c3"] is None and names["c4"] is None  # Sine is taken; c4 knows nothing
    assert matched_names({}) == {}


def test_purity_counts_demonstrations_in_their_concepts_majority():
    assert purity(MEMBERS) == pytest.approx(5 / 6)
    assert purity({"c1": ["A", "A"], "c2": ["B"]}) == 1.0
    assert np.isnan(purity({"c1": [None]}))


def test_a_merged_concept_answers_wrong_for_its_minority():
    # an Angle demonstration answered c1 (named GShape) is wrong under both namings
    for names in (majority_names(MEMBERS), matched_names(MEMBERS)):
        assert correct_classification_rate(["Angle", "GShape"],
                                           [names["c1"], names["c1"]]) == 0.5


def test_auroc_is_the_probability_a_positive_outranks_a_negative():
    assert auroc([3, 4], [1, 2]) == 1.0
    assert auroc([1, 2], [3, 4]) == 0.0
    assert auroc([1, 1], [1, 1]) == 0.5
    assert auroc([0.9, 0.2], [0.5]) == 0.5
    assert np.isnan(auroc([], [1.0]))


@pytest.mark.parametrize("n", [21, 50])
def test_stream_headline_says_when_the_stream_is_too_short_to_score(n):
    from iloci.config import load_config
    from iloci.evaluation.report import stream_headline
    from iloci.evaluation.stream import FIRST_SCORED, summarize_stream

    steps = [{"correct": i % 2 == 0, "feedbacks": [1] * (i % 3), "seen_before": i > 3}
             for i in range(n)]
    from iloci.interfaces import COMPONENT_KINDS
    # every component named, none looked up: runs in the bare kernel's env too
    metrics = summarize_stream(steps, load_config(None, supplied=COMPONENT_KINDS), 1.0)
    metrics.update(purity=1.0, concepts=3)
    text = stream_headline(metrics)
    assert "nan" not in text
    if n < FIRST_SCORED:
        assert f"{FIRST_SCORED}-{n}" not in text
        assert f"the stream has {n} demonstrations, scoring starts at demonstration " \
               f"{FIRST_SCORED}" in text
    else:
        assert f"demonstrations {FIRST_SCORED}-{n} | " in text
