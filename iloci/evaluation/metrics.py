"""Metrics of the evaluation protocol (numpy only).

Concept labels are strings; matrices are indexed by a fixed, sorted list of
concepts so folds can be averaged.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from iloci.data.concepts import _counts, majority_names

__all__ = [
    "correct_classification_rate",
    "confusion_matrix",
    "confidence_matrix",
    "backward_moving_average",
    "mean_std",
    "majority_names",
    "matched_names",
    "purity",
    "auroc",
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


def matched_names(members: Mapping[str, Sequence[str | None]]) -> dict[str, str | None]:
    """One-to-one names: a maximum matching of robot concepts to true concepts.

    The assignment maximises the number of demonstrations whose robot
    concept is named by their true concept (Hungarian algorithm,
    :func:`scipy.optimize.linear_sum_assignment`), each true concept naming
    at most one robot concept. Robot concepts left without a true concept
    (more robot concepts than true ones, or none known) map to ``None``:
    an answer with such a label is never correct. Stricter than
    :func:`majority_names`, which forgives a split concept.

    Parameters
    ----------
    members : mapping of str to sequence of str
        As for :func:`majority_names`.

    Returns
    -------
    dict
        Robot label -> true concept or ``None``.
    """
    counts = _counts(members)
    robots = list(counts)
    truths = list(dict.fromkeys(t for c in counts.values() for t in c))
    out: dict[str, str | None] = dict.fromkeys(robots)
    if not robots or not truths:
        return out
    # Each robot concept's own majority, when it is strict and no two robot concepts
    # share one, reaches every row's maximum: the only maximum matching (on the
    # pairs of positive gain, the ones kept), the Hungarian algorithm's answer.
    best = {}
    for r, c in counts.items():
        top = max(c.values(), default=0)
        winners = [t for t, n in c.items() if n == top]
        if top > 0 and len(winners) > 1:
            break
        if top > 0:
            best[r] = winners[0]
    else:
        if len(set(best.values())) == len(best):
            out.update(best)
            return out
    from scipy.optimize import linear_sum_assignment
    gain = np.array([[counts[r].get(t, 0) for t in truths] for r in robots], dtype=float)
    rows, cols = linear_sum_assignment(gain, maximize=True)
    for i, j in zip(rows, cols):
        if gain[i, j] > 0:
            out[robots[i]] = truths[j]
    return out


def purity(members: Mapping[str, Sequence[str | None]]) -> float:
    """Concept purity: the fraction of demonstrations in their concept's majority.

    ``sum over robot concepts of (count of its most frequent true concept)
    / number of demonstrations`` (Manning et al., *Introduction to
    Information Retrieval*, 2008, sec. 16.3). 1 when no robot concept mixes
    two true concepts; NaN when no true concept is known.

    Parameters
    ----------
    members : mapping of str to sequence of str
        As for :func:`majority_names`.
    """
    counts = _counts(members)
    total = sum(sum(c.values()) for c in counts.values())
    if not total:
        return float("nan")
    return float(sum(max(c.values(), default=0) for c in counts.values()) / total)


def auroc(positive: Sequence[float], negative: Sequence[float]) -> float:
    """Area under the ROC curve of a score separating two groups.

    The probability that a random ``positive`` scores above a random
    ``negative``, ties counting one half (the Mann-Whitney U statistic
    divided by ``n_pos * n_neg``). NaN when a group is empty.

    Parameters
    ----------
    positive, negative : sequence of float
        Scores of the two groups (e.g. recognition confidence of taught and
        of untaught concepts' demonstrations).
    """
    pos = np.asarray(positive, dtype=np.float64)
    neg = np.asarray(negative, dtype=np.float64)
    if not pos.size or not neg.size:
        return float("nan")
    from scipy.stats import rankdata
    ranks = rankdata(np.concatenate([pos, neg]))
    u = ranks[:pos.size].sum() - pos.size * (pos.size + 1) / 2
    return float(u / (pos.size * neg.size))
