"""Metrics and figures of the evaluation report."""

from __future__ import annotations

import numpy as np
import pytest

from iloci.evaluation.metrics import (backward_moving_average, confidence_matrix,
                                      confusion_matrix, correct_classification_rate,
                                      mean_std)


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
