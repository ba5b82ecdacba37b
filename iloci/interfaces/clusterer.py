"""The clusterer's interface: groups of exemplars' PB vectors (the concepts' prototypes)."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


__all__ = ["Clusterer"]


@runtime_checkable
class Clusterer(Protocol):
    """Complete-link agglomerative clustering cut at a distance.

    The contract is complete link, and only complete link: the partition
    must be the one agglomerative complete-link clustering gives at the cut,
    i.e. (1) no cluster's diameter (largest pairwise Euclidean distance
    between its members) exceeds ``distance_threshold``, and (2) any two
    clusters are further apart than it under complete link (their farthest
    pair of members), so no two could still merge. The learner's validity
    rules for prototypes (the paper's eq. 1, :mod:`iloci.concepts.clustering`)
    read ``D_cutoff`` as this diameter bound. Another algorithm (single or
    average link, k-means, DBSCAN/HDBSCAN, an HDBSCAN-seeded search) gives
    other partitions and fails the conformance check ``cl_complete_link``
    (:mod:`iloci.testing`), even when it is a fine clusterer: iloci does not
    support it as a ``Clusterer``. A plugin may compute the complete-link
    partition any way it likes (faster, on a GPU, seeded by another method
    and then repaired), as long as the result is that partition.
    """

    def cluster(self, points: np.ndarray, distance_threshold: float) -> np.ndarray:
        """Cluster points so that no cluster's diameter exceeds the threshold.

        Parameters
        ----------
        points : ndarray, shape (M, P)
        distance_threshold : float
            Clusters are merged while their complete-link distance is
            ``<= distance_threshold``.

        Returns
        -------
        ndarray of int, shape (M,)
            Labels ``0..K-1`` numbered in order of first appearance, so two
            back ends giving the same partition give the same labels.

        Raises
        ------
        InvalidInputError
            ``points`` is not a finite 2-D array, or the threshold is
            negative or not finite.
        """
        ...
