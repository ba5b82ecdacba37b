"""Robustness benchmark: recognizing drawings the way people draw them.

The paper's 5-fold LASA experiment (default config), with every fold's test
set recognized again under each perturbation of
:data:`iloci.evaluation.perturb.SUITE` (pace, sampling rate, pen rests,
jitter, rotation, stretch, uniform scale), iloci beside DTW 1-NN; then the
same folds taught in *blocked* order (concept by concept) instead of
shuffled. Writes ``benchmarks/results/robustness.json``::

    robustness        per perturbation: iloci and DTW 1-NN CCR over the folds
    order             shuffled and blocked CCR, per fold and mean
    targets           the issue's targets and whether this run met them
    wall_seconds      both runs; machine: CPU count and load average

Run: ``python benchmarks/robustness.py [--config C] [--jobs 2]
[--set section.key=value ...] [--no-blocked] [--out runs/robustness]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
import tomllib
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results" / "robustness.json"

#: The issue's targets (CCR points).
CLEAN_FLOOR = 0.9808          # today's 5-fold CCR, benchmarks/results/evaluate.json
WITHIN = 0.02                 # every perturbation but rotation and stretch
ROTATION_WITHIN = 0.03        # rotation up to 15 degrees
BLOCKED_WITHIN = 0.02
WALL_LIMIT_S = 15 * 60


def _overrides(pairs: list[str]) -> dict:
    """``section.key=value`` (value in TOML syntax) -> nested dict."""
    out: dict = {}
    for pair in pairs:
        key, _, value = pair.partition("=")
        sec, _, name = key.partition(".")
        out.setdefault(sec, {})[name] = tomllib.loads(f"v = {value}")["v"]
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", "-c", help="TOML config (default: the default settings)")
    ap.add_argument("--jobs", "-j", type=int, default=2, help="folds in parallel (default 2)")
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                    help="override one config value (TOML syntax), e.g. "
                    "sensorimotor.smoothing=0.03")
    ap.add_argument("--no-blocked", action="store_true", help="skip the blocked-order run")
    ap.add_argument("--folds", type=int, nargs="+", metavar="K", help="only these folds")
    ap.add_argument("--out", "-o", default="runs/robustness", help="report directory")
    ap.add_argument("--results", default=str(RESULTS), help="JSON to write")
    args = ap.parse_args(argv)

    from iloci.config import load_config
    from iloci.evaluation.evaluate import evaluate
    from iloci.evaluation.report import headline, robustness_table, write_json_atomic, \
        write_outputs

    config = load_config(args.config)
    for sec, values in _overrides(args.set).items():
        config = config.replace(**{sec: values})
    config = config.replace(evaluation={"robustness": True, "order": "shuffled"})
    load_before = os.getloadavg()
    t0 = time.perf_counter()
    metrics, results = evaluate(config, jobs=args.jobs, folds=args.folds)
    wall_suite = time.perf_counter() - t0
    write_outputs(args.out, metrics, results)
    print(headline(metrics))
    print("\n".join(robustness_table(metrics["robustness"])), flush=True)

    order: dict = {"shuffled": {"ccr_mean": metrics["ccr_mean"],
                                "ccr_folds": metrics["ccr_folds"]}}
    wall_blocked = 0.0
    if not args.no_blocked:
        t1 = time.perf_counter()
        blocked, _ = evaluate(config.replace(evaluation={"robustness": False,
                                                         "order": "blocked"}),
                              jobs=args.jobs, folds=args.folds, baseline=False)
        wall_blocked = time.perf_counter() - t1
        order["blocked"] = {"ccr_mean": blocked["ccr_mean"], "ccr_folds": blocked["ccr_folds"]}
        order["difference"] = blocked["ccr_mean"] - metrics["ccr_mean"]
        print(f"blocked order: CCR {100 * blocked['ccr_mean']:.2f} % against shuffled "
              f"{100 * metrics['ccr_mean']:.2f} %")
    wall = wall_suite + wall_blocked

    rob = metrics["robustness"]
    clean = rob["clean"]["ccr_mean"]
    within = {}
    for name, row in rob.items():
        if row["group"] in ("clean", "stretch"):
            continue
        if row["group"] == "rotation":
            within[name] = clean - row["ccr_mean"] <= ROTATION_WITHIN + 1e-12
        else:
            within[name] = clean - row["ccr_mean"] <= WITHIN + 1e-12
    out = {
        "command": "python benchmarks/robustness.py " + " ".join(argv or sys.argv[1:]),
        "back_ends": {k: getattr(config, k).name for k in
                      ("perceptual_model", "clusterer", "teacher", "ik", "simulator")},
        "sensorimotor": config.to_dict()["sensorimotor"],
        "folds": args.folds or list(range(config.evaluation.folds)),
        "ccr_mean": metrics["ccr_mean"],
        "ccr_folds": metrics["ccr_folds"],
        "baseline": metrics.get("baseline"),
        "robustness": rob,
        "order": order,
        "wall_seconds": wall,
        "wall_seconds_suite": wall_suite,
        "wall_seconds_blocked": wall_blocked,
        "jobs": args.jobs,
        "targets": {
            "clean_ccr_ge_98.08": metrics["ccr_mean"] >= CLEAN_FLOOR,
            "within_2_points_except_rotation_stretch": all(
                v for k, v in within.items() if not k.startswith("rotation")),
            "rotation_le_15_within_3_points": all(
                v for k, v in within.items() if k.startswith("rotation")),
            "per_perturbation": within,
            "blocked_within_2_points": (abs(order["difference"]) <= BLOCKED_WITHIN
                                        if "difference" in order else None),
            "wall_le_15_min": wall <= WALL_LIMIT_S,
        },
        "machine": {"python": platform.python_version(), "platform": platform.platform(),
                    "cpus": os.cpu_count(), "load_average_before": load_before,
                    "load_average_after": os.getloadavg(),
                    "note": "2 cores shared with other engineers' jobs during the run"},
        "versions": metrics["versions"],
    }
    write_json_atomic(args.results, out)
    print(f"wall {wall:.1f} s ({wall_suite:.1f} s suite, {wall_blocked:.1f} s blocked) with "
          f"{args.jobs} job(s); wrote {args.results}")
    return out


if __name__ == "__main__":
    main()
