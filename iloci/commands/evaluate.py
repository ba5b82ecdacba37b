"""``iloci evaluate``: the paper's k-fold experiment on LASA or your own data set, with a report."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import re
import sys

from iloci.config import load_config
from iloci.data.datasets import check_protocol, load_dataset_once, manifests_in
from iloci.data.files import writable_dir
from iloci.errors import InvalidInputError
from iloci.progress import REFUSED_ERRNOS, why_not_written


def _jobs(args: argparse.Namespace, config) -> str:
    """The folds run at once, as evaluate() will resolve them, for the banner."""
    # the evaluation's modules are loaded when a command runs, not on every `iloci` start
    from iloci.evaluation.evaluate import default_jobs
    if args.jobs is not None:
        return str(args.jobs)
    if config.evaluation.jobs:
        return str(config.evaluation.jobs)
    folds = len(args.folds) if args.folds else config.evaluation.folds
    cores = default_jobs()
    if folds < cores:
        return f"{folds} (one per fold: {folds} fold(s) to run, {cores} CPU cores)"
    return f"{cores} (one per CPU core)"


def _default_out(config) -> str:
    """``runs/lasa``, or for a data set of one's own ``runs/<its name>``: a run on other
    data never writes over LASA's report (the data set is read here, checked, and kept
    for the run: :func:`~iloci.data.datasets.load_dataset_once`)."""
    if not config.data.path:
        return os.path.join("runs", "lasa")
    name = load_dataset_once(config.data.path, warn=True).name
    return os.path.join("runs", re.sub(r"[^\w.-]+", "_", name).strip("._") or "data")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("evaluate", help="run the k-fold evaluation (LASA or --data) and write "
                       "a report")
    p.add_argument("--config", "-c", help="TOML config (default: the paper's settings)")
    p.add_argument("--data", metavar="PATH",
                   help="your own data set instead of LASA: a folder with a sub-folder of "
                   "trajectory files (.csv, .npy, .inkml, .xml) per concept, optionally a "
                   "sub-folder per writer in each, or a manifest (.csv/.json: file, "
                   "concept[, writer, session]) (default: [data] path)")
    p.add_argument("--split", choices=("concepts", "writers"), default=None,
                   help="concepts: k folds per concept (the paper's); writers: teach some "
                   "writers, recognize the others (default: evaluation.split)")
    p.add_argument("--out", "-o", default=None, help="output directory (default: "
                   "runs/lasa; with --data or [data] path, runs/ and the data set's name)")
    p.add_argument("--jobs", "-j", type=int, default=None,
                   help="folds run at once (default: evaluation.jobs; when that is 0, "
                   "one per CPU core)")
    p.add_argument("--executor", default="local", metavar="NAME",
                   help="where folds run: 'local' (worker processes, the default) or 'ray' "
                   "(needs the iloci-ray plugin)")
    p.add_argument("--address", metavar="ADDR",
                   help="a running Ray cluster (HOST:PORT) for --executor ray "
                   "(default: start Ray on this machine)")
    p.add_argument("--folds", type=int, nargs="+", metavar="K",
                   help="run only these folds (0-based)")
    p.add_argument("--no-baseline", action="store_true",
                   help="skip the baselines (DTW 1-NN on normalised paths, $1, raw DTW)")
    p.add_argument("--memories", metavar="DIR",
                   help="also save each fold's learned robot as DIR/fold-K.npz")
    p.add_argument("--protocol", choices=("folds", "stream"), default=None,
                   help="folds: the paper's k-fold experiment; stream: test-then-learn over "
                   "every demonstration (default: evaluation.protocol)")
    p.add_argument("--robustness", action="store_true",
                   help="also recognize every test set under the perturbations of "
                   "iloci.evaluation.perturb (pace, sampling, rests, jitter, rotation, "
                   "stretch, scale) beside DTW 1-NN (evaluation.robustness)")
    p.add_argument("--order", choices=("shuffled", "blocked"), default=None,
                   help="order of each learning set: seeded shuffle, or concept by "
                   "concept (default: evaluation.order)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress display")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # the evaluation's modules and rich: loaded when the command runs, not on every `iloci` start
    from iloci.evaluation.report import check_report_extras

    config = load_config(args.config)
    changes = {}
    if args.robustness:
        changes["robustness"] = True
    if args.order:
        changes["order"] = args.order
    if args.split:
        changes["split"] = args.split
    if changes:
        config = config.replace(evaluation=changes)
    if args.data is not None and not args.data.strip():
        raise InvalidInputError("--data is empty (an unset shell variable?): give the path "
                                "of a data set, or leave --data out to evaluate on LASA. "
                                "Nothing was run.")
    if args.data:
        config = config.replace(data={"path": args.data})
    if args.protocol is not None and args.protocol != config.evaluation.protocol:
        config = config.replace(evaluation={"protocol": args.protocol})
    # fail now, not after the first fold: the report's libraries, a writable --out
    check_report_extras(baseline=not args.no_baseline
                        and config.evaluation.protocol != "stream")
    if args.out is None:
        args.out = _default_out(config)
    for flag, where in (("--out", args.out), ("--memories", args.memories)):
        _outside_the_data(flag, where, config.data.path)
    # made only now, and removed again if the run fails before writing into them
    made = [d for d in (args.out, args.memories) if d and not os.path.exists(d)]
    writable_dir(args.out, "--out")
    if args.memories:
        writable_dir(args.memories, "--memories")
    try:
        if config.evaluation.protocol == "stream":
            return _run_stream(args, config)
        return _run_folds(args, config)
    except BaseException:
        for d in made:
            try:
                os.rmdir(d)  # only if still empty: nothing a run wrote is removed
            except OSError:
                pass
        raise


def _outside_the_data(flag: str, where: str | None, data: str) -> None:
    """Refuse an output folder inside a data set of concept folders: the next run would
    read it as a concept (or its files as drawings)."""
    if not where or not data:
        return
    root = Path(data).expanduser().resolve()
    if not root.is_dir() or manifests_in(root):
        return  # a manifest lists its files: a folder beside them is not read
    out = Path(where).expanduser().resolve()
    if out == root or root in out.parents:
        raise InvalidInputError(
            f"{flag} {where} is inside the data set {root}: every folder there is read as "
            f"a concept, so this run's own output would be read as drawings. Give {flag} "
            f"a folder outside it (e.g. {flag} {root.parent / 'runs' / root.name}). Nothing "
            "was run.")


def _run_folds(args: argparse.Namespace, config) -> int:
    # loaded when the command runs (see run's imports)
    from iloci.display import FoldProgress
    from iloci.evaluation.evaluate import check_drawings, evaluate
    from iloci.evaluation.report import headline, write_outputs

    if config.data.path and config.evaluation.protocol == "folds":
        # read and checked before anything runs (evaluate() checks again, cheaply)
        dataset = load_dataset_once(config.data.path, warn=True)
        check_protocol(dataset, config.evaluation.folds, config.evaluation.split,
                       config.evaluation.seed)
        check_drawings(dataset, config)
        names = list(dataset.concepts)
        shown = ", ".join(names[:8]) + (", ..." if len(names) > 8 else "")
        what = (f"data set {dataset.name} ({len(dataset.samples)} samples, "
                f"{len(dataset.concepts)} concepts, {len(dataset.writers)} "
                f"writer{'' if len(dataset.writers) == 1 else 's'}; "
                f"concepts: {shown})")
    else:
        what = "LASA"
    split = ", writer-disjoint" if config.evaluation.split == "writers" else ""
    k = config.evaluation.folds
    run = (f"{k}-fold {what}" if not args.folds else
           f"fold{'s' if len(args.folds) > 1 else ''} {', '.join(map(str, args.folds))} of "
           f"{k} folds of {what}")
    print(f"iloci evaluate: {run}{split}, seed {config.seed}, "
          f"perceptual model {config.perceptual_model.name}, clusterer "
          f"{config.clusterer.name}, teacher {config.teacher.name}, "
          f"jobs {_jobs(args, config)}, executor {args.executor}",
          file=sys.stderr)
    progress = None if args.quiet else FoldProgress()
    try:
        if progress is None:
            metrics, results = evaluate(config, jobs=args.jobs, folds=args.folds,
                                        baseline=not args.no_baseline,
                                        executor=args.executor, address=args.address,
                                        memory_dir=args.memories)
        else:
            with progress:
                metrics, results = evaluate(config, jobs=args.jobs, progress=progress,
                                            folds=args.folds, baseline=not args.no_baseline,
                                            executor=args.executor, address=args.address,
                                            memory_dir=args.memories)
    except KeyboardInterrupt:
        print("\ninterrupted: workers stopped, nothing written.", file=sys.stderr)
        return 130
    # the results first: a report that cannot be written does not take them along
    print(headline(metrics))
    if metrics.get("robustness"):
        # loaded when the command runs (see run's imports)
        from iloci.evaluation.report import robustness_table
        print("\n" + "\n".join(robustness_table(metrics["robustness"])))
    try:
        report = write_outputs(args.out, metrics, results)
    except OSError as exc:
        return _not_written(args.out, exc)
    print(f"\nwrote {args.out}/metrics.json, {report} and figures/")
    return 0


def _not_written(out: str, exc: OSError) -> int:
    """Say that the report could not be written (the results were printed), and what is
    in ``out``; exit code 1."""
    if exc.errno not in REFUSED_ERRNOS:
        raise exc
    written = sorted(p.name for p in Path(out).glob("*.json") if p.is_file())
    kept = (f"{', '.join(written)} {'is' if len(written) == 1 else 'are'} complete there "
            "(each file is written whole or not at all)" if written else "nothing is there")
    print(f"error: {why_not_written(exc.filename or out, exc)} The results above were "
          f"computed, but the report in {out} is not complete: {kept}. Free some space (or "
          "fix the permissions) and run the command again, or give another --out.",
          file=sys.stderr)
    return 1


def _run_stream(args: argparse.Namespace, config) -> int:
    # loaded when the command runs (see run's imports)
    from iloci.evaluation.report import stream_headline, write_stream_outputs
    from iloci.evaluation.stream import run_stream

    print(f"iloci evaluate: stream protocol (test-then-learn) over "
          f"{config.data.path or 'LASA'}, seed "
          f"{config.seed}, perceptual model {config.perceptual_model.name}, teacher "
          f"{config.teacher.name}", file=sys.stderr)
    last = [-1]

    def progress(msg: dict) -> None:
        quarter = int(10 * (msg["step"] + 1) / msg["total"])
        if not args.quiet and quarter != last[0]:
            last[0] = quarter
            print(f"stream {msg['step'] + 1}/{msg['total']} demos", file=sys.stderr,
                  flush=True)

    try:
        metrics, steps = run_stream(config, progress=progress)
    except KeyboardInterrupt:
        print("\ninterrupted: nothing written.", file=sys.stderr)
        return 130
    print(stream_headline(metrics))
    try:
        report = write_stream_outputs(args.out, metrics, steps)
    except OSError as exc:
        return _not_written(args.out, exc)
    print(f"\nwrote {args.out}/metrics.json, {report} and figures/")
    return 0
