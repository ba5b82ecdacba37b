"""Smoothing, resampling, scaling and fitting a pen trajectory into the drawing plane.

The paper (section "sensorimotor") smooths each demonstration, scales it and
fits it into a y-z rectangle of the robot's workspace. Its filter and
resolution are not given; iloci's choices:

* **Smoothing**: Savitzky-Golay, cubic, ``smoothing_window`` points
  (default 31 of LASA's 1000). A local cubic fit removes tablet jitter
  without the two faults of a moving average of the same width: it does not
  flatten the extrema and corners that tell shapes apart, and it does not
  shift the curve (zero phase). Ends are fitted, not padded
  (``mode="interp"``), so the pen's start and end stay in place.
* **Resampling** to ``steps`` points (default 50, the sequence length of the
  network), by linear interpolation at uniform *time* (the teacher's pace,
  as the paper feeds it), or uniformly along the *arc length* (speed-free).
* **Scaling and fitting**: one uniform scale (aspect ratio kept) so the
  path's bounding box fills the rectangle along its tighter side, centred
  in the rectangle. The teacher's x axis maps to the plane's y and the
  teacher's y to z, so a teacher facing the robot sees the shape drawn as
  they drew it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from iloci.errors import InvalidDemonstrationError, InvalidInputError
from iloci.interfaces import Demonstration
from iloci.sensorimotor.robots import DrawingPlane
from iloci.validation import check_array

__all__ = ["POLYORDER", "fit_to_plane", "preprocess", "resample", "smooth"]

#: Order of the Savitzky-Golay polynomial.
POLYORDER = 3


def _points(a: Any, what: str = "positions") -> np.ndarray:
    p = check_array(a, what, ("N", 2), finite=False, error=InvalidDemonstrationError)
    if len(p) < 3:
        raise InvalidDemonstrationError(f"{what} has {len(p)} point(s); at least 3 are "
                                        "needed to define a motion.")
    return check_array(p, what, ("N", 2), error=InvalidDemonstrationError,
                       finite_hint=" Remove or interpolate missing samples.")


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
    p = _points(positions)
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
    p = _points(positions)
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
    p = _points(points, "points")
    lo, hi = p.min(axis=0), p.max(axis=0)
    extent = hi - lo
    if not np.any(extent > 1e-12 * max(1.0, float(np.abs(p).max()))):
        raise InvalidDemonstrationError("the path has zero extent: all points are equal, so "
                                        "there is nothing to draw.")
    with np.errstate(divide="ignore"):
        scale = float(np.min(plane.size / np.where(extent > 0, extent, 0.0)))
    return plane.center + (p - (lo + hi) / 2) * scale


def preprocess(demo: Demonstration, *, steps: int = 50, resample_by: str = "time",
               smoothing_window: int = 31, plane: DrawingPlane) -> np.ndarray:
    """Smooth, resample and fit one demonstration into the drawing plane.

    Parameters
    ----------
    demo : Demonstration
    steps, resample_by, smoothing_window
        As in :class:`iloci.config.SensorimotorConfig` (``steps``,
        ``resample``, ``smoothing_window``).
    plane : DrawingPlane

    Returns
    -------
    ndarray, shape (steps, 2)
        Plane points ``(y, z)`` (m, torso frame).
    """
    if not isinstance(demo, Demonstration):
        raise InvalidInputError(f"expected a Demonstration, got {type(demo).__name__}; wrap "
                                "raw arrays with iloci.Demonstration(positions, times).")
    smoothed = smooth(demo.positions, smoothing_window)
    path = resample(smoothed, demo.times, steps, resample_by)
    return fit_to_plane(path, plane)
