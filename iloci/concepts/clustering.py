"""Clustering a concept's entries into prototypes (the paper's eq. 1 and validity rules).

When a rewarded demonstration becomes a new exemplar and the concept's
total numSamples exceeds ``num_threshold``, the PB vectors of the concept's
entries are clustered with complete link (by the configured
:class:`~iloci.interfaces.Clusterer`), cut at

    D_cutoff = mu - K_cutoff * sigma

where mu and sigma are the mean and standard deviation of the pairwise
Euclidean distances among the concept's PB vectors. A cluster is *valid*
when

1. the sum of its members' numSamples exceeds ``num_threshold``,
2. it holds at least one exemplar, and
3. the mean pairwise distance among its PB vectors is below D_cutoff.

Each valid cluster with two or more members is replaced by its medoid (the
member whose summed distance to the others is smallest), whose numSamples
becomes the cluster's sum. A one-member cluster is left as it is: replacing
an entry by itself changes nothing.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.distance import pdist, squareform

from iloci.errors import InvalidInputError
from iloci.interfaces import Clusterer

__all__ = ["pairwise_distances", "d_cutoff", "medoid", "ClusterPlan", "plan_clusters"]


def pairwise_distances(pbs: np.ndarray) -> np.ndarray:
    """Euclidean distance matrix of PB vectors.

    Parameters
    ----------
    pbs : ndarray, shape (M, P)

    Returns
    -------
    ndarray, shape (M, M)
    """
    return squareform(_pdist(pbs))


def _pdist(pbs: np.ndarray) -> np.ndarray:
    """Condensed Euclidean distances of every pair ``i < j`` (scipy's ``pdist``)."""
    x = np.asarray(pbs, dtype=np.float64)
    if x.ndim != 2:
        raise InvalidInputError(f"PB vectors must have shape (M, P), got {x.shape}.")
    return pdist(x, "euclidean")


def d_cutoff(pbs: np.ndarray, k_cutoff: float) -> float:
    """D_cutoff = mu - K_cutoff * sigma of the pairwise PB distances.

    Parameters
    ----------
    pbs : ndarray, shape (M, P)
        The PB vectors of one concept's entries, ``M >= 2``.
    k_cutoff : float

    Returns
    -------
    float
        NaN when ``M < 2`` (no pair).
    """
    d = _pdist(pbs)
    if d.size == 0:
        return float("nan")
    return float(d.mean() - k_cutoff * d.std())


def medoid(pbs: np.ndarray) -> int:
    """Index of the member with the smallest summed distance to the others.

    Parameters
    ----------
    pbs : ndarray, shape (M, P)

    Returns
    -------
    int
        Ties go to the lowest index (the oldest entry).
    """
    return int(np.argmin(pairwise_distances(pbs).sum(axis=1)))


@dataclass(frozen=True)
class ClusterPlan:
    """What clustering one concept decided.

    Attributes
    ----------
    d_cutoff : float
        The cut distance (NaN when the concept has fewer than two entries).
    labels : ndarray of int, shape (M,)
        Cluster of each of the concept's entries (all ``-1`` when not
        clustered).
    valid : tuple of tuple of int
        Valid clusters with at least two members, as indices into the
        concept's entries.
    medoids : tuple of int
        The medoid of each valid cluster (an index into the concept's
        entries).
    """

    d_cutoff: float
    labels: np.ndarray
    valid: tuple[tuple[int, ...], ...]
    medoids: tuple[int, ...]


def checked_labels(clusterer: Any, returned: Any, x: np.ndarray, cut: float) -> np.ndarray:
    """What ``clusterer.cluster(x, cut)`` returned, checked as the interface promises.

    :class:`~iloci.interfaces.Clusterer`: one label per point, integers
    from 0, and the complete-link partition: no cluster wider than the cut,
    and no two clusters whose farthest pair lies within it (complete link
    would merge them). A cast to int would read
    NaN as a huge number, and 0.5 as 0: a clusterer plugin's fault then
    became a memory of other prototypes, with exit 0 (a plugin audit).

    Returns
    -------
    ndarray of int64, shape (M,)

    Raises
    ------
    InvalidInputError
        Naming the clusterer and what is wrong.
    """
    name = type(clusterer).__name__
    m = len(x)

    def fault(what: str) -> InvalidInputError:
        return InvalidInputError(f"clusterer {name} {what}; nothing was changed. Fix the "
                                 "clusterer (iloci.testing.check_component checks it), or "
                                 "choose another with [clusterer] name.")
    try:
        raw = np.asarray(returned)
    except Exception:  # noqa: BLE001  (an object numpy cannot read)
        raise fault(f"returned {type(returned).__name__}, not an array of labels") from None
    if raw.shape != (m,):
        raise fault(f"returned labels of shape {raw.shape} for {m} points")
    if raw.dtype == bool or not np.issubdtype(raw.dtype, np.number) or np.iscomplexobj(raw):
        raise fault(f"returned labels of dtype {raw.dtype}, not integers")
    as_float = raw.astype(np.float64)
    whole = np.isfinite(as_float) & (as_float == np.round(as_float))
    if not whole.all():
        bad = int(np.flatnonzero(~whole)[0])
        raise fault(f"returned label {raw[bad].item()!r} (point {bad}); labels are whole numbers")
    if np.any(as_float < 0):
        raise fault(f"returned a negative label ({int(as_float.min())}); labels count from 0")
    labels = as_float.astype(np.int64)
    dist = squareform(_pdist(x))
    groups = [np.flatnonzero(labels == lab) for lab in np.unique(labels)]
    tol = cut * 1e-9
    for members in groups:
        wide = float(dist[np.ix_(members, members)].max())
        if wide > cut + tol:
            raise fault(f"put points {wide:.4g} apart into one cluster, over the cut "
                        f"{cut:.4g} (D_cutoff); complete-link clusters are never wider "
                        "than the cut")
    for i, a in enumerate(groups):
        for b in groups[i + 1:]:
            link = float(dist[np.ix_(a, b)].max())
            if link <= cut - tol:
                raise fault(f"kept apart two clusters (points {a.tolist()} and {b.tolist()}) "
                            f"whose farthest pair is {link:.4g} apart, within the cut "
                            f"{cut:.4g}: complete link merges them")
    return labels


def plan_clusters(pbs: np.ndarray, num_samples: Sequence[int], exemplar: Sequence[bool], *,
                  clusterer: Clusterer, k_cutoff: float, num_threshold: int) -> ClusterPlan:
    """Cluster one concept's entries and pick the valid clusters and their medoids.

    Parameters
    ----------
    pbs : ndarray, shape (M, P)
        PB vectors of the concept's entries.
    num_samples : sequence of int, length M
    exemplar : sequence of bool, length M
        Whether each entry is an exemplar (not a prototype).
    clusterer : Clusterer
    k_cutoff : float
    num_threshold : int

    Returns
    -------
    ClusterPlan
    """
    x = np.asarray(pbs, dtype=np.float64)
    m = len(x)
    ns = np.asarray(num_samples, dtype=np.int64)
    ex = np.asarray(exemplar, dtype=bool)
    if ns.shape != (m,) or ex.shape != (m,):
        raise InvalidInputError(f"num_samples and exemplar must have length {m}, got "
                                f"{ns.shape} and {ex.shape}.")
    cut = d_cutoff(x, k_cutoff) if m >= 2 else float("nan")
    none = ClusterPlan(cut, np.full(m, -1, dtype=np.int64), (), ())
    # a cut at or below 0 cannot group distinct PB vectors
    if m < 2 or not np.isfinite(cut) or cut <= 0:
        return none
    labels = checked_labels(clusterer, clusterer.cluster(x, cut), x, cut)
    valid: list[tuple[int, ...]] = []
    medoids: list[int] = []
    for lab in dict.fromkeys(labels.tolist()):
        members = np.flatnonzero(labels == lab)
        if len(members) < 2:
            continue
        mean_pair = float(_pdist(x[members]).mean())
        if ns[members].sum() > num_threshold and ex[members].any() and mean_pair < cut:
            valid.append(tuple(int(i) for i in members))
            medoids.append(int(members[medoid(x[members])]))
    return ClusterPlan(cut, labels, tuple(valid), tuple(medoids))
