"""``iloci sweep SPEC.toml [--address ADDR] [--out DIR]``."""

from __future__ import annotations

import argparse
import shlex
import sys
import warnings


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sweep", help="grid or random search over config values x seeds x folds on Ray",
        description="Run every fold of every seed of every setting a sweep spec names, "
        "as Ray tasks; each finished run is stored at once, so a sweep started again "
        "skips it. Writes results.csv, report.md and figures/ to --out. The spec's "
        "format: `python -c 'import iloci_ray.sweep as s; print(s.__doc__)'`.")
    p.add_argument("spec", metavar="SPEC.toml", help="the sweep spec")
    p.add_argument("--address", metavar="ADDR",
                   help="a running Ray cluster, HOST:PORT (`ray start --head` prints it); "
                   "default: start Ray on this machine")
    p.add_argument("--out", "-o", default=None,
                   help="output directory (default: runs/sweep-<spec name>)")
    p.add_argument("--jobs", "-j", type=int, default=None,
                   help="runs at once (default: the cluster's CPUs)")
    p.add_argument("--retries", type=int, default=None, metavar="N",
                   help="times a run whose worker died (out of memory, a signal, a crash) is "
                   "started again before it is recorded as failed (default: 2)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress display")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from iloci.errors import InvalidInputError
    from iloci.display import Bars
    from iloci_ray.report import write_report
    from iloci_ray.sweep import (RETRIES, check_out, load_spec, other_spec, plan_runs,
                                 run_sweep, summary_lines)

    if args.jobs is not None and args.jobs < 1:
        raise InvalidInputError(f"--jobs must be >= 1, got {args.jobs}.")
    retries = RETRIES if args.retries is None else args.retries
    if retries < 0:
        raise InvalidInputError(f"--retries must be >= 0, got {retries}.")
    spec = load_spec(args.spec)
    out = check_out(args.out or f"runs/sweep-{Path(args.spec).stem}")
    before = other_spec(out, spec.source)
    if before:
        warnings.warn(f"{out} holds the report of another sweep spec ({before}); this "
                      "sweep's report replaces it. Its runs are kept: run that spec again "
                      f"with --out {out} to write its report back, or give another --out.",
                      stacklevel=1)
    total = len(plan_runs(spec))
    print(f"iloci sweep: {spec.source}, {total} runs, out {out}, Ray "
          f"{args.address or 'on this machine'}", file=sys.stderr)
    bars = Bars(unit="runs")
    counts = {"finished": 0, "skipped": 0, "failed": 0}

    def on_event(kind, run, metrics) -> None:
        if kind == "started":
            return
        if kind == "restarted":
            bars.log(f"Ray lost its raylet ({metrics['error']}): stopped and started again "
                     f"({metrics['restart']} of {metrics['of']} times), {metrics['runs']} "
                     "run(s) left, those in flight redone")
            return
        if kind in ("retried", "failed"):
            what = "started again" if kind == "retried" else "recorded as failed"
            bars.log(f"run {run.key}: {run.setting}, seed {run.seed}, fold {run.fold}: "
                     f"{metrics['error']} (try {metrics['attempts']} of {retries + 1}); "
                     f"{what}")
            if kind == "retried":
                return
        counts[kind] += 1
        if kind == "finished":
            bars.log(f"run {run.key}: {run.setting}, seed {run.seed}, fold {run.fold}: "
                     f"CCR {100 * metrics['ccr']:.1f} %, {metrics['wall_seconds']:.0f} s")
        bars.update("sweep", sum(counts.values()),
                    f"{counts['skipped']} stored before, {counts['failed']} failed")

    if args.quiet:
        records, info = run_sweep(spec, out, address=args.address, jobs=args.jobs,
                                  retries=retries)
    else:
        with bars:
            bars.add("sweep", "sweep", total)
            records, info = run_sweep(spec, out, address=args.address, jobs=args.jobs,
                                      retries=retries, on_event=on_event)
    command = " ".join(["iloci sweep", *(shlex.quote(a) for a in sys.argv[2:])]) \
        if sys.argv[1:2] == ["sweep"] else "iloci sweep ..."
    for line in summary_lines(info, records, command):
        print(line)
    print(f"wall {info['wall_seconds']:.1f} s")
    if records:
        report = write_report(out, spec, records, info)
        print(f"wrote {out}/results.csv, {report} and figures/")
    return 1 if info["failed"] else 0
