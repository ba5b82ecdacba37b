"""Perturbations of a demonstration: the ways a person's drawing differs from LASA's.

Each perturbation keeps the *shape* a person means and changes only how it
reaches the robot: the pace, the sampling rate, pauses of the pen, hand
jitter, a slightly rotated, stretched or scaled drawing. The robustness
section of ``iloci evaluate`` recognizes every fold's test set again under
each one (:data:`SUITE`), iloci beside the DTW 1-NN baseline.

Sizes are relative to the demonstration's own size, the longer side of its
bounding box (``extent``); durations to its own duration. Random draws (the
jitter, the sign of a rotation) come from a generator seeded per
demonstration, so a suite run is reproducible.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from iloci.linalg import matmul
from iloci.errors import InvalidInputError
from iloci.interfaces import Demonstration

__all__ = ["Perturbation", "SUITE", "suite", "perturb", "time_warp", "resample_count",
           "pen_rests", "jitter", "rotate", "stretch", "scale"]


def _times(demo: Demonstration) -> np.ndarray:
    """A demonstration's times, s (a constructed Demonstration always has them)."""
    assert demo.times is not None
    return demo.times


def _extent(demo: Demonstration) -> float:
    return float(np.ptp(demo.positions, axis=0).max())


def _with(demo: Demonstration, positions: np.ndarray, times: np.ndarray) -> Demonstration:
    return replace(demo, positions=np.asarray(positions, dtype=np.float64),
                   times=np.asarray(times, dtype=np.float64))


def _at_times(demo: Demonstration, t: np.ndarray) -> np.ndarray:
    """Positions of ``demo`` at times ``t`` (linear interpolation), shape (len(t), 2)."""
    return np.column_stack([np.interp(t, _times(demo), demo.positions[:, k]) for k in range(2)])


def time_warp(demo: Demonstration, kind: str = "slow_fast") -> Demonstration:
    """The same path at another pace, sampled as often as the original.

    The pen reaches the original's position at original time ``T g(t/T)``
    at new time ``t`` (``T`` the duration); ``g`` is ``u**2`` for
    ``"slow_fast"`` (slow at first, twice the mean speed at the end) and
    ``1 - (1 - u)**2`` for ``"fast_slow"``.
    """
    t = _times(demo)
    t0, T = float(t[0]), float(t[-1] - t[0])
    u = np.linspace(0.0, 1.0, len(t))
    if kind == "slow_fast":
        g = u ** 2
    elif kind == "fast_slow":
        g = 1.0 - (1.0 - u) ** 2
    else:
        raise InvalidInputError(f"time warp must be 'slow_fast' or 'fast_slow', got {kind!r}.")
    return _with(demo, _at_times(demo, t0 + T * g), t0 + T * u)


def resample_count(demo: Demonstration, points: int) -> Demonstration:
    """The same drawing sampled ``points`` times at a uniform rate (linear interpolation)."""
    t = np.linspace(_times(demo)[0], _times(demo)[-1], int(points))
    return _with(demo, _at_times(demo, t), t)


def pen_rests(demo: Demonstration, fraction: float = 0.25, where: str = "ends") -> Demonstration:
    """The pen rests (does not move) for ``fraction`` of the duration.

    ``where="ends"``: that long at the start and again at the end;
    ``"middle"``: once, half way through the samples. The rest is sampled
    at the demonstration's mean rate.
    """
    t, p = _times(demo), demo.positions
    n = len(t)
    k = max(1, int(round(fraction * n)))
    dt = float(t[-1] - t[0]) / (n - 1)
    if where == "ends":
        pos = np.vstack([np.repeat(p[:1], k, axis=0), p, np.repeat(p[-1:], k, axis=0)])
    elif where == "middle":
        m = n // 2
        pos = np.vstack([p[:m], np.repeat(p[m - 1:m], k, axis=0), p[m:]])
    else:
        raise InvalidInputError(f"pen rests are at the 'ends' or in the 'middle', got {where!r}.")
    return _with(demo, pos, t[0] + dt * np.arange(len(pos)))


def jitter(demo: Demonstration, size: float, rng: np.random.Generator) -> Demonstration:
    """Independent Gaussian noise on every sample, standard deviation ``size * extent``."""
    noise = rng.normal(0.0, size * _extent(demo), demo.positions.shape)
    return _with(demo, demo.positions + noise, _times(demo))


def rotate(demo: Demonstration, degrees: float, rng: np.random.Generator) -> Demonstration:
    """Rotated by ``degrees`` (sign drawn at random) about the bounding box's centre."""
    a = np.deg2rad(degrees) * rng.choice([-1.0, 1.0])
    c, s = np.cos(a), np.sin(a)
    p = demo.positions
    centre = (p.min(axis=0) + p.max(axis=0)) / 2
    return _with(demo, matmul(p - centre, np.array([[c, s], [-s, c]])) + centre, _times(demo))


def stretch(demo: Demonstration, x: float = 1.0, y: float = 1.0) -> Demonstration:
    """Stretched by ``x`` horizontally and ``y`` vertically (non-uniform scale)."""
    return _with(demo, demo.positions * np.array([x, y]), _times(demo))


def scale(demo: Demonstration, factor: float) -> Demonstration:
    """Uniformly scaled by ``factor`` (e.g. another unit: mm, m, pixels)."""
    return _with(demo, demo.positions * factor, _times(demo))


@dataclass(frozen=True)
class Perturbation:
    """One entry of the suite.

    Attributes
    ----------
    name : str
        Key in ``metrics.json`` (e.g. ``"jitter_0.02"``).
    group : str
        What it tests: ``clean``, ``pace``, ``sampling``, ``rests``,
        ``jitter``, ``rotation``, ``stretch`` or ``scale``.
    label : str
        One line for the report's table.
    apply : callable
        ``(demo, rng) -> Demonstration``.
    """

    name: str
    group: str
    label: str
    apply: Callable[[Demonstration, np.random.Generator], Demonstration]


def _p(name: str, group: str, label: str, fn: Callable[..., Demonstration]) -> Perturbation:
    return Perturbation(name, group, label, fn)


#: The robustness suite, in report order.
SUITE: tuple[Perturbation, ...] = (
    _p("clean", "clean", "as recorded", lambda d, r: d),
    _p("pace_slow_fast", "pace", "slow at first, fast at the end", lambda d, r: time_warp(d)),
    _p("pace_fast_slow", "pace", "fast at first, slow at the end",
       lambda d, r: time_warp(d, "fast_slow")),
    _p("points_25", "sampling", "sampled at 25 points", lambda d, r: resample_count(d, 25)),
    _p("points_100", "sampling", "sampled at 100 points", lambda d, r: resample_count(d, 100)),
    _p("points_10000", "sampling", "sampled at 10 000 points",
       lambda d, r: resample_count(d, 10000)),
    _p("rests_ends", "rests", "pen resting 25 % of the time at start and end",
       lambda d, r: pen_rests(d, 0.25, "ends")),
    _p("rests_middle", "rests", "pen resting 25 % of the time half way",
       lambda d, r: pen_rests(d, 0.25, "middle")),
    _p("jitter_0.01", "jitter", "jitter 1 % of the size", lambda d, r: jitter(d, 0.01, r)),
    _p("jitter_0.02", "jitter", "jitter 2 % of the size", lambda d, r: jitter(d, 0.02, r)),
    _p("jitter_0.05", "jitter", "jitter 5 % of the size", lambda d, r: jitter(d, 0.05, r)),
    _p("rotation_5", "rotation", "rotated by ±5°", lambda d, r: rotate(d, 5, r)),
    _p("rotation_10", "rotation", "rotated by ±10°", lambda d, r: rotate(d, 10, r)),
    _p("rotation_15", "rotation", "rotated by ±15°", lambda d, r: rotate(d, 15, r)),
    _p("stretch_x_1.25", "stretch", "1.25 × wider", lambda d, r: stretch(d, x=1.25)),
    _p("stretch_y_1.25", "stretch", "1.25 × taller", lambda d, r: stretch(d, y=1.25)),
    _p("scale_0.01", "scale", "at 1 % of the size", lambda d, r: scale(d, 0.01)),
    _p("scale_10", "scale", "at 10 × the size", lambda d, r: scale(d, 10.0)),
)


def suite(names: Any = None) -> list[Perturbation]:
    """The perturbations named (all of :data:`SUITE` for ``None``), in suite order.

    Raises
    ------
    InvalidInputError
        An unknown name (the message lists the known ones).
    """
    if names is None:
        return list(SUITE)
    known = {p.name: p for p in SUITE}
    wanted = list(names)
    unknown = [n for n in wanted if n not in known]
    if unknown:
        raise InvalidInputError(f"unknown perturbation(s) {unknown}; known: "
                                f"{', '.join(known)}.")
    return [p for p in SUITE if p.name in set(wanted)]


def perturb(demos: list[Demonstration], perturbation: Perturbation,
            seed: int = 0) -> list[Demonstration]:
    """``perturbation`` applied to each demonstration.

    The generator of demonstration ``i`` is seeded with ``(seed, i)`` and the
    perturbation's position in :data:`SUITE`, so the same call gives the
    same demonstrations.
    """
    index = next((k for k, p in enumerate(SUITE) if p.name == perturbation.name), len(SUITE))
    return [perturbation.apply(d, np.random.default_rng([int(seed), index, i]))
            for i, d in enumerate(demos)]
