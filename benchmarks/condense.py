"""Condensing a concept's clusters: the paper's rule against ``condense = "consistent"``.

Issue 25 (recognition on data it was never tuned to). On a data set where
concepts are clustered (more than ``num_threshold`` taught drawings of a
concept per fold), each row runs ``iloci evaluate`` with the defaults but
one ``[learner]`` setting, on the same folds, the baselines beside it:

``consistent``
    the default: a valid cluster's medoid replaces only the members it
    stands for (docs/method.md, "Clustering").
``paper``
    ``condense = "paper"``: the medoid replaces every member.
``no_clustering``
    ``num_threshold = 1000000``: nothing is ever clustered (every
    rewarded drawing not strengthened stays an exemplar).

The data set: 480 single-stroke lower-case UNIPEN letters, ``c e l o s u v
w``, 6 of each by each of 10 writers (the first 10, by name, of the
writers with 6 single-stroke samples of each; ``balanced_subset(...,
per=6, seed=0)``), exported as ``letters/<letter>/<writer>/<n>.csv``
(``t, x, y`` where the file gives a sampling rate). LASA's main job and
the UNIPEN digits benchmark are not run: with at most 3 taught drawings of
a concept per fold they never cluster, and their results are bit for bit
the same under both rules (``benchmarks/golden.py --check``).

Writes ``benchmarks/results/condense.json``: per row, CCR mean and folds,
memory size (entries, prototypes), the baselines' CCR, wall seconds.

Run: ``python benchmarks/condense.py --unipen PATH [--seed 0] [--jobs 2]
[--rows consistent paper no_clustering]`` (about 5 minutes per row on an
idle 2-core machine).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "condense.json"
LETTERS = "celosuvw"
ROWS = {
    "consistent": {},
    "paper": {"learner": {"condense": "paper"}},
    "no_clustering": {"learner": {"num_threshold": 1_000_000}},
}


def export_letters(root: str, out: Path, *, letters: str = LETTERS, writers: int = 10,
                   per: int = 6) -> dict:
    """Write ``per`` single-stroke samples of each of ``letters`` by each of the first
    ``writers`` writers who drew them all as ``out/<letter>/<writer>/<n>.csv`` (t, x, y);
    returns what was written (its checksum: :func:`iloci.data.unipen.samples_checksum`)."""
    from datasets import write_sample_files  # this folder's benchmarks/datasets.py

    from iloci.data.unipen import balanced_subset, samples_checksum, unipen_letters

    samples = [s for s in unipen_letters(root, drop_copies=True)
               if s.single_stroke and s.label in letters]
    picked = balanced_subset(samples, per=per, seed=0, labels=letters)
    keep = sorted({s.writer for s in picked})[:writers]
    picked = [s for s in picked if s.writer in keep]
    write_sample_files(picked, out, times=True)
    return {"samples": len(picked), "writers": keep, "letters": letters,
            "checksum": samples_checksum(picked)}


def run_row(name: str, data: Path, seed: int, jobs: int) -> dict:
    from iloci.config import load_config
    from iloci.evaluation.evaluate import evaluate

    changes: dict = {"data": {"path": str(data)}, "evaluation": {"seed": seed}}
    for section, values in ROWS[name].items():
        changes.setdefault(section, {}).update(values)
    print(f"[condense] {name}: running", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    metrics, _ = evaluate(load_config(changes), jobs=jobs)
    wall = time.perf_counter() - t0
    return {
        "learner_changes": ROWS[name].get("learner", {}),
        "ccr_mean": metrics["ccr_mean"], "ccr_folds": metrics["ccr_folds"],
        "entries": metrics["entries"]["mean"], "prototypes": metrics["prototypes"]["mean"],
        "exemplars": metrics["exemplars"]["mean"],
        "interactions_per_demo": metrics["interactions_per_demo"]["mean"],
        "baselines": {b: {"ccr_mean": v["ccr_mean"], "ccr_folds": v["ccr_folds"]}
                      for b, v in metrics["baselines"].items()},
        "wall_seconds": wall,
    }


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--unipen", metavar="PATH", required=True,
                    help="the train_r01_v07 folder (see benchmarks/datasets.py)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", "-j", type=int, default=2)
    ap.add_argument("--rows", nargs="+", choices=list(ROWS), default=list(ROWS))
    ap.add_argument("--out", default=str(RESULTS))
    args = ap.parse_args(argv)
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="iloci-letters-") as tmp:
        data = Path(tmp) / "letters"
        source = export_letters(args.unipen, data)
        rows = {name: run_row(name, data, args.seed, args.jobs) for name in args.rows}
    out = {
        "command": "python benchmarks/condense.py " + " ".join(argv or sys.argv[1:]),
        "data": source, "seed": args.seed, "rows": rows,
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                    "load_before": load0, "load_after": os.getloadavg()},
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    for name, r in rows.items():
        best = max(r["baselines"].values(), key=lambda b: b["ccr_mean"])["ccr_mean"]
        print(f"{name}: CCR {100 * r['ccr_mean']:.2f} % (best baseline {100 * best:.2f}), "
              f"{r['entries']:.1f} entries ({r['prototypes']:.1f} prototypes), "
              f"{r['wall_seconds']:.0f} s")
    return out


if __name__ == "__main__":
    main()
