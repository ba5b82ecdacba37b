"""Placing the drawing plane automatically: the largest square every point of which is drawable.

:func:`find_drawing_plane` works with any :class:`~iloci.interfaces.IKSolver`
(it needs ``solve``, ``forward``, ``lower`` and ``upper``) and numpy only.
For a plane orientation (default: vertical, facing the robot's forward
axis) it looks for the largest rectangle of the given aspect ratio such
that every point of a test grid over the rectangle *grown by*
``edge`` on every side is

* reached by the IK, warm-started point to point from the rest posture
  (the way a demonstration is solved),
* with every joint at least ``joint_margin`` (rad) inside its limits, and
* away from singular configurations: the smallest singular value of the
  3 x J position Jacobian (finite differences of ``forward``) at least
  ``min_singular`` times its value at the best-conditioned sampled posture.

Search: postures sampled uniformly inside the limits (seeded) give the
reachable workspace; depths along the plane normal and centres in the plane
are taken from it on a grid; each candidate's size is doubled until a test
fails, then the best few candidates are refined by bisection on the size
and a local search on the centre. The result is checked on a finer grid and
its margins reported.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import time
from typing import Any

import numpy as np

from iloci.errors import IlociError, InvalidInputError, UnreachableTargetError
from iloci.sensorimotor.robots.model import DrawingPlane, _vec3
from iloci.sensorimotor.robots.urdf import read_urdf

__all__ = ["NoReachablePlaneError", "PlaneCheck", "check_plane", "find_drawing_plane"]


class NoReachablePlaneError(IlociError, ValueError):
    """No rectangle of the requested orientation is drawable with the required margins."""


@dataclass(frozen=True)
class PlaneCheck:
    """How well an arm reaches a grid over a rectangle.

    Attributes
    ----------
    ok : bool
        Every point reached, with the joint margin and away from singularities.
    reached : bool
        Every point reached within the IK's tolerance.
    joint_margin : ndarray, shape (J,)
        Smallest distance of each joint from its nearest limit over the grid
        (rad); NaN when not every point was reached.
    singular : float
        Smallest singular value of the position Jacobian over the grid (m/rad).
    q_center : ndarray, shape (J,) or None
        The posture reaching the centre.
    """

    ok: bool
    reached: bool
    joint_margin: np.ndarray
    singular: float
    q_center: np.ndarray | None


def _jacobian_sv(ik: Any, q: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Singular values (3,) of the pen tip's position Jacobian at each posture of ``q`` (T, J)."""
    T, J = q.shape
    stacked = np.concatenate([q + h * e for e in np.eye(J)] + [q - h * e for e in np.eye(J)])
    x = np.asarray(ik.forward(stacked), dtype=np.float64).reshape(2, J, T, 3)
    jac = (x[0] - x[1]) / (2 * h)  # (J, T, 3)
    return np.linalg.svd(np.transpose(jac, (1, 2, 0)), compute_uv=False)  # (T, 3)


def _grid(n: int) -> np.ndarray:
    """Serpentine grid of n x n points over [-1/2, 1/2]^2, shape (n*n, 2), rows alternating."""
    s = np.linspace(-0.5, 0.5, n)
    rows = [np.column_stack([s if i % 2 == 0 else s[::-1], np.full(n, t)])
            for i, t in enumerate(s)]
    return np.concatenate(rows)


def check_plane(ik: Any, plane: Any, q_start: np.ndarray, *, edge: float = 0.0,
                grid: int = 7, joint_margin: float = 0.0, min_singular: float = 0.0
                ) -> PlaneCheck:
    """Check a rectangle (grown by ``edge`` m) on a ``grid`` x ``grid`` test grid.

    The centre is solved from ``q_start``; the grid is then walked in
    serpentine order from its first corner, warm-started point to point.
    """
    lo, hi = np.asarray(ik.lower, float), np.asarray(ik.upper, float)
    big = plane.grown(edge)
    pts2 = big.center + _grid(grid) * big.size
    try:
        qc = np.asarray(ik.solve(plane.to_3d(big.center[None]), q_start))[0]
        # reach the grid's first corner from the centre along a straight line
        lead = big.center + np.linspace(0, 1, 6)[1:, None] * (pts2[0] - big.center)
        q_lead = np.asarray(ik.solve(plane.to_3d(lead), qc))
        q = np.asarray(ik.solve(plane.to_3d(pts2), q_lead[-1]))
    except UnreachableTargetError:
        return PlaneCheck(False, False, np.full(len(lo), np.nan), 0.0, None)
    margin = np.minimum(q - lo, hi - q).min(axis=0)
    sv = float(_jacobian_sv(ik, q)[:, -1].min())
    ok = bool(np.all(margin >= joint_margin) and sv >= min_singular)
    return PlaneCheck(ok, True, margin, sv, qc)


def _fmt(v: Any) -> str:
    """A direction for a message: ``(1, 0, 0)``."""
    return "(" + ", ".join(f"{float(x):.3g}" for x in v) + ")"


def _arm_note(robot: Any) -> str:
    """What the plane search worked with, for its errors: the arm's joints, and the movable
    joints above its base frame, which iloci never moves (a base frame chosen too low)."""
    joints = list(robot.joint_names)
    note = (f" (The arm from {robot.base_frame!r} to {robot.end_effector_frame!r} moves "
            f"{len(joints)} joint(s): {', '.join(joints)}.")
    try:
        tree = read_urdf(robot.urdf_path)
        above = tree.movable_between(tree.root, robot.base_frame)
    except (IlociError, OSError):  # the robot was built from this file: not expected
        return note + ")"
    if above:
        note += (f" Its base frame {robot.base_frame!r} hangs below the movable joint(s) "
                 f"{', '.join(above)}, which iloci holds still: if they belong to the arm, "
                 f"set base_frame to a link above them (the URDF's root is {tree.root!r}).")
    return note + ")"


def find_drawing_plane(robot: Any, ik: Any, *, normal: tuple[float, float, float] = (1, 0, 0),
                       up: tuple[float, float, float] = (0, 0, 1), aspect: float = 1.0,
                       joint_margin: float = math.radians(10.0), min_singular: float = 0.1,
                       edge_fraction: float = 0.1, max_height: float = 0.3,
                       min_up: float = 0.0, samples: int = 2000, seed: int = 0,
                       ) -> tuple[Any, np.ndarray, dict[str, Any]]:
    """The largest drawable rectangle of the given orientation, by sampling and IK.

    Parameters
    ----------
    robot : Robot
        Joint limits and rest posture (``rest``, else ``q_home``).
    ik : IKSolver
        Solves for ``robot`` (its ``forward`` gives the pen tip, base frame).
    normal, up : 3-vectors
        Plane orientation (base frame): ``normal`` points away from the robot,
        ``up`` is the height direction (default: vertical, facing +x).
    aspect : float
        width / height of the rectangle.
    joint_margin : float
        Required distance of every joint from its limits (rad; default 10 deg).
    min_singular : float
        Required smallest singular value of the position Jacobian, relative
        to its largest value over the sampled postures (default 0.1).
    edge_fraction : float
        Test grids cover the rectangle grown by this fraction of its height
        on every side, so demonstrations slightly overshooting stay reachable.
    max_height : float
        Largest height sought (m; default 0.3, a drawing board): larger
        drawings only make the arm move faster for nothing.
    min_up : float
        The grown rectangle's lowest edge stays at least this high along
        ``up`` above the base origin (m; default 0: not below the base,
        e.g. not under the table an arm stands on). The plane is also at
        least a quarter of the arm's reach in front of the base.
    samples : int
        Postures sampled to find the reachable workspace.
    seed : int

    Returns
    -------
    plane : DrawingPlane
    q_home : ndarray, shape (J,)
        Posture reaching the plane's centre from the rest posture.
    report : dict
        ``method`` ("auto"), the settings, the margins measured on a 15 x 15
        grid of the grown rectangle (``joint_margin_deg`` per joint,
        ``min_joint_margin_deg``, ``min_singular`` in m/rad and relative),
        ``candidates`` tested and ``seconds``.

    Raises
    ------
    NoReachablePlaneError
        No rectangle of at least 1 cm passes (says what to relax).
    """
    t0 = time.perf_counter()
    if not (aspect > 0 and 0 <= edge_fraction < 1 and joint_margin >= 0 and min_singular >= 0):
        raise InvalidInputError("plane search needs aspect > 0, 0 <= edge_fraction < 1 and "
                                "non-negative margins.")
    probe = DrawingPlane(0.0, 0.0, 0.0, 1.0, 1.0, normal=_vec3(normal), up=_vec3(up))
    u, v, n = probe.axes
    lo, hi = np.asarray(ik.lower, float), np.asarray(ik.upper, float)
    rest = np.asarray(robot.rest if robot.rest is not None else robot.q_home, float)
    rng = np.random.default_rng(seed)
    inner_lo = np.minimum(lo + joint_margin, (lo + hi) / 2)
    inner_hi = np.maximum(hi - joint_margin, (lo + hi) / 2)
    qs = inner_lo + rng.random((samples, len(lo))) * (inner_hi - inner_lo)
    x = np.asarray(ik.forward(qs), float)
    sv = _jacobian_sv(ik, qs[: min(samples, 500)])
    sv_ref = float(np.max(sv[:, -1]))
    abs_singular = min_singular * sv_ref
    # only sampled postures away from singularities describe the usable workspace
    good = np.concatenate([sv[:, -1] >= abs_singular, np.ones(samples - len(sv), bool)])
    depth = x @ n
    front = good & (depth > 0)
    if front.sum() < 20:
        raise NoReachablePlaneError(
            f"{robot.name!r} reaches almost nothing in front of it along normal "
            f"{_fmt(normal)} (base frame {robot.base_frame!r}); choose another plane_normal."
            + _arm_note(robot))
    reach = float(np.percentile(np.linalg.norm(x[front], axis=1), 95))
    h_cap = min(max_height, reach)

    def plane_at(d: float, a: float, b: float, h: float) -> DrawingPlane:
        c = d * n + a * u + b * v
        return DrawingPlane(float(c[0]), float(c[1]), float(c[2]), aspect * h, h,
                            normal=_vec3(n), up=_vec3(v))

    tested = 0

    def passes(d: float, a: float, b: float, h: float) -> bool:
        nonlocal tested
        if b - h / 2 - edge_fraction * h < min_up or d < 0.25 * reach:
            return False
        tested += 1
        return check_plane(ik, plane_at(d, a, b, h), rest, edge=edge_fraction * h, grid=5,
                           joint_margin=joint_margin, min_singular=abs_singular).ok

    def largest(d: float, a: float, b: float, h_min: float, h_max: float, steps: int) -> float:
        """Largest passing height in [h_min, h_max] by bisection (0 if h_min fails)."""
        if not passes(d, a, b, h_min):
            return 0.0
        good_h, bad_h = h_min, h_max
        if passes(d, a, b, h_max):
            return h_max
        for _ in range(steps):
            mid = math.sqrt(good_h * bad_h)
            if passes(d, a, b, mid):
                good_h = mid
            else:
                bad_h = mid
        return good_h

    # coarse: grid of depths and centres, middle first; heights doubling from
    # 2 % of the reach up to the cap (the first centre reaching it wins)
    depths = np.maximum(np.percentile(depth[front], [55, 40, 70]), 0.3 * reach)
    h0 = min(0.02 * reach, h_cap)
    grid = [(i, j) for i in (50, 35, 65, 20, 80) for j in (50, 35, 65, 20, 80)]
    grid.sort(key=lambda ij: abs(ij[0] - 50) + abs(ij[1] - 50))
    candidates = []
    for d in depths:
        slab = front & (np.abs(depth - d) < 0.1 * reach)
        if slab.sum() < 10:
            continue
        a_s, b_s = x[slab] @ u, x[slab] @ v
        for i, j in grid:
            a, b = float(np.percentile(a_s, i)), float(np.percentile(b_s, j))
            h = 0.0
            trial = h0
            while passes(d, a, b, trial):
                h = trial
                if trial >= h_cap:
                    break
                trial = min(2 * trial, h_cap)
            if h > 0:
                candidates.append((h, float(d), a, b))
            if h >= h_cap:
                break
        if candidates and max(c[0] for c in candidates) >= h_cap:
            break
    if not candidates:
        raise NoReachablePlaneError(
            f"no drawing plane found for {robot.name!r}: no square of "
            f"{h0 * 100:.1f} cm, facing {_fmt(n)} with up {_fmt(v)}, is reachable with every joint "
            f"{math.degrees(joint_margin):.1f} deg inside its limits and the Jacobian's "
            f"smallest singular value >= {min_singular} of its best, its lowest edge "
            f">= {min_up} m above the base origin. Give the plane "
            "([robot] plane = [x, y, z, width, height]), another plane_normal / plane_up, or "
            "lower plane_joint_margin / plane_min_singular / plane_min_up." + _arm_note(robot))
    # the largest first (stable: among equals, the one found first)
    candidates.sort(key=lambda c: -c[0])
    best = (0.0, 0.0, 0.0, 0.0)
    for h, d, a, b in candidates[:2]:
        if h >= h_cap:
            best = max(best, (h, d, a, b), key=lambda c: c[0])
            break
        # refine the size, then try moving the centre by a quarter of it
        h = largest(d, a, b, h, min(2 * h, h_cap), 3)
        improved = h < h_cap
        moves = 0
        while improved and moves < 4:
            moves += 1
            improved = False
            for da, db, dd in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0),
                               (0, 0, 1), (0, 0, -1)):
                step = h / 4
                a2, b2, d2 = a + da * step, b + db * step, d + dd * step
                h2 = (largest(d2, a2, b2, h, min(1.5 * h, h_cap), 2)
                      if passes(d2, a2, b2, min(h * 1.02, h_cap)) else 0)
                if h2 > h * 1.02:
                    h, a, b, d = h2, a2, b2, d2
                    improved = True
                    break
        if h > best[0]:
            best = (h, d, a, b)
    h, d, a, b = best
    # the final check on a finer grid; shrink slightly if it fails there
    for _ in range(10):
        plane = plane_at(d, a, b, h)
        final = check_plane(ik, plane, rest, edge=edge_fraction * h, grid=15,
                            joint_margin=joint_margin, min_singular=abs_singular)
        if final.ok:
            break
        h *= 0.95
    else:
        raise NoReachablePlaneError(f"no drawing plane for {robot.name!r} passed the final "
                                    "15 x 15 check; relax the margins or give the plane."
                                    + _arm_note(robot))
    if h < 0.01:
        raise NoReachablePlaneError(
            f"the largest drawable square for {robot.name!r} is {h * 1000:.1f} mm: too small "
            "to draw in. Give the plane, another orientation, or lower the margins."
            + _arm_note(robot))
    assert final.q_center is not None
    report = {
        "method": "auto",
        "normal": [float(c) for c in n], "up": [float(c) for c in v], "aspect": aspect,
        "required_joint_margin_deg": math.degrees(joint_margin),
        "max_height": max_height, "min_up": min_up,
        "required_min_singular_relative": min_singular,
        "edge_m": edge_fraction * h,
        "joint_margin_deg": dict(zip(robot.joint_names,
                                     np.degrees(final.joint_margin).round(2).tolist())),
        "min_joint_margin_deg": float(np.degrees(final.joint_margin.min())),
        "min_singular": final.singular,
        "min_singular_relative": final.singular / sv_ref,
        "candidates": tested, "samples": samples, "seed": seed,
        "seconds": time.perf_counter() - t0,
    }
    return plane, final.q_center, report
