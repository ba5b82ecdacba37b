"""iloci's first baseline, DTW 1-NN on raw positions: now ``dtw_raw`` of
:mod:`iloci.evaluation.baselines`, which also has the honest ones (DTW on
normalised paths, the $1 recognizer). Kept for code that imports it here.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from iloci.evaluation.baselines import _resample_time, dtw_raw_1nn
from iloci.interfaces import Demonstration

__all__ = ["resample_positions", "dtw_1nn"]


def resample_positions(demo: Demonstration, points: int = 50) -> np.ndarray:
    """Positions linearly resampled at ``points`` equal time steps, shape (points, 2)."""
    return _resample_time(demo, points)


def dtw_1nn(learn: Sequence[Demonstration], test: Sequence[Demonstration], *,
            points: int = 50) -> list[str]:
    """DTW 1-NN on raw positions (:func:`iloci.evaluation.baselines.dtw_raw_1nn`)."""
    return dtw_raw_1nn(learn, test, points=points)
