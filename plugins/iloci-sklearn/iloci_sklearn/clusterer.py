"""Complete-link agglomerative clustering with scikit-learn."""

from __future__ import annotations

import numpy as np
from sklearn.cluster import AgglomerativeClustering

from iloci.concepts.labels import canonical_labels, check_points


class SklearnClusterer:
    """Complete-link clusters cut at a distance (``AgglomerativeClustering``).

    sklearn merges while the linkage distance is strictly below its
    ``distance_threshold``; scipy's ``fcluster`` keeps merges at distances
    ``<= t``. The threshold is nudged up by one ulp so both back ends cut
    at the same place and give identical partitions.
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
        model = AgglomerativeClustering(
            n_clusters=None, linkage="complete", metric="euclidean",
            distance_threshold=float(np.nextafter(threshold, np.inf)))
        return canonical_labels(model.fit_predict(x))
