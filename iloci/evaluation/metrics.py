"""Metrics of the evaluation protocol (numpy only).

Concept labels are strings; matrices are indexed by a fixed, sorted list of
concepts so folds can be averaged.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = [
    "correct_classification_rate",
    "confusion_matrix",
    "confidence_matrix",
    "backward_moving_average",
    "mean_std",
]


def correct_classification_rate(true: Sequence[str], predicted: Sequence[str]) -> float:
    """Fraction of test demonstrations whose predicted concept is the true one."""
    if len(true) != len(predicted):
        raise ValueError("true and predicted differ in length")
    if not len(true):
        return float("nan")
    return float(np.mean([t == p for t, p in zip(true, predicted)]))


def confusion_matrix(true: Sequence[str], predicted: Sequence[str],
                     concepts: Sequence[str]) -> np.ndarray:
    """Row-normalised confusion matrix, shape (C, C).

    Row ``i`` is the distribution of predictions for demonstrations of
    concept ``concepts[i]``; rows of concepts with no demonstration are NaN.
    """
    index = {c: i for i, c in enumerate(concepts)}
    counts = np.zeros((len(concepts), len(concepts)))
    for t, p in zip(true, predicted):
        counts[index[t], index[p]] += 1
    totals = counts.sum(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(totals > 0, counts / totals, np.nan)


def confidence_matrix(true: Sequence[str], predicted: Sequence[str],
                      confidence: Sequence[float], concepts: Sequence[str]) -> np.ndarray:
    """Mean confidence of each (true, predicted) pair, shape (C, C); NaN where none."""
    index = {c: i for i, c in enumerate(concepts)}
    sums = np.zeros((len(concepts), len(concepts)))
    counts = np.zeros_like(sums)
    for t, p, c in zip(true, predicted, confidence):
        sums[index[t], index[p]] += c
        counts[index[t], index[p]] += 1
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / counts, np.nan)


def backward_moving_average(x: Sequence[float] | np.ndarray, window: int = 7) -> np.ndarray:
    """``y[i] = mean(x[max(0, i - window + 1) : i + 1])``, shape (len(x),).

    The paper smooths the +1/-1 reinforcement signal this way (window 7).
    """
    a = np.asarray(x, dtype=np.float64)
    if a.size == 0:
        return a
    c = np.concatenate([[0.0], np.cumsum(a)])
    i = np.arange(1, len(a) + 1)
    lo = np.maximum(0, i - window)
    return (c[i] - c[lo]) / (i - lo)


def mean_std(values: Sequence[float]) -> tuple[float, float]:
    """Mean and population standard deviation (ddof=0, as over the 5 folds)."""
    a = np.asarray(values, dtype=np.float64)
    return float(np.mean(a)), float(np.std(a))
