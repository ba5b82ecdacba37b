"""From a pen trajectory to the robot's drawing: rests, resampling, smoothing, fitting.

The paper (section "sensorimotor") smooths each demonstration, scales it and
fits it into a y-z rectangle of the robot's workspace; its filter and
resolution are not given. A person at a tablet or a mouse draws at their own
pace, at their device's sampling rate, pauses, and jitters; the default, the
path reading (``resample="arc_length"``), reads the drawn *path* and nothing
else (:func:`preprocess`):

* **Screen coordinates**: ``y_axis="down"`` flips y first.
* **Rests** at the start and the end (the pen down before it moves, held
  after it stops) are trimmed (:func:`trim_rests`).
* **Resampling along the path** (``resample="arc_length"``, the default):
  ``steps`` points (default 50, the network's sequence length) evenly spaced
  along the path's length, so the teacher's pace and pauses do not change
  them (:func:`resample_path`). The length is measured on a lightly
  smoothed copy (jitter adds length of its own) and re-measured along the
  smoothed path; a path of fewer than :data:`DENSE` samples is first
  interpolated by a cubic spline, so 25 samples give the curve they were
  taken from rather than a polygon.
* **Smoothing along the path**: a Gaussian local linear regression whose
  bandwidth is a fraction of the path's length (``smoothing``, default 4 %),
  not a number of samples, so it removes the same jitter at 25 samples as
  at 10 000 (:func:`local_linear`). Each sample is weighted by the stretch
  of path it stands for, so samples crowded where the pen was slow do not
  outvote the rest.
* **The paper's time-based reading** (``resample="time"``):
  Savitzky-Golay
  smoothing, cubic, ``smoothing_window`` samples (default 31 of LASA's
  1000), then ``steps`` points evenly in *time* (:func:`smooth`,
  :func:`resample`); with ``rest_tolerance = 0`` nothing is trimmed.
* **Scaling and fitting**: one uniform scale (aspect ratio kept) so the
  path's bounding box fills the rectangle along its tighter side, centred
  in the rectangle (:func:`fit_to_plane`). The teacher's x axis maps to the
  plane's y and the teacher's y to z, so a teacher facing the robot sees
  the shape drawn as they drew it.

The figures behind the choice: the guide's section "How a drawing is read"
and ``benchmarks/results/robustness.json``.
"""

from __future__ import annotations

import numpy as np

from iloci.errors import InvalidDemonstrationError, InvalidInputError
from iloci.interfaces import Demonstration
from iloci.progress import long_step
from iloci.sensorimotor.path import (PRESMOOTH, as_points, densify,
                                     local_linear, path_parameter, resample_path)
from iloci.sensorimotor.robots import DrawingPlane
from iloci.validation import MAX_POINTS, check_size

__all__ = ["MAX_POINTS", "POLYORDER", "PRESMOOTH", "check_size", "densify", "fit_to_plane",
           "local_linear", "path_parameter",
           "preprocess", "resample", "resample_path", "smooth", "trim_rests"]

#: Drawings of at least this many samples show their progress (:func:`iloci.progress.long_step`)
#: when reading them takes over a second; smaller ones take far less.
SHOWN_ABOVE = 20_000


#: Order of the Savitzky-Golay polynomial.
POLYORDER = 3


def smooth(positions: np.ndarray, window: int = 31) -> np.ndarray:
    """Savitzky-Golay (cubic) smoothing of a pen path.

    Parameters
    ----------
    positions : ndarray, shape (N, 2)
    window : int
        Odd window length in points; 0 or 1 returns a copy unchanged. A
        window longer than the path is shortened to the largest odd length
        that fits; paths under 5 points are returned unchanged.

    Returns
    -------
    ndarray, shape (N, 2)

    Raises
    ------
    InvalidInputError
        ``window`` is negative or even.
    InvalidDemonstrationError
        ``positions`` is not a finite (N, 2) array with N >= 3.
    """
    p = as_points(positions)
    w = int(window)
    if w < 0 or (w > 1 and w % 2 == 0):
        raise InvalidInputError(f"smoothing window must be 0, 1 or an odd number of points, "
                                f"got {window}.")
    w = min(w, len(p) if len(p) % 2 else len(p) - 1)
    if w <= POLYORDER:
        return p.copy()
    from scipy.signal import savgol_filter

    return savgol_filter(p, w, POLYORDER, axis=0, mode="interp")


def resample(positions: np.ndarray, times: np.ndarray | None = None, steps: int = 50,
             by: str = "time") -> np.ndarray:
    """Resample a path to ``steps`` points by linear interpolation.

    Parameters
    ----------
    positions : ndarray, shape (N, 2)
    times : ndarray, shape (N,), optional
        Strictly increasing time stamps; default ``0..N-1``. Used when
        ``by="time"``.
    steps : int
        Number of output points, ``>= 3``.
    by : {"time", "arc_length"}
        Uniform in time, or uniform along the path's length.

    Returns
    -------
    ndarray, shape (steps, 2)
        First and last points equal the input's.

    Raises
    ------
    InvalidInputError
        ``steps < 3``, unknown ``by``, or bad ``times``.
    InvalidDemonstrationError
        ``positions`` is not a finite (N, 2) array with N >= 3, or has zero
        length when ``by="arc_length"``.
    """
    p = as_points(positions)
    if int(steps) != steps or steps < 3:
        raise InvalidInputError(f"steps must be an integer >= 3, got {steps}.")
    steps = int(steps)
    if by == "time":
        if times is None:
            s = np.arange(len(p), dtype=np.float64)
        else:
            s = np.asarray(times, dtype=np.float64)
            if s.shape != (len(p),) or not np.all(np.isfinite(s)) or np.any(np.diff(s) <= 0):
                raise InvalidInputError(f"times must be finite, strictly increasing and of "
                                        f"shape ({len(p)},).")
    elif by == "arc_length":
        seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
        keep = np.concatenate([[True], seg > 0])  # drop repeated points (pen at rest)
        p = p[keep]
        s = np.concatenate([[0.0], np.cumsum(seg[seg > 0])])
        if len(p) < 2:
            raise InvalidDemonstrationError("the path has zero length: all points are equal.")
    else:
        raise InvalidInputError(f"resampling must be by 'time' or 'arc_length', got {by!r}.")
    u = np.linspace(s[0], s[-1], steps)
    return np.column_stack([np.interp(u, s, p[:, 0]), np.interp(u, s, p[:, 1])])


def trim_rests(positions: np.ndarray, times: np.ndarray | None = None,
               tolerance: float = 0.01) -> tuple[np.ndarray, np.ndarray | None]:
    """Drop the samples where the pen rests before it starts and after it stops.

    A sample belongs to the starting rest while it stays within
    ``tolerance * extent`` of the first sample (``extent``: the longer side
    of the path's bounding box); the last of them is kept, so the path
    still starts where the pen rested. Likewise at the end.

    Parameters
    ----------
    positions : ndarray, shape (N, 2)
    times : ndarray, shape (N,), optional
        Cut like the positions.
    tolerance : float
        Fraction of the extent; 0 keeps every sample.

    Returns
    -------
    positions : ndarray, shape (M, 2), M <= N
    times : ndarray, shape (M,) or None
    """
    p = as_points(positions)
    if tolerance <= 0:
        return p, times
    r = tolerance * float(np.ptp(p, axis=0).max())
    away0 = np.flatnonzero(np.linalg.norm(p - p[0], axis=1) > r)
    away1 = np.flatnonzero(np.linalg.norm(p - p[-1], axis=1) > r)
    if not len(away0) or not len(away1):  # the pen never leaves its start: nothing to trim
        return p, times
    i, j = max(int(away0[0]) - 1, 0), min(int(away1[-1]) + 1, len(p) - 1)
    if j - i < 2:
        return p, times
    return p[i:j + 1], (None if times is None else np.asarray(times)[i:j + 1])


def lone_outlier(positions: np.ndarray, factor: float = 20.0) -> tuple[int, float] | None:
    """A sample far outside the rest of the drawing (a glitch of the logger), or None.

    The sample farthest from the median position (per axis) is an outlier
    when its distance to the bounding box of all the other samples exceeds
    ``factor`` times that box's longer side. One such sample sets the
    drawing's size on its own, so the rests (:func:`trim_rests`, measured
    against that size) swallow the real stroke and the fit to the plane
    shrinks it to a dot.

    Parameters
    ----------
    positions : ndarray, shape (N, 2)
    factor : float
        How many times the others' extent away (20: a stroke's own samples
        never lie beyond its bounding box).

    Returns
    -------
    (row, ratio) or None
        The sample's row and its distance over the others' extent.
    """
    p = as_points(positions)
    if len(p) < 4:
        return None
    r = int(np.argmax(np.abs(p - np.median(p, axis=0)).max(axis=1)))
    rest = np.delete(p, r, axis=0)
    lo, hi = rest.min(axis=0), rest.max(axis=0)
    spread = float((hi - lo).max())
    gap = float(np.max(np.maximum(lo - p[r], p[r] - hi)))
    if spread > 0 and gap > factor * spread:
        return r, gap / spread
    return None


def outlier_note(found: tuple[int, float] | None) -> str:
    """``""``, or what to say in an error about a drawing of :func:`lone_outlier`'s result."""
    if found is None:
        return ""
    row, ratio = found
    return (f"; sample {row} lies {ratio:.3g} times the rest of the drawing's size away from "
            "it, a glitch? (it alone sets the drawing's size, so its other samples read as "
            "the pen's rests): remove that sample")


def fit_to_plane(points: np.ndarray, plane: DrawingPlane) -> np.ndarray:
    """Scale (aspect ratio kept) and centre a path in the drawing rectangle.

    Parameters
    ----------
    points : ndarray, shape (T, 2)
        Path in the teacher's frame (x right, y up; any unit).
    plane : DrawingPlane

    Returns
    -------
    ndarray, shape (T, 2)
        Plane points ``(y, z)`` (m, torso frame), inside the rectangle and
        touching two of its opposite sides.

    Raises
    ------
    InvalidDemonstrationError
        Not a finite (T, 2) array with T >= 3, or zero extent.
    """
    p = as_points(points, "points")
    lo, hi = p.min(axis=0), p.max(axis=0)
    extent = hi - lo
    if not np.any(extent > 1e-12 * max(1.0, float(np.abs(p).max()))):
        raise InvalidDemonstrationError("the path has zero extent: all points are equal, so "
                                        "there is nothing to draw.")
    with np.errstate(divide="ignore"):
        scale = float(np.min(plane.size / np.where(extent > 0, extent, 0.0)))
    return plane.center + (p - (lo + hi) / 2) * scale


def preprocess(demo: Demonstration, *, steps: int = 50, resample_by: str = "arc_length",
               smoothing: float = 0.04, smoothing_window: int = 31,
               rest_tolerance: float = 0.01, y_axis: str = "up", min_points: int = 5,
               plane: DrawingPlane) -> np.ndarray:
    """Read one demonstration as the robot's drawing: plane points.

    1. ``y_axis="down"`` (screen coordinates) flips y, so up is up;
    2. the pen's rests at the start and the end are trimmed
       (:func:`trim_rests`, ``rest_tolerance``);
    3. ``resample_by="arc_length"``: :func:`resample_path` (``steps``
       points evenly along the path, smoothed along it by ``smoothing``);
       ``"time"``: Savitzky-Golay smoothing of ``smoothing_window`` samples,
       then ``steps`` points evenly in time (:func:`smooth`,
       :func:`resample`);
    4. :func:`fit_to_plane`.

    Parameters
    ----------
    demo : Demonstration
    steps, resample_by, smoothing, smoothing_window, rest_tolerance, y_axis, min_points
        As in :class:`iloci.config.SensorimotorConfig` (``resample_by`` is
        its ``resample``).
    plane : DrawingPlane

    Returns
    -------
    ndarray, shape (steps, 2)
        Plane points ``(y, z)`` (m, torso frame).

    Raises
    ------
    InvalidDemonstrationError
        Fewer than ``min_points`` samples once the rests are trimmed.
    """
    if not isinstance(demo, Demonstration):
        raise InvalidInputError(f"expected a Demonstration, got {type(demo).__name__}; wrap "
                                "raw arrays with iloci.Demonstration(positions, times).")
    if y_axis not in ("up", "down"):
        raise InvalidInputError(f"y_axis must be 'up' or 'down', got {y_axis!r}.")
    check_size(len(demo.positions), f"demonstration {demo.key!r}")
    positions = demo.positions
    if y_axis == "down":
        positions = positions * np.array([1.0, -1.0])
    positions, times = trim_rests(positions, demo.times, rest_tolerance)
    if len(positions) < min_points:
        rests = (f" once the pen's rests are trimmed (from {len(demo.positions)})"
                 if len(positions) < len(demo.positions) else "")
        glitch = outlier_note(lone_outlier(demo.positions))
        raise InvalidDemonstrationError(
            f"demonstration {demo.key!r} has {len(positions)} samples{rests}{glitch}; at "
            f"least {min_points} are needed to read a drawing (a tap or a click is not one)"
            + ("." if glitch else ": sample the pen more often or draw a longer stroke "
               "([sensorimotor] min_points)."))
    if resample_by == "arc_length":
        if len(positions) < SHOWN_ABOVE:
            path = resample_path(positions, steps, smoothing)
        else:
            with long_step(f"reading the drawing {demo.key} ({len(demo.positions):,} "
                           "samples)") as tell:
                path = resample_path(positions, steps, smoothing, progress=tell)
    elif resample_by == "time":
        path = resample(smooth(positions, smoothing_window), times, steps, "time")
    else:
        raise InvalidInputError(f"resampling must be by 'time' or 'arc_length', got "
                                f"{resample_by!r}.")
    return fit_to_plane(path, plane)
