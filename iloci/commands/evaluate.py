"""``iloci evaluate``: the paper's k-fold LASA experiment, with a report."""

from __future__ import annotations

import argparse
import sys


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("evaluate", help="run the k-fold LASA evaluation and write a report")
    p.add_argument("--config", "-c", help="TOML config (default: the paper's settings)")
    p.add_argument("--out", "-o", default="runs/lasa", help="output directory "
                   "(default: runs/lasa)")
    p.add_argument("--jobs", "-j", type=int, default=None,
                   help="folds run at once (default: evaluation.jobs)")
    p.add_argument("--executor", default="local", metavar="NAME",
                   help="where folds run: 'local' (worker processes, the default) or 'ray' "
                   "(needs the iloci-ray plugin)")
    p.add_argument("--address", metavar="ADDR",
                   help="a running Ray cluster (HOST:PORT) for --executor ray "
                   "(default: start Ray on this machine)")
    p.add_argument("--folds", type=int, nargs="+", metavar="K",
                   help="run only these folds (0-based)")
    p.add_argument("--no-baseline", action="store_true", help="skip the DTW 1-NN baseline")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress display")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from iloci.config import load_config
    from iloci.evaluation.evaluate import evaluate
    from iloci.evaluation.report import headline, write_outputs
    from iloci.progress import FoldProgress

    config = load_config(args.config)
    print(f"iloci evaluate: {config.evaluation.folds}-fold LASA, seed {config.seed}, "
          f"perceptual model {config.perceptual_model.name}, clusterer "
          f"{config.clusterer.name}, teacher {config.teacher.name}, "
          f"jobs {args.jobs or config.evaluation.jobs}, executor {args.executor}",
          file=sys.stderr)
    progress = None if args.quiet else FoldProgress()
    try:
        if progress is None:
            metrics, results = evaluate(config, jobs=args.jobs, folds=args.folds,
                                        baseline=not args.no_baseline,
                                        executor=args.executor, address=args.address)
        else:
            with progress:
                metrics, results = evaluate(config, jobs=args.jobs, progress=progress,
                                            folds=args.folds, baseline=not args.no_baseline,
                                            executor=args.executor, address=args.address)
    except KeyboardInterrupt:
        print("\ninterrupted: workers stopped, nothing written.", file=sys.stderr)
        return 130
    report = write_outputs(args.out, metrics, results)
    print(headline(metrics))
    print(f"\nwrote {args.out}/metrics.json, {report} and figures/")
    return 0
