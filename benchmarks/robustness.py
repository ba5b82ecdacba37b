"""Robustness benchmark: recognizing drawings the way people draw them.

The paper's 5-fold LASA experiment (default config), with every fold's test
set recognized again under each perturbation of
:data:`iloci.evaluation.perturb.SUITE` (pace, sampling rate, pen rests,
jitter, rotation, stretch, uniform scale), iloci beside DTW 1-NN; then the
same folds taught in *blocked* order (concept by concept) instead of
shuffled. Writes ``benchmarks/results/robustness.json``::

    robustness        per perturbation: iloci and each baseline's CCR over the folds
    baselines         the baselines on the clean folds (best_baseline: the strongest)
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


def build_results(metrics: dict, blocked: dict | None, config, *, command: str,
                  wall_suite: float, wall_blocked: float, jobs: int, folds,
                  load_before, load_after, note: str) -> dict:
    """benchmarks/results/robustness.json from the two evaluations' metrics."""
    order: dict = {"shuffled": {"ccr_mean": metrics["ccr_mean"],
                                "ccr_folds": metrics["ccr_folds"]}}
    if blocked is not None:
        order["blocked"] = {"ccr_mean": blocked["ccr_mean"], "ccr_folds": blocked["ccr_folds"]}
        order["difference"] = blocked["ccr_mean"] - metrics["ccr_mean"]
    wall = wall_suite + wall_blocked
    rob = metrics["robustness"]
    clean = rob["clean"]["ccr_mean"]
    within = {}
    for name, row in rob.items():
        if row["group"] in ("clean", "stretch"):
            continue
        limit = ROTATION_WITHIN if row["group"] == "rotation" else WITHIN
        within[name] = clean - row["ccr_mean"] <= limit + 1e-12
    return {
        "command": command,
        "back_ends": {k: config[k]["name"] for k in
                      ("perceptual_model", "clusterer", "teacher", "ik", "simulator")},
        "sensorimotor": config["sensorimotor"],
        "folds": folds,
        "ccr_mean": metrics["ccr_mean"],
        "ccr_std": metrics["ccr_std"],
        "ccr_folds": metrics["ccr_folds"],
        "baseline": metrics.get("baseline"),
        "baselines": metrics.get("baselines"),
        "best_baseline": metrics.get("best_baseline"),
        "robustness": rob,
        "order": order,
        "wall_seconds": wall,
        "wall_seconds_suite": wall_suite,
        "wall_seconds_blocked": wall_blocked,
        "jobs": jobs,
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
                    "load_average_after": load_after, "note": note},
        "versions": metrics["versions"],
    }


def from_runs(suite_dir: str, blocked_dir: str | None, results: str, note: str) -> dict:
    """Rebuild the JSON from reports already written (``--out`` of this script, and
    ``iloci evaluate --order blocked --out DIR``), e.g. when the blocked part ran
    on its own."""
    import json

    from iloci.evaluation.report import write_json_atomic
    metrics = json.loads((Path(suite_dir) / "metrics.json").read_text())
    blocked = (json.loads((Path(blocked_dir) / "metrics.json").read_text())
               if blocked_dir else None)
    def what_matters(config: dict) -> dict:
        # min_points only rejects strokes shorter than it: none in LASA or the suite
        return config | {"evaluation": None,
                         "sensorimotor": config["sensorimotor"] | {"min_points": None}}

    if blocked is not None and what_matters(blocked["config"]) != what_matters(metrics["config"]):
        raise SystemExit("the blocked run's config differs from the suite's beyond "
                         "[evaluation] and min_points")
    out = build_results(
        metrics, blocked, metrics["config"],
        command=f"python benchmarks/robustness.py --from-runs {suite_dir} {blocked_dir or ''}",
        wall_suite=metrics["wall_seconds"],
        wall_blocked=blocked["wall_seconds"] if blocked else 0.0,
        jobs=metrics["jobs"], folds=[f["fold"] for f in metrics["folds"]],
        load_before=None, load_after=None, note=note)
    write_json_atomic(results, out)
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
    ap.add_argument("--from-runs", nargs="+", metavar="DIR",
                    help="write the JSON from reports already written: the suite's --out "
                    "and, optionally, an `iloci evaluate --order blocked` --out")
    ap.add_argument("--note", default="", help="with --from-runs: how the runs were made")
    args = ap.parse_args(argv)
    if args.from_runs:
        dirs = args.from_runs + [None]
        return from_runs(dirs[0], dirs[1], args.results, args.note)

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

    wall_blocked = 0.0
    blocked_metrics = None
    if not args.no_blocked:
        t1 = time.perf_counter()
        blocked, _ = evaluate(config.replace(evaluation={"robustness": False,
                                                         "order": "blocked"}),
                              jobs=args.jobs, folds=args.folds, baseline=False)
        wall_blocked = time.perf_counter() - t1
        blocked_metrics = blocked
        print(f"blocked order: CCR {100 * blocked['ccr_mean']:.2f} % against shuffled "
              f"{100 * metrics['ccr_mean']:.2f} %")
    wall = wall_suite + wall_blocked

    out = build_results(
        metrics, blocked_metrics, config.to_dict(),
        command="python benchmarks/robustness.py " + " ".join(argv or sys.argv[1:]),
        wall_suite=wall_suite, wall_blocked=wall_blocked, jobs=args.jobs,
        folds=args.folds or list(range(config.evaluation.folds)),
        load_before=load_before, load_after=os.getloadavg(),
        note="2 cores shared with other engineers' jobs during the run")
    write_json_atomic(args.results, out)
    print(f"wall {wall:.1f} s ({wall_suite:.1f} s suite, {wall_blocked:.1f} s blocked) with "
          f"{args.jobs} job(s); wrote {args.results}")
    return out


if __name__ == "__main__":
    main()
