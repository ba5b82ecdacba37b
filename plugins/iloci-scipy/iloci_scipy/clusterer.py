"""Complete-link agglomerative clustering with scipy."""

from __future__ import annotations

import numpy as np
from scipy.cluster.hierarchy import fcluster, linkage

from iloci.concepts.labels import canonical_labels, check_points


class ScipyClusterer:
    """Complete-link clusters cut at a distance (``scipy.cluster.hierarchy``).

    Two clusters merge while their complete-link distance (the largest
    pairwise Euclidean distance between their members) is ``<=
    distance_threshold``.
    """

    def cluster(self, points: np.ndarray, distance_threshold: float) -> np.ndarray:
        """Labels, shape (M,), numbered 0.. in order of first appearance.

        Parameters
        ----------
        points : ndarray, shape (M, P)
        distance_threshold : float
        """
        x, threshold = check_points(points, distance_threshold)
        if len(x) == 1:
            return np.zeros(1, dtype=np.int64)
        z = linkage(x, method="complete", metric="euclidean")
        return canonical_labels(fcluster(z, t=threshold, criterion="distance"))
