"""Helpers shared by Clusterer back ends (numpy only)."""

from __future__ import annotations

import numpy as np

from iloci.errors import InvalidInputError

__all__ = ["canonical_labels", "check_points"]


def canonical_labels(labels: np.ndarray) -> np.ndarray:
    """Renumber labels 0.. in order of first appearance, shape (M,) int64."""
    labels = np.asarray(labels)
    _, first = np.unique(labels, return_index=True)
    order = np.argsort(first)
    mapping = {labels[first[i]]: new for new, i in enumerate(order)}
    return np.array([mapping[v] for v in labels], dtype=np.int64)


def check_points(points: object, distance_threshold: object) -> tuple[np.ndarray, float]:
    """Validate clustering input; return (points (M, P) float64, threshold)."""
    try:
        x = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidInputError("points to cluster must be a numeric array of shape "
                                "(M, P).") from None
    if x.ndim != 2 or x.shape[0] < 1 or x.shape[1] < 1:
        raise InvalidInputError(f"points to cluster must have shape (M, P) with M >= 1, "
                                f"got {x.shape}.")
    if not np.all(np.isfinite(x)):
        raise InvalidInputError("points to cluster contain NaN or inf.")
    try:
        t = float(distance_threshold)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InvalidInputError(f"distance_threshold must be a number, got "
                                f"{distance_threshold!r}.") from None
    if not np.isfinite(t) or t < 0:
        raise InvalidInputError(f"distance_threshold must be finite and >= 0, got {t}.")
    return x, t
