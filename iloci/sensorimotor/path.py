"""The path reading of a drawing: ``steps`` points evenly along the drawn path, smoothed.

The default reading of :func:`iloci.sensorimotor.preprocess.preprocess`
(``resample="arc_length"``; see that module for the whole pipeline): the
path's normalised length is its parameter (:func:`path_parameter`,
measured on a lightly smoothed copy, its Gaussian by FFT above
:data:`FFT_ABOVE` samples), a coarse path is first interpolated by a cubic
spline (:func:`densify`), and a Gaussian local linear regression along the
path smooths it (:func:`local_linear`, samples pooled above
:data:`POOL_ABOVE`) (:func:`resample_path`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from iloci.errors import InvalidDemonstrationError, InvalidInputError
from iloci.validation import check_array

__all__ = ["PRESMOOTH", "FFT_ABOVE", "POOL_ABOVE", "POOL_PER_WIDTH", "DENSE", "REFINE",
           "as_points", "path_parameter", "local_linear", "resample_path", "densify"]

#: Gaussian smoothing (fraction of the samples) of the path whose length
#: first parametrises it (:func:`path_parameter`).
PRESMOOTH = 0.01


def as_points(a: Any, what: str = "positions") -> np.ndarray:
    """``a`` as (N, 2) finite positions, N >= 3; InvalidDemonstrationError otherwise."""
    p = check_array(a, what, ("N", 2), finite=False, error=InvalidDemonstrationError)
    if len(p) < 3:
        raise InvalidDemonstrationError(f"{what} has {len(p)} point(s); at least 3 are "
                                        "needed to define a motion.")
    return check_array(p, what, ("N", 2), error=InvalidDemonstrationError,
                       finite_hint=" Remove or interpolate missing samples.")


def path_parameter(positions: np.ndarray, presmooth: float = PRESMOOTH) -> np.ndarray:
    """Normalised arc length ``s`` in [0, 1] of each sample, robust to jitter.

    The length is measured along the path after a Gaussian smoothing of
    ``presmooth * N`` samples (standard deviation): measured on the raw
    samples, hand jitter would add its own length, which grows with the
    sampling rate and swamps the drawing's (at 5 % jitter and 1000 points
    the raw length is about 20 times the drawn one).

    Parameters
    ----------
    positions : ndarray, shape (N, 2)
    presmooth : float
        Fraction of the samples; 0 measures the raw samples.

    Returns
    -------
    ndarray, shape (N,)
        Non-decreasing, from 0 to 1 (equal values where the pen rests).

    Raises
    ------
    InvalidDemonstrationError
        The path has zero length.
    """
    p = as_points(positions)
    sigma = presmooth * len(p)
    if sigma >= 0.5:
        p = _gaussian(p, sigma)
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if not s[-1] > 0:
        raise InvalidDemonstrationError("the path has zero length: all points are equal.")
    return s / s[-1]


#: Above this many samples, :func:`path_parameter`'s Gaussian (whose width grows
#: with the samples) is applied by FFT, O(N log N) instead of O(N^2); below, by
#: direct convolution. Both give the same result to 1e-12 of the path's extent.
FFT_ABOVE = 20_000


def _gaussian(p: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian smoothing along axis 0 (edges extended; scipy's ``mode="nearest"``,
    truncated at 4 sigma), shape of ``p``."""
    if len(p) <= FFT_ABOVE:
        from scipy.ndimage import gaussian_filter1d
        return gaussian_filter1d(p, sigma, axis=0, mode="nearest")
    r = int(4.0 * sigma + 0.5)  # scipy.ndimage's radius for truncate=4
    x = np.arange(-r, r + 1, dtype=np.float64)
    kernel = np.exp(-0.5 * (x / sigma) ** 2)
    kernel /= kernel.sum()
    # one row per coordinate (contiguous: an FFT along strided memory is slow)
    rows = np.ascontiguousarray(p.T)
    padded = np.concatenate([np.repeat(rows[:, :1], r, axis=1), rows,
                             np.repeat(rows[:, -1:], r, axis=1)], axis=1)
    size = padded.shape[1] + len(kernel) - 1
    nfft = 1 << (size - 1).bit_length()
    full = np.fft.irfft(np.fft.rfft(padded, nfft) * np.fft.rfft(kernel, nfft), nfft)
    return full[:, 2 * r:2 * r + len(p)].T  # the "valid" part: each sees 2r + 1 samples


#: Above this many samples, :func:`local_linear` pools the samples falling in each
#: stretch of ``width / POOL_PER_WIDTH`` of the parameter into one (their weighted
#: mean parameter and position, their summed weight) before it fits: time linear in
#: N with a small constant. Pooling leaves out the spread within a stretch, a
#: relative change of about ``1 / (12 * POOL_PER_WIDTH**2)`` to the fit's sums; the
#: drawing moves by under 1e-4 of its size (``benchmarks/results/preprocess.json``).
POOL_ABOVE = 50_000
#: Pooled stretches per bandwidth (see :data:`POOL_ABOVE`).
POOL_PER_WIDTH = 64


def _pool(s: np.ndarray, p: np.ndarray, share: np.ndarray, delta: float
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Samples (sorted ``s``) pooled per stretch ``delta``: weighted means, summed weights."""
    if not delta > 0:
        return s, p, share
    b = np.floor((s - s[0]) / delta).astype(np.int64)
    if b[-1] + 1 >= len(s) // 4:  # too few samples per stretch to gain anything
        return s, p, share
    # s is sorted, so each stretch's samples are one run: sums by np.add.reduceat, O(N)
    starts = np.flatnonzero(np.concatenate([[True], b[1:] != b[:-1]]))
    w = np.add.reduceat(share, starts)
    keep = w > 0
    safe = np.where(keep, w, 1.0)
    ps = np.add.reduceat(share * s, starts) / safe
    px = np.add.reduceat(share * p[:, 0], starts) / safe
    py = np.add.reduceat(share * p[:, 1], starts) / safe
    return ps[keep], np.column_stack([px, py])[keep], w[keep]


#: Grid points of :func:`local_linear` evaluated together: bounds its memory to about
#: ``_CELLS`` window entries (8 bytes each, a few arrays) however many samples a path has.
_CELLS = 2_000_000


def local_linear(s: np.ndarray, positions: np.ndarray, u: np.ndarray,
                 width: float, progress: Any = None) -> np.ndarray:
    """Gaussian-weighted local linear regression of ``positions`` on ``s``, at ``u``.

    At each ``u_k`` a line is fitted to the samples by weighted least
    squares, with weights ``exp(-((s - u_k) / h_k)**2 / 2)``, and its value
    at ``u_k`` is returned (a local linear kernel smoother; Fan & Gijbels,
    *Local Polynomial Modelling*, 1996, ch. 3). ``h_k`` is ``width``, widened
    where the samples are sparse to the distance from ``u_k`` to its second
    nearest sample, so a coarsely sampled path is interpolated (a straight
    line through its two nearest samples) rather than averaged away. Unlike
    a moving average the fit does not shift a curve's ends inward. Each
    sample's weight is also multiplied by the stretch of ``s`` it stands
    for (half the gaps to its neighbours), so samples crowded where the pen
    was slow or resting count once together (a Priestley-Chao weighting);
    samples further than 6 bandwidths are left out (their weight is below
    1.6e-8 of the peak).

    Parameters
    ----------
    s : ndarray, shape (N,)
        Parameter of each sample (e.g. :func:`path_parameter`).
    positions : ndarray, shape (N, 2)
    u : ndarray, shape (K,)
        Where to evaluate.
    width : float
        Bandwidth, in the units of ``s``; 0 interpolates linearly.
    progress : callable, optional
        ``progress(fraction)`` as the evaluation points are done.

    Returns
    -------
    ndarray, shape (K, 2)

    Notes
    -----
    Time and memory are linear in ``N``: each point sees the samples within
    6 bandwidths, points are evaluated in blocks of about ``_CELLS``
    (sample, point) pairs, and above :data:`POOL_ABOVE` samples the samples
    are pooled first.
    """
    s = np.asarray(s, dtype=np.float64)
    p = np.asarray(positions, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    if width <= 0:
        return np.column_stack([np.interp(u, s, p[:, k]) for k in range(2)])
    if np.any(np.diff(s) < 0):
        order = np.argsort(s, kind="stable")
        s, p = s[order], p[order]
    # each sample stands for the stretch of path around it (half the gaps to
    # its neighbours): samples crowded where the pen is slow or resting
    # share one stretch instead of outvoting the rest of the path
    gaps = np.diff(s)
    share = np.concatenate([[0.0], gaps]) + np.concatenate([gaps, [0.0]])
    if not np.any(share > 0):
        share = np.ones_like(s)
    if len(s) > POOL_ABOVE:
        s, p, share = _pool(s, p, share, width / POOL_PER_WIDTH)
    n = len(s)
    # bandwidth per point: widened to the second nearest sample where sparse
    at = np.searchsorted(s, u)
    cand = np.clip(at[:, None] + np.arange(-2, 2)[None, :], 0, n - 1)
    near = np.sort(np.abs(s[cand] - u[:, None]), axis=1)
    h = np.maximum(width, near[:, min(1, n - 1)])
    # samples beyond 6 bandwidths weigh under 1.6e-8 of the peak: left out
    lo = np.maximum(np.searchsorted(s, u - 6 * h, side="left") - 1, 0)
    hi = np.minimum(np.searchsorted(s, u + 6 * h, side="right") + 1, n)
    span = int((hi - lo).max()) if len(u) else 0
    block = max(1, _CELLS // max(1, span))
    out = np.empty((len(u), 2))
    for k in range(0, len(u), block):
        sl = slice(k, k + block)
        out[sl] = _local_linear_block(s, p, u[sl], h[sl], lo[sl], hi[sl], share, at[sl])
        if progress is not None:
            progress(min(1.0, (k + block) / len(u)))
    return out


def _local_linear_block(s: np.ndarray, p: np.ndarray, u: np.ndarray, h: np.ndarray,
                        lo: np.ndarray, hi: np.ndarray, share: np.ndarray,
                        at: np.ndarray) -> np.ndarray:
    """:func:`local_linear` at points ``u`` whose windows are ``lo:hi``."""
    n = len(s)
    idx = lo[:, None] + np.arange(int((hi - lo).max()))[None, :]       # (K, M)
    inside = idx < hi[:, None]
    idx = np.minimum(idx, n - 1)
    d = s[idx] - u[:, None]
    w = np.where(inside, np.exp(-0.5 * (d / h[:, None]) ** 2) * share[idx], 0.0)
    wd = w * d
    pw = p[idx]
    s0, s1, s2 = w.sum(1), wd.sum(1), (wd * d).sum(1)
    t0 = np.einsum("km,kmc->kc", w, pw)
    t1 = np.einsum("km,kmc->kc", wd, pw)
    den = s0 * s2 - s1 * s1
    ok = (s0 > 0) & (den > 1e-12 * np.maximum(s0 * s2, 1e-300))
    safe_den = np.where(ok, den, 1.0)[:, None]
    safe_s0 = np.where(s0 > 0, s0, 1.0)[:, None]
    nearest = p[np.clip(at, 0, n - 1)]
    return np.where(ok[:, None], (s2[:, None] * t0 - s1[:, None] * t1) / safe_den,
                    np.where((s0 > 0)[:, None], t0 / safe_s0, nearest))


def resample_path(positions: np.ndarray, steps: int = 50, smoothing: float = 0.04,
                  presmooth: float = PRESMOOTH, progress: Any = None) -> np.ndarray:
    """``steps`` points evenly spaced along the drawn path, smoothed along it.

    The path's parameter is its normalised length (:func:`path_parameter`),
    so neither the teacher's pace nor the sampling rate nor a pause of the
    pen changes the result; the smoothing (:func:`local_linear`, bandwidth
    ``smoothing`` of the path's length) is in units of the path too, so it
    removes the same jitter from a drawing sampled 25 or 10 000 times.

    Parameters
    ----------
    positions : ndarray, shape (N, 2)
    steps : int
        ``>= 3``.
    smoothing : float
        Bandwidth as a fraction of the path's length.
    presmooth : float
        See :func:`path_parameter`.
    progress : callable, optional
        ``progress(fraction)`` as the work advances (time is linear in N:
        about 3 s for 10^6 samples, ``benchmarks/results/preprocess.json``).

    Returns
    -------
    ndarray, shape (steps, 2)
    """
    tell = progress or (lambda fraction: None)
    p = as_points(positions)
    if int(steps) != steps or steps < 3:
        raise InvalidInputError(f"steps must be an integer >= 3, got {steps}.")
    if len(p) < DENSE:
        p = densify(p)
    s = path_parameter(p, presmooth)
    tell(0.1)
    for r in range(REFINE):
        # re-measure the length along the smoothed path: the presmoothing is
        # in samples, hence paced by the teacher; this one is in path units
        grid = np.linspace(0.0, 1.0, DENSE)
        curve = local_linear(s, p, grid, smoothing, progress=lambda f, r=r: tell(
            0.1 + 0.7 * (r + f) / REFINE))
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(curve, axis=0), axis=1))])
        if not arc[-1] > 0:
            break
        s = np.interp(s, grid, arc / arc[-1])
    return local_linear(s, p, np.linspace(0.0, 1.0, int(steps)), smoothing,
                        progress=lambda f: tell(0.8 + 0.2 * f))


#: Paths with fewer samples are interpolated by a cubic spline to this many
#: first (:func:`densify`); also the grid the path's length is re-measured on.
DENSE = 200
#: Times the path's length is re-measured along the smoothed path.
REFINE = 1


def densify(positions: np.ndarray, points: int = DENSE) -> np.ndarray:
    """A coarsely sampled path interpolated by a cubic spline, shape (points, 2).

    The spline passes through every sample, parametrised by the chord
    length between samples (repeated samples are dropped first); a straight
    line between samples would cut every curve short (at 25 samples of a
    LASA shape, its corners lose about a tenth of their depth).
    """
    from scipy.interpolate import make_interp_spline
    p = as_points(positions)
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    keep = np.concatenate([[True], seg > 0])
    p = p[keep]
    if len(p) < 4:
        return p
    c = np.concatenate([[0.0], np.cumsum(seg[seg > 0])])
    spline = make_interp_spline(c, p, k=3, axis=0)
    return spline(np.linspace(0.0, c[-1], points))
