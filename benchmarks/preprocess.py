"""Time to read one huge stroke, from its CSV file to the robot's 50 plane points.

A seeded synthetic stroke (a spiral-like curve with 0.2 % hand jitter) of N
samples, N = 10^3, 10^4, 10^5, 10^6, is written as a ``t,x,y`` CSV file; the
median of ``--repeats`` runs times

* ``load``: :func:`iloci.data.load_trajectory` (the file to a Demonstration),
* ``preprocess``: :func:`iloci.sensorimotor.preprocess.preprocess` with the
  default settings (rests, path resampling, smoothing, fitting to the Nao's plane).

The target (issue 29): time linear in N, the slope of log(time) over log(N)
(least squares over the four sizes) at most 1.2. Also measured: how far the
pooled fit used above ``POOL_ABOVE`` samples (:mod:`iloci.sensorimotor.path`)
moves the drawing from the exact fit (at 10^5 samples, where the exact one
still runs), relative to the plane's size, and the exact fit's time there.

Usage (writes benchmarks/results/preprocess.json)::

    nice -n 10 python benchmarks/preprocess.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
import statistics
import sys
import tempfile
import time

import numpy as np

from iloci.data import load_trajectory
import iloci.sensorimotor.path as path_reading
import iloci.sensorimotor.preprocess as pp
from iloci.sensorimotor.robots import NAO_PLANE

OUT = Path(__file__).resolve().parent / "results" / "preprocess.json"
SIZES = (1_000, 10_000, 100_000, 1_000_000)


def stroke(n: int, seed: int = 0) -> np.ndarray:
    """(n, 3) rows t, x, y: a curve drawn in 10 s, with Gaussian jitter."""
    t = np.linspace(0.0, 1.0, n)
    rng = np.random.default_rng(seed)
    xy = np.column_stack([np.cos(6 * t) * (1 + t), np.sin(4 * t)])
    return np.column_stack([10 * t, xy + rng.normal(0.0, 0.002, (n, 2))])


def timed(fn, repeats: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def slope(ns: list[int], ts: list[float]) -> float:
    return float(np.polyfit(np.log10(ns), np.log10(ts), 1)[0])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        load_trajectory(_write(Path(tmp), 100))  # imports and first calls out of the timing
        for n in SIZES:
            f = _write(Path(tmp), n)
            t_load, demo = timed(lambda f=f: load_trajectory(f), args.repeats)
            t_pre, pts = timed(lambda d=demo: pp.preprocess(d, plane=NAO_PLANE), args.repeats)
            rows.append({"points": n, "load_s": round(t_load, 4),
                         "preprocess_s": round(t_pre, 4),
                         "total_s": round(t_load + t_pre, 4)})
            print(rows[-1], flush=True)
        demo = load_trajectory(_write(Path(tmp), 100_000))
    pooled = pp.preprocess(demo, plane=NAO_PLANE)
    limit = path_reading.POOL_ABOVE
    path_reading.POOL_ABOVE = 10**12
    try:
        t_exact, exact = timed(lambda: pp.preprocess(demo, plane=NAO_PLANE), 1)
    finally:
        path_reading.POOL_ABOVE = limit
    ns = [r["points"] for r in rows]
    res = {
        "sizes": rows,
        "slope_log_time": {k: round(slope(ns, [r[f"{k}_s"] for r in rows]), 3)
                           for k in ("load", "preprocess", "total")},
        "target_slope_max": 1.2,
        "pooled_vs_exact_at_1e5": {
            "max_abs_m": float(np.abs(pooled - exact).max()),
            "relative_to_plane": float(np.abs(pooled - exact).max() / NAO_PLANE.size.min()),
            "exact_preprocess_s": round(t_exact, 3)},
        "max_points": pp.MAX_POINTS,
        "repeats": args.repeats,
        "python": sys.version.split()[0],
    }
    OUT.write_text(json.dumps(res, indent=1) + "\n")
    print(json.dumps(res, indent=1))


def _write(folder: Path, n: int) -> Path:
    f = folder / f"stroke_{n}.csv"
    if not f.exists():
        np.savetxt(f, stroke(n), delimiter=",", header="t,x,y", comments="", fmt="%.9g")
    return f


if __name__ == "__main__":
    main()
