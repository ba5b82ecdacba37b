"""Evaluation benchmark: the paper's 5-fold LASA experiment, CCR and wall time.

Writes ``benchmarks/results/evaluate.json``::

    ccr_mean, ccr_std, ccr_folds    iloci's correct classification rate
    baseline                        the DTW 1-NN baseline on the same folds
    paper                           the paper's CCR (91.346 +- 3.511 %)
    wall_seconds                    the whole run (all folds, ``--jobs`` processes)
    fold_wall_seconds               each fold's own wall time
    interactions_per_demo, entries, exemplars, prototypes, concepts
    targets                         the issue's targets and whether this run met them
    rnnpb_kernel                    native-rnnpb's kernel and instruction set here
                                    (``ILOCI_RNNPB_ISA=avx2`` forces one: same results)
    machine                         CPU count and load average before and after

It runs exactly what ``iloci evaluate`` runs (the default back ends unless
``--config`` says otherwise) and also writes the full report to ``--out``.

Run: ``python benchmarks/evaluate.py [--config C] [--jobs 2] [--out runs/bench]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results" / "evaluate.json"


def _kernel(model: str) -> str | None:
    """What native-rnnpb's float32 code is here (``ILOCI_RNNPB_ISA`` included), else None."""
    if model != "native-rnnpb":
        return None
    from iloci_native.native import kernel_info
    return kernel_info()


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", "-c", help="TOML config (default: the paper's settings)")
    ap.add_argument("--jobs", "-j", type=int, default=2, help="folds in parallel (default 2)")
    ap.add_argument("--out", "-o", default="runs/bench", help="report directory")
    args = ap.parse_args(argv)

    from iloci.config import load_config
    from iloci.evaluation.evaluate import evaluate
    from iloci.evaluation.report import headline, write_json_atomic, write_outputs

    config = load_config(args.config)
    load_before = os.getloadavg()
    t0 = time.perf_counter()
    metrics, results = evaluate(config, jobs=args.jobs)
    wall = time.perf_counter() - t0
    write_outputs(args.out, metrics, results)
    paper = metrics["paper"]["ccr_mean"]
    baseline = metrics.get("baseline", {})
    out = {
        "command": "python benchmarks/evaluate.py " + " ".join(argv or sys.argv[1:]),
        "back_ends": {k: getattr(config, k).name for k in
                      ("perceptual_model", "clusterer", "teacher", "ik", "simulator")},
        "ccr_mean": metrics["ccr_mean"],
        "ccr_std": metrics["ccr_std"],
        "ccr_folds": metrics["ccr_folds"],
        "baseline": {k: baseline.get(k) for k in ("method", "ccr_mean", "ccr_std", "ccr_folds")},
        "paper": metrics["paper"],
        "wall_seconds": wall,
        "fold_wall_seconds": metrics["fold_wall_seconds"],
        "jobs": args.jobs,
        **{k: metrics[k] for k in ("interactions_per_demo", "entries", "exemplars",
                                   "prototypes", "concepts", "generation_error")},
        "targets": {
            "ccr_mean_ge_paper_91.35": metrics["ccr_mean"] >= paper,
            "ccr_mean_ge_dtw_baseline": (metrics["ccr_mean"] >= baseline["ccr_mean"]
                                         if baseline else None),
            "wall_le_180_s": wall <= 180.0,
        },
        "rnnpb_kernel": _kernel(config.perceptual_model.name),
        "machine": {"python": platform.python_version(), "platform": platform.platform(),
                    "cpus": os.cpu_count(), "load_average_before": load_before,
                    "load_average_after": os.getloadavg()},
        "versions": metrics["versions"],
    }
    write_json_atomic(RESULTS, out)
    print(headline(metrics))
    print(f"wall {wall:.1f} s with {args.jobs} job(s); wrote {RESULTS}")
    return out


if __name__ == "__main__":
    main()
