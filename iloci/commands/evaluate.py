"""``iloci evaluate``: the paper's k-fold LASA experiment, with a report."""

from __future__ import annotations

import argparse
import sys
import time
from typing import TextIO


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("evaluate", help="run the k-fold LASA evaluation and write a report")
    p.add_argument("--config", "-c", help="TOML config (default: the paper's settings)")
    p.add_argument("--out", "-o", default="runs/lasa", help="output directory "
                   "(default: runs/lasa)")
    p.add_argument("--jobs", "-j", type=int, default=None,
                   help="folds in parallel processes (default: evaluation.jobs)")
    p.add_argument("--folds", type=int, nargs="+", metavar="K",
                   help="run only these folds (0-based)")
    p.add_argument("--no-baseline", action="store_true", help="skip the DTW 1-NN baseline")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress display")
    p.set_defaults(func=run)


def _fmt_s(s: float) -> str:
    s = max(0, int(round(s)))
    return f"{s // 60}:{s % 60:02d}"


class Progress:
    """Progress bars with ETA, one per fold, redrawn on a terminal."""

    def __init__(self, stream: TextIO = sys.stderr, width: int = 24) -> None:
        self.stream = stream
        self.width = width
        self.tty = stream.isatty()
        self.folds: dict[int, dict] = {}
        self.t0 = time.perf_counter()
        self.drawn = 0
        self.last_plain: dict[int, int] = {}

    def __call__(self, msg: dict) -> None:
        k = msg["fold"]
        now = time.perf_counter()
        f = self.folds.setdefault(k, {"step": 0, "total": 1, "start": now, "done": False,
                                      "ccr": None, "feedback": [], "queued": False})
        kind = msg["kind"]
        if kind == "fold_queued":
            f.update(total=max(1, msg["total"]), queued=True)
        elif kind == "fold_start":
            f.update(total=max(1, msg["total"]), start=now, queued=False)
        elif kind == "interaction":
            f["step"] = msg["step"] + 1
            f["total"] = max(1, msg["total"])
        elif kind == "fold_done":
            f.update(done=True, ccr=msg["ccr"], step=f["total"], seconds=msg["seconds"])
        self.draw(k)

    def _line(self, k: int, f: dict) -> str:
        frac = min(1.0, f["step"] / f["total"])
        bar = "#" * int(frac * self.width)
        elapsed = time.perf_counter() - f["start"]
        if f["done"]:
            tail = f"done in {_fmt_s(f.get('seconds', elapsed))}, CCR {100 * f['ccr']:.1f} %"
        elif f["step"]:
            eta = elapsed / f["step"] * (f["total"] - f["step"])
            tail = f"{elapsed:5.0f} s, ETA {_fmt_s(eta)}"
        else:
            tail = "waiting for a worker" if f.get("queued") else "starting"
        return (f"fold {k} [{bar:<{self.width}}] {f['step']:>3}/{f['total']} demos  {tail}")

    def draw(self, changed: int) -> None:
        if self.tty:
            if self.drawn:
                self.stream.write(f"\x1b[{self.drawn}F")
            lines = [self._line(k, self.folds[k]) for k in sorted(self.folds)]
            total_elapsed = time.perf_counter() - self.t0
            lines.append(f"elapsed {_fmt_s(total_elapsed)}")
            for line in lines:
                self.stream.write("\x1b[2K" + line + "\n")
            self.drawn = len(lines)
            self.stream.flush()
            return
        f = self.folds[changed]
        quarter = int(4 * f["step"] / f["total"]) if not f["done"] else 5
        if self.last_plain.get(changed) != quarter:
            self.last_plain[changed] = quarter
            print(self._line(changed, f), file=self.stream, flush=True)


def _check_out_dir(out: str) -> None:
    """Raise InvalidInputError unless the report can be written under ``out``."""
    import os
    import tempfile
    from pathlib import Path

    from iloci.errors import InvalidInputError
    path = Path(out)
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as exc:
        raise InvalidInputError(f"--out {out}: the report cannot be written there "
                                f"({exc.strerror or exc}); choose another directory."
                                ) from None
    if not os.access(path, os.W_OK):
        raise InvalidInputError(f"--out {out}: directory is not writable.")


def run(args: argparse.Namespace) -> int:
    from iloci.config import load_config
    from iloci.evaluation.evaluate import evaluate
    from iloci.evaluation.report import check_report_extras, headline, write_outputs

    config = load_config(args.config)
    # fail now, not after the first fold: the report's libraries, a writable --out
    check_report_extras(baseline=not args.no_baseline)
    _check_out_dir(args.out)
    progress = None if args.quiet else Progress()
    print(f"iloci evaluate: {config.evaluation.folds}-fold LASA, seed {config.seed}, "
          f"perceptual model {config.perceptual_model.name}, clusterer "
          f"{config.clusterer.name}, teacher {config.teacher.name}, "
          f"jobs {args.jobs or config.evaluation.jobs}", file=sys.stderr)
    try:
        metrics, results = evaluate(config, jobs=args.jobs, progress=progress,
                                    folds=args.folds, baseline=not args.no_baseline)
    except KeyboardInterrupt:
        print("\ninterrupted: workers stopped, nothing written.", file=sys.stderr)
        return 130
    report = write_outputs(args.out, metrics, results)
    print(headline(metrics))
    print(f"\nwrote {args.out}/metrics.json, {report} and figures/")
    return 0
