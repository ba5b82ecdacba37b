"""Baselines iloci's recognition is compared with, run on the same folds in the same run.

Each baseline is a labelled 1-nearest-neighbour classifier: every learning
demonstration is stored with its true concept (no feedback, no network), and
each test demonstration takes the concept of its nearest stored one. They
differ in how two pen paths are compared:

``dtw_normalised``
    Dynamic time warping (``dtaidistance``'s C implementation, Euclidean
    point cost, no window) between paths resampled to 50 points equally
    spaced in time, translated so their centroid is at the origin and scaled
    uniformly so the larger side of their bounding box is 1. The
    translation and uniform scaling are the normalisation of the $P
    recognizer (Vatavu, Anthony and Wobbrock 2012, "Gestures as point
    clouds: a $P recognizer for user interface prototypes", ICMI,
    doi:10.1145/2388676.2388732, steps SCALE and TRANSLATE-TO-ORIGIN);
    keeping the aspect ratio, unlike $1's non-uniform scaling, keeps lines
    and dots apart. This is the strongest of the three on LASA.
``dollar1``
    The $1 unistroke recognizer (Wobbrock, Wilson and Li 2007, "Gestures
    without libraries, toolkits or training: a $1 recognizer for user
    interface prototypes", UIST, doi:10.1145/1294211.1294238), implemented
    from the paper's pseudocode (its appendix A): resample to N = 64
    points equally spaced along the path, rotate so the indicative angle
    (centroid to first point) is 0, scale non-uniformly to a 250 x 250
    reference square, translate the centroid to the origin, and score by the
    path distance minimised over rotations in +-45 degrees with a golden
    section search to a 2 degree threshold. No PyPI package of it is kept
    up (checked 2026-12: ``dollar-one-recognizer-py`` has one release and no
    tests), hence this implementation.
``dtw_raw``
    iloci's first baseline (:func:`iloci.evaluation.baseline.dtw_1nn`):
    DTW on the raw positions resampled to 50 points in time, without
    centring or scaling, so it depends on where and how large a shape was
    drawn. Kept only under this name, for continuity with earlier reports.

A claim that iloci does well names the best of these
(:func:`best_baseline`) on the same folds.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from iloci.errors import InvalidInputError, MissingBackendError
from iloci.evaluation.metrics import correct_classification_rate
from iloci.interfaces import Demonstration

__all__ = ["Baseline", "BASELINES", "BASELINE_NAMES", "normalise_path", "dtw_normalised_1nn",
           "dollar1_1nn", "dtw_raw_1nn", "dollar1_resample", "dollar1_template",
           "run_baselines", "best_baseline"]

#: Points a path is resampled to for the DTW baselines (in time).
DTW_POINTS = 50
#: $1's resampling size N, reference square size and angle search (Wobbrock et al. 2007, sec. 4).
DOLLAR1_N = 64
DOLLAR1_SQUARE = 250.0
DOLLAR1_ANGLE = math.radians(45.0)
DOLLAR1_THRESHOLD = math.radians(2.0)
_PHI = 0.5 * (-1.0 + math.sqrt(5.0))


def _check(demos: Sequence[Demonstration], what: str, *, labelled: bool) -> list[Demonstration]:
    demos = list(demos)
    if not demos:
        raise InvalidInputError(f"the baselines need at least one {what} demonstration.")
    for i, d in enumerate(demos):
        if not isinstance(d, Demonstration):
            raise InvalidInputError(f"{what}[{i}] is a {type(d).__name__}, not a Demonstration.")
        if labelled and d.true_concept is None:
            raise InvalidInputError(
                f"{what} demonstration {d.key!r} has no true_concept: a 1-NN baseline "
                "stores each learning demonstration with its concept; give it one.")
    return demos


def _resample_time(demo: Demonstration, points: int) -> np.ndarray:
    t = demo.times
    assert t is not None  # Demonstration fills in times when none are given
    grid = np.linspace(t[0], t[-1], points)
    return np.column_stack([np.interp(grid, t, demo.positions[:, k]) for k in range(2)])


def normalise_path(demo: Demonstration, points: int = DTW_POINTS) -> np.ndarray:
    """The path ``dtw_normalised`` compares: resampled in time, centred, scaled.

    Parameters
    ----------
    demo : Demonstration
    points : int
        Samples, equally spaced in time from the first to the last.

    Returns
    -------
    ndarray, shape (points, 2)
        Centroid at the origin, larger bounding-box side 1 (unitless).
        The normalisation of $P (Vatavu et al. 2012; module docstring).
    """
    p = _resample_time(demo, points)
    p = p - p.mean(axis=0)
    size = float(np.max(np.ptp(p, axis=0)))
    return p / size if size > 0 else p


def _dtw_1nn(ref: list[np.ndarray], ref_labels: list[str], query: list[np.ndarray]) -> list[str]:
    try:
        from dtaidistance import dtw_ndim
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise MissingBackendError("baseline", "dtw", ["dtaidistance"],
                                  "pip install 'iloci[report]' (or: pip install dtaidistance)"
                                  ) from exc
    series = [np.ascontiguousarray(s, dtype=np.float64) for s in ref + query]
    n = len(ref)
    # dtaidistance fills only the upper triangle (row < column): ask for the
    # reference-rows x query-columns block and transpose it.
    dist = dtw_ndim.distance_matrix_fast(series, block=((0, n), (n, len(series))),
                                         parallel=False)
    block = np.asarray(dist)[:n, n:].T
    return [ref_labels[i] for i in np.argmin(block, axis=1)]


def dtw_normalised_1nn(learn: Sequence[Demonstration], test: Sequence[Demonstration], *,
                       points: int = DTW_POINTS) -> list[str]:
    """Predicted concept of each test demonstration by DTW 1-NN on normalised paths.

    Parameters
    ----------
    learn : sequence of Demonstration
        Labelled (``true_concept`` set) learning demonstrations.
    test : sequence of Demonstration
    points : int
        Resampling length (in time).

    Returns
    -------
    list of str, length ``len(test)``

    Raises
    ------
    InvalidInputError
        An empty set or an unlabelled learning demonstration.
    MissingBackendError
        ``dtaidistance`` is not installed (``pip install 'iloci[report]'``).
    """
    learn = _check(learn, "learn", labelled=True)
    test = _check(test, "test", labelled=False)
    return _dtw_1nn([normalise_path(d, points) for d in learn],
                    [str(d.true_concept) for d in learn],
                    [normalise_path(d, points) for d in test])


def dtw_raw_1nn(learn: Sequence[Demonstration], test: Sequence[Demonstration], *,
                points: int = DTW_POINTS) -> list[str]:
    """DTW 1-NN on raw positions resampled in time (``dtw_raw``; module docstring).

    Same parameters, returns and errors as :func:`dtw_normalised_1nn`.
    """
    learn = _check(learn, "learn", labelled=True)
    test = _check(test, "test", labelled=False)
    return _dtw_1nn([_resample_time(d, points) for d in learn],
                    [str(d.true_concept) for d in learn],
                    [_resample_time(d, points) for d in test])


# ---------------------------------------------------------------- $1 recognizer

def dollar1_resample(points: np.ndarray, n: int = DOLLAR1_N) -> np.ndarray:
    """$1 step 1: ``n`` points equally spaced along the path (shape (n, 2)).

    Linear interpolation at ``n`` equally spaced arc lengths, which is what
    the paper's incremental RESAMPLE computes (without its floating-point
    drift that sometimes drops the last point).
    """
    p = np.asarray(points, dtype=np.float64)
    seg = np.hypot(*np.diff(p, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0:
        return np.repeat(p[:1], n, axis=0)
    keep = np.concatenate([[True], seg > 0])  # np.interp needs increasing abscissae
    grid = np.linspace(0.0, s[-1], n)
    return np.column_stack([np.interp(grid, s[keep], p[keep, k]) for k in range(2)])


def _rotate(p: np.ndarray, theta: float | np.ndarray) -> np.ndarray:
    """Rotate (..., n, 2) points about their centroid by ``theta`` (rad, per leading item)."""
    c = p.mean(axis=-2, keepdims=True)
    th = np.asarray(theta, dtype=np.float64)[..., None]
    cos, sin = np.cos(th), np.sin(th)
    d = p - c
    x = d[..., 0] * cos - d[..., 1] * sin
    y = d[..., 0] * sin + d[..., 1] * cos
    return np.stack([x, y], axis=-1) + c


def dollar1_template(points: np.ndarray, n: int = DOLLAR1_N) -> np.ndarray:
    """$1 steps 1-3 on one path: resampled, rotated to indicative angle 0, scaled, translated.

    Parameters
    ----------
    points : ndarray, shape (N, 2)
    n : int
        Resampling size (the paper's N = 64).

    Returns
    -------
    ndarray, shape (n, 2)
        Fitted to a 250 x 250 square (non-uniformly, as the paper does; a
        degenerate side is left unscaled), centroid at the origin.
    """
    p = dollar1_resample(points, n)
    c = p.mean(axis=0)
    angle = math.atan2(c[1] - p[0, 1], c[0] - p[0, 0])
    p = _rotate(p, -angle)
    side = np.ptp(p, axis=0)
    side = np.where(side > 1e-12 * max(float(side.max()), 1e-300), side, 1.0)
    p = p * (DOLLAR1_SQUARE / side)
    return p - p.mean(axis=0)


def _path_distance(cand: np.ndarray, templates: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Mean point distance of ``cand`` rotated by ``theta[i]`` to ``templates[i]``."""
    rotated = _rotate(np.broadcast_to(cand, templates.shape), theta)
    return np.hypot(*(rotated - templates).transpose(2, 0, 1)).mean(axis=1)


def _dollar1_distances(cand: np.ndarray, templates: np.ndarray) -> np.ndarray:
    """DISTANCE-AT-BEST-ANGLE (golden section search) of one candidate to every template."""
    k = len(templates)
    a = np.full(k, -DOLLAR1_ANGLE)
    b = np.full(k, DOLLAR1_ANGLE)
    x1 = _PHI * a + (1 - _PHI) * b
    f1 = _path_distance(cand, templates, x1)
    x2 = (1 - _PHI) * a + _PHI * b
    f2 = _path_distance(cand, templates, x2)
    # every template narrows its own interval; the interval width shrinks by
    # the same factor for all, so they finish together
    while float(np.max(np.abs(b - a))) > DOLLAR1_THRESHOLD:
        left = f1 < f2
        b = np.where(left, x2, b)
        a = np.where(left, a, x1)
        nx2 = np.where(left, x1, x2)
        nf2 = np.where(left, f1, f2)
        nx1 = np.where(left, _PHI * a + (1 - _PHI) * b, x2)
        nf1 = np.where(left, np.nan, f2)
        nx2 = np.where(left, nx2, (1 - _PHI) * a + _PHI * b)
        nf2 = np.where(left, nf2, np.nan)
        fresh = _path_distance(cand, templates, np.where(left, nx1, nx2))
        f1 = np.where(left, fresh, nf1)
        f2 = np.where(left, nf2, fresh)
        x1, x2 = nx1, nx2
    return np.minimum(f1, f2)


def dollar1_1nn(learn: Sequence[Demonstration], test: Sequence[Demonstration], *,
                n: int = DOLLAR1_N) -> list[str]:
    """Predicted concept of each test demonstration by the $1 recognizer.

    Every learning demonstration is a template (module docstring).

    Parameters
    ----------
    learn : sequence of Demonstration
        Labelled (``true_concept`` set) learning demonstrations.
    test : sequence of Demonstration
    n : int
        Resampling size (the paper's N = 64).

    Returns
    -------
    list of str, length ``len(test)``

    Raises
    ------
    InvalidInputError
        An empty set or an unlabelled learning demonstration.
    """
    learn = _check(learn, "learn", labelled=True)
    test = _check(test, "test", labelled=False)
    templates = np.stack([dollar1_template(d.positions, n) for d in learn])
    labels = [str(d.true_concept) for d in learn]
    out = []
    for d in test:
        dist = _dollar1_distances(dollar1_template(d.positions, n), templates)
        out.append(labels[int(np.argmin(dist))])
    return out


@dataclass(frozen=True)
class Baseline:
    """One baseline: its name, a one-line description for reports, and its classifier."""

    name: str
    method: str
    predict: Callable[[Sequence[Demonstration], Sequence[Demonstration]], list[str]]


#: The baselines, in the order reports list them.
BASELINES: dict[str, Baseline] = {
    b.name: b for b in (
        Baseline("dtw_normalised",
                 "DTW 1-NN, paths resampled to 50 points in time, centred, scaled to unit size "
                 "($P normalisation, Vatavu et al. 2012)", dtw_normalised_1nn),
        Baseline("dollar1", "$1 recognizer (Wobbrock, Wilson, Li 2007), every learning "
                 "demonstration a template", dollar1_1nn),
        Baseline("dtw_raw", "DTW 1-NN on raw positions resampled to 50 points in time "
                 "(iloci's first baseline)", dtw_raw_1nn),
    )
}
BASELINE_NAMES: tuple[str, ...] = tuple(BASELINES)


def run_baselines(learn: Sequence[Demonstration], test: Sequence[Demonstration],
                  names: Sequence[str] = BASELINE_NAMES) -> dict[str, dict]:
    """Every named baseline on one fold.

    Parameters
    ----------
    learn, test : sequence of Demonstration
        The fold's learning set (labelled) and test set.
    names : sequence of str
        Baselines to run (keys of :data:`BASELINES`).

    Returns
    -------
    dict
        Name -> ``{"predicted": list of str, "ccr": float (fraction in
        [0, 1], NaN when a test demonstration has no true concept), "seconds": float}``.

    Raises
    ------
    InvalidInputError
        An unknown baseline name, an empty set or an unlabelled learning
        demonstration.
    """
    import time


    unknown = [n for n in names if n not in BASELINES]
    if unknown:
        raise InvalidInputError(f"unknown baseline(s) {unknown}; known: "
                                f"{', '.join(BASELINE_NAMES)}.")
    test = list(test)
    truth = [d.true_concept for d in test]
    out: dict[str, dict] = {}
    for name in names:
        t0 = time.perf_counter()
        predicted = BASELINES[name].predict(learn, test)
        seconds = time.perf_counter() - t0
        ccr = (correct_classification_rate([str(t) for t in truth], predicted)
               if all(t is not None for t in truth) else float("nan"))
        out[name] = {"predicted": predicted, "ccr": ccr, "seconds": seconds}
    return out


def best_baseline(ccr: Mapping[str, float]) -> tuple[str, float]:
    """The baseline with the highest CCR (ties: the first in :data:`BASELINE_NAMES`).

    Parameters
    ----------
    ccr : mapping of str to float
        Baseline name -> CCR (fraction); NaN entries are ignored.

    Returns
    -------
    (name, ccr)

    Raises
    ------
    InvalidInputError
        No finite CCR in ``ccr``.
    """
    ranked = [(n, float(ccr[n])) for n in BASELINE_NAMES if n in ccr and np.isfinite(ccr[n])]
    ranked += [(n, float(v)) for n, v in ccr.items()
               if n not in BASELINES and np.isfinite(v)]
    if not ranked:
        raise InvalidInputError("best_baseline needs at least one finite CCR.")
    return max(ranked, key=lambda nv: nv[1])
