"""Simulator tracking benchmark: the IK joint path of every LASA demonstration, executed.

Each of the 182 demonstrations (26 shapes x 7) goes through the default
sensorimotor pipeline (50 points, Pinocchio IK) and its joint path is
executed at the demonstration's own pace (``Motion.dt``) in each simulator.
The error of a point is the distance between the pen tip the simulated arm
reached and the planned one (Pinocchio FK of the planned joint path, which
is the IK target within 1e-7 m).

Writes ``benchmarks/results/sim.json``, per simulator (``pybullet``,
``mujoco``)::

    max_error_m, median_error_m   executed vs planned pen tip, over all points
    p99_error_m                   99th percentile of the same
    max_joint_error_rad           executed vs planned joint angles
    seconds                       wall time of the 182 executions (no IK)
    ms_per_execution              seconds / 182
    settings                      the simulator (its repr)

plus ``agreement_max_m``: the largest distance between the PyBullet and
MuJoCo pen paths of the same joint path. Target (issue 7): max_error_m <
0.002 for both.

Run: ``python benchmarks/sim.py``  (needs iloci-pinocchio, iloci-pybullet and
iloci-mujoco).
"""

from __future__ import annotations

import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from iloci.config import SensorimotorConfig
from iloci.data import load_lasa
from iloci.sensorimotor.pipeline import to_motions

RESULTS = Path(__file__).resolve().parent / "results" / "sim.json"
TARGET_MAX_ERROR_M = 0.002


def run(sim, motions, planned) -> tuple[dict, list[np.ndarray]]:
    """Execute every motion in ``sim``; return its statistics and the pen paths."""
    t0 = time.perf_counter()
    executions = [sim.execute(m.joint_path, m.dt) for m in motions]
    seconds = time.perf_counter() - t0
    err = np.concatenate([np.linalg.norm(e.end_effector - p, axis=1)
                          for e, p in zip(executions, planned)])
    joint_err = max(float(np.abs(e.joint_path - m.joint_path).max())
                    for e, m in zip(executions, motions))
    stats = {
        "max_error_m": float(err.max()),
        "median_error_m": float(np.median(err)),
        "p99_error_m": float(np.percentile(err, 99)),
        "max_joint_error_rad": joint_err,
        "seconds": float(seconds),
        "ms_per_execution": float(seconds / len(motions) * 1e3),
        "settings": repr(sim),
    }
    return stats, [e.end_effector for e in executions]


def main() -> dict:
    from iloci_mujoco.sim import MuJoCoSimulator
    from iloci_pinocchio.ik import PinocchioIK
    from iloci_pybullet.sim import PyBulletSimulator

    cfg = SensorimotorConfig()
    ik = PinocchioIK()
    demos = load_lasa()
    motions = to_motions(demos, cfg, ik)
    planned = [ik.forward(m.joint_path) for m in motions]
    dts = np.array([m.dt for m in motions])

    result: dict = {"demos": len(motions), "points": int(sum(len(m) for m in motions)),
                    "steps": cfg.steps, "dt_s": {"min": float(dts.min()),
                                                 "median": float(np.median(dts)),
                                                 "max": float(dts.max())}}
    paths = {}
    for name, make in (("pybullet", PyBulletSimulator), ("mujoco", MuJoCoSimulator)):
        with make("nao-v32-right-arm") as sim:
            result[name], paths[name] = run(sim, motions, planned)
    result["agreement_max_m"] = float(max(
        np.linalg.norm(a - b, axis=1).max() for a, b in zip(paths["pybullet"], paths["mujoco"])))
    result["target"] = {"max_error_m": TARGET_MAX_ERROR_M}
    result["passed"] = bool(all(result[n]["max_error_m"] < TARGET_MAX_ERROR_M
                                for n in ("pybullet", "mujoco")))
    result["machine"] = {"python": sys.version.split()[0], "platform": platform.platform(),
                         "cpus": os.cpu_count()}
    # atomic: a reader never sees a half-written file
    from iloci.evaluation.report import write_json_atomic
    write_json_atomic(RESULTS, result)
    return result


if __name__ == "__main__":
    res = main()
    for name in ("pybullet", "mujoco"):
        r = res[name]
        print(f"{name:9s} max {r['max_error_m'] * 1e3:.3f} mm  median "
              f"{r['median_error_m'] * 1e3:.3f} mm  {r['seconds']:.1f} s "
              f"({r['ms_per_execution']:.0f} ms per execution)")
    print(f"pybullet vs mujoco: max {res['agreement_max_m'] * 1e3:.3f} mm; "
          f"passed={res['passed']}; wrote {RESULTS}")
    sys.exit(0 if res["passed"] else 1)
