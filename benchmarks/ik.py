"""IK benchmark: every LASA demonstration through the Pinocchio IK and back through FK.

Writes ``benchmarks/results/ik.json``::

    demos, points            182 demonstrations x 50 points (default config)
    max_error_m, median_error_m   |FK(IK(target)) - target| over all points
    limit_violations         joint values outside the URDF limits (must be 0)
    seconds                  wall time of IK + FK over all demos (best of 3 runs)
    seconds_runs             every run's time
    preprocess_seconds       smoothing + resampling + fitting (not in ``seconds``)
    joint_margin_deg         smallest distance of each joint to its limits on LASA
    plane                    drawing-plane check: a grid over the rectangle grown
                             by ``grow_m`` on every side, each point solved from
                             q_home; unreachable points and joint margins

Targets (issue 3): max_error_m < 0.001, limit_violations == 0, seconds <= 1.

Run: ``python benchmarks/ik.py``  (needs the iloci-pinocchio plugin).
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from iloci.config import SensorimotorConfig
from iloci.data import load_lasa
from iloci.errors import UnreachableTargetError
from iloci.sensorimotor.pipeline import preprocessed
from iloci.sensorimotor.robots import get_robot

RESULTS = Path(__file__).resolve().parent / "results" / "ik.json"


def plane_check(ik, robot, grow: float = 0.01, n: int = 41) -> dict:
    """Solve a grid over the drawing rectangle grown by ``grow`` (m) from q_home."""
    plane = robot.plane
    ys = plane.y + np.linspace(-0.5, 0.5, n) * (plane.width + 2 * grow)
    zs = plane.z + np.linspace(-0.5, 0.5, n) * (plane.height + 2 * grow)
    unreachable = 0
    margin = np.full(len(robot.joint_names), np.inf)
    max_err = 0.0
    for y in ys:
        for z in zs:
            target = np.array([[plane.x, y, z]])
            try:
                q = ik.solve(target, q0=robot.q_home)
            except UnreachableTargetError:
                unreachable += 1
                continue
            max_err = max(max_err, float(np.linalg.norm(ik.forward(q) - target)))
            margin = np.minimum(margin, np.minimum(q[0] - robot.lower, robot.upper - q[0]))
    return {"grid": [n, n], "grow_m": grow, "points": n * n, "unreachable": unreachable,
            "max_error_m": max_err,
            "joint_margin_deg": dict(zip(robot.joint_names,
                                         np.round(np.rad2deg(margin), 2).tolist()))}


def main() -> dict:
    from iloci_pinocchio.ik import PinocchioIK

    cfg = SensorimotorConfig()
    robot = get_robot()
    ik = PinocchioIK(robot)
    demos = load_lasa()
    import scipy.interpolate  # noqa: F401  (import time is not preprocessing time)
    import scipy.ndimage  # noqa: F401
    import scipy.signal  # noqa: F401

    t0 = time.perf_counter()
    targets = [robot.plane.to_3d(preprocessed(d, cfg, robot)) for d in demos]
    t_pre = time.perf_counter() - t0

    runs = []
    for _ in range(3):
        t0 = time.perf_counter()
        paths = [ik.solve(x, q0=robot.q_home) for x in targets]
        reached = [ik.forward(q) for q in paths]
        runs.append(time.perf_counter() - t0)

    err = np.concatenate([np.linalg.norm(r - x, axis=1) for r, x in zip(reached, targets)])
    q = np.vstack(paths)
    violations = int(np.sum((q < robot.lower) | (q > robot.upper)))
    margin = np.minimum(q - robot.lower, robot.upper - q).min(axis=0)
    result = {
        "demos": len(demos),
        "points": int(err.size),
        "steps": cfg.steps,
        "max_error_m": float(err.max()),
        "median_error_m": float(np.median(err)),
        "limit_violations": violations,
        "seconds": float(min(runs)),
        "seconds_runs": [round(r, 4) for r in runs],
        "microseconds_per_point": float(min(runs) / err.size * 1e6),
        "preprocess_seconds": float(t_pre),
        "joint_margin_deg": dict(zip(robot.joint_names,
                                     np.round(np.rad2deg(margin), 2).tolist())),
        "plane": {"x": robot.plane.x, "y": robot.plane.y, "z": robot.plane.z,
                  "width": robot.plane.width, "height": robot.plane.height,
                  **plane_check(ik, robot)},
        "solver": repr(ik),
        "targets": {"max_error_m": 0.001, "limit_violations": 0, "seconds": 1.0},
        "machine": {"python": sys.version.split()[0], "platform": platform.platform(),
                    "cpus": os.cpu_count()},
    }
    result["passed"] = bool(result["max_error_m"] < 0.001 and violations == 0
                            and result["seconds"] <= 1.0)
    # atomic: a reader never sees a half-written file
    from iloci.evaluation.report import write_json_atomic
    write_json_atomic(RESULTS, result)
    return result


if __name__ == "__main__":
    res = main()
    print(json.dumps({k: res[k] for k in ("demos", "points", "max_error_m", "median_error_m",
                                          "limit_violations", "seconds", "passed")}, indent=2))
    print(f"plane check: {res['plane']['unreachable']} unreachable of "
          f"{res['plane']['points']}, margins {res['plane']['joint_margin_deg']}")
    print(f"wrote {RESULTS}")
    sys.exit(0 if res["passed"] else 1)
