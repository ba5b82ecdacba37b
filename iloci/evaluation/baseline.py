"""The baseline users compare iloci with: DTW 1-nearest-neighbour.

Dynamic time warping from ``dtaidistance`` (C implementation) on the raw
pen trajectories resampled to a fixed number of points in time. No
feedback, no network: every learning demonstration is stored with its true
concept, and each test demonstration takes the concept of its DTW-nearest
learning demonstration.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from iloci.interfaces import Demonstration

__all__ = ["resample_positions", "dtw_1nn"]


def resample_positions(demo: Demonstration, points: int = 50) -> np.ndarray:
    """Positions linearly resampled at ``points`` equal time steps, shape (points, 2)."""
    t = demo.times
    assert t is not None  # Demonstration fills in times when none are given
    grid = np.linspace(t[0], t[-1], points)
    return np.column_stack([np.interp(grid, t, demo.positions[:, k]) for k in range(2)])


def dtw_1nn(learn: Sequence[Demonstration], test: Sequence[Demonstration], *,
            points: int = 50) -> list[str]:
    """Predicted concept of each test demonstration, by DTW 1-NN.

    Parameters
    ----------
    learn : sequence of Demonstration
        Labelled (``true_concept`` set) learning demonstrations.
    test : sequence of Demonstration
    points : int
        Resampling length.

    Returns
    -------
    list of str, length ``len(test)``
    """
    try:
        from dtaidistance import dtw_ndim
    except ImportError as exc:  # pragma: no cover - depends on the environment
        from iloci.errors import MissingBackendError
        raise MissingBackendError("baseline", "dtw", ["dtaidistance"],
                                  "pip install dtaidistance") from exc
    series = [resample_positions(d, points) for d in list(learn) + list(test)]
    n = len(learn)
    # dtaidistance fills only the upper triangle (row < column): ask for the
    # learn-rows x test-columns block and transpose it.
    dist = dtw_ndim.distance_matrix_fast(
        series, block=((0, n), (n, len(series))), parallel=False)
    block = np.asarray(dist)[:n, n:].T
    nearest = np.argmin(block, axis=1)
    return [str(learn[i].true_concept) for i in nearest]
