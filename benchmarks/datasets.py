"""Recognition beyond LASA: iloci beside every baseline, per data set and seed, same folds.

Data sets (each run through ``iloci.evaluation.evaluate.evaluate``, what
``iloci evaluate`` runs, so iloci and the baselines of
:mod:`iloci.evaluation.baselines` see the same folds in the same run):

``lasa``
    LASA, 26 shapes / 22 concepts, 5 folds per shape (the paper's protocol).
``unipen``
    UNIPEN ``train_r01_v07`` single-stroke isolated digits: the writers who
    drew every digit in one stroke (15 persons; IBM's session ids ``rNN-WW``
    of one person ``WW`` are one writer), one sample of each digit from each
    (150 samples, :func:`iloci.data.unipen.balanced_subset`, seed 0; of a
    drawing the release stores twice only the first copy is read, see
    :func:`iloci.data.unipen.read_unipen`),
    exported as a folder per digit with a sub-folder per writer and read by
    ``[data] path`` exactly as a user's data set is; 5 folds per concept.
``unipen-writers``
    The same samples, writer-disjoint (``[evaluation] split = "writers"``):
    the writers dealt into 5 groups, each fold taught by one group and
    tested on the drawings of the other writers, never seen.

Writes ``benchmarks/results/datasets.json``: per data set and seed, iloci's
CCR (mean, std, per fold) and each baseline's on the same folds, the best
baseline and whether iloci reaches it; the data set's size and checksum;
the wall time. Each (data set, seed) is cached in
``benchmarks/results/datasets/`` as soon as it finishes, so an interrupted
run resumes (``--fresh`` recomputes; the cache is keyed by the config, the
data set's checksum and the Python sources of ``iloci/`` and ``plugins/``,
so changed code, defaults or data rerun).

UNIPEN is not shipped: clone it and give its folder::

    git clone --depth 1 https://github.com/GreenCappuccino/train_r01_v07 /data/train_r01_v07
    python benchmarks/datasets.py --unipen /data/train_r01_v07

Run: ``python benchmarks/datasets.py --unipen PATH [--seeds 0 1 2] [--quick]
[--datasets lasa unipen unipen-writers] [--config C] [--jobs 2] [--reuse lasa]``.
``--quick``: seed 0 only. ``--reuse D``: D's cached rows even if other code
made them (marked ``"reused": true``).
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import json
import os
import platform
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "datasets.json"
CACHE = HERE / "results" / "datasets"
DATASETS = ("lasa", "unipen", "unipen-writers")


def write_sample_files(samples, out: Path, *, times: bool = False) -> None:
    """Write UNIPEN samples as ``out/<label>/<writer>/<n>.csv``: ``x, y`` as the reader gives
    them, and with ``times`` a ``t`` column (s) first where the file gives a sampling rate."""
    import numpy as np

    counter: dict[tuple[str, str], int] = {}
    for s in samples:
        writer = s.writer.replace("/", "-")
        n = counter.setdefault((s.label, writer), 0)
        counter[(s.label, writer)] += 1
        path = out / s.label / writer / f"{n}.csv"
        path.parent.mkdir(parents=True, exist_ok=True)
        pos = np.concatenate(s.strokes)
        if times and s.points_per_second:
            t = np.arange(len(pos)) / s.points_per_second
            np.savetxt(path, np.column_stack([t, pos]), delimiter=",", header="t,x,y",
                       comments="", fmt="%.6g")
        else:
            np.savetxt(path, pos, delimiter=",", header="x,y", comments="", fmt="%.6g")


def export_unipen(root: str, out: Path, *, seed: int = 0) -> dict:
    """Write the benchmark's UNIPEN digits as ``out/<digit>/<writer>/<n>.csv`` (x, y).

    Positions as the reader gives them (mm where the file says its
    resolution, else tablet units; scale differs between contributors,
    which every method but ``dtw_raw`` normalises away); no time column,
    since not every contributor gives a sampling rate. A drawing the release
    stores twice is exported once (:func:`iloci.data.unipen.read_unipen`
    keeps its first copy). An earlier export in ``out`` (one with a
    ``SOURCE.json``) of other samples is removed first, so no stale file
    stays beside the new ones. The sub-folder is the writer (the person,
    ``UnipenSample.writer``); ``SOURCE.json``'s ``writer_ids`` lists the
    ids the files give each one (IBM's session ids).
    """
    import shutil

    from iloci.data.unipen import balanced_subset, samples_checksum, unipen_digits

    samples = balanced_subset(unipen_digits(root), per=1, seed=seed)
    digest = samples_checksum(samples)
    stamp = out / "SOURCE.json"
    if stamp.is_file() and json.loads(stamp.read_text()).get("checksum") == digest:
        return json.loads(stamp.read_text())
    if stamp.is_file():
        for old in out.iterdir():
            if old.is_dir():
                shutil.rmtree(old)
    write_sample_files(samples, out)
    info = {"source": str(root), "samples": len(samples),
            "writers": len({s.writer for s in samples}), "checksum": digest,
            "writer_ids": {w.replace("/", "-"): sorted({s.writer_id for s in samples
                                                        if s.writer == w})
                           for w in sorted({s.writer for s in samples})},
            "selection": "balanced_subset(unipen_digits(root), per=1, seed=0)"}
    stamp.write_text(json.dumps(info, indent=1))
    return info


@functools.cache
def _code_hash() -> str:
    """SHA-256 of the kernel's and the plugins' Python sources: a cached result of other code
    is not reused. Taken once, when the run starts (the code it imported)."""
    h = hashlib.sha256()
    for top in ("iloci", "plugins"):
        for f in sorted((HERE.parent / top).rglob("*.py")):
            h.update(f.relative_to(HERE.parent).as_posix().encode() + b"\0" + f.read_bytes())
    return h.hexdigest()


def _key(config_dict: dict, extra: str) -> str:
    blob = json.dumps(config_dict, sort_keys=True) + extra + _code_hash()
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def run_one(name: str, seed: int, config, jobs: int, unipen_dir: Path | None,
            fresh: bool, reuse: bool = False) -> dict:
    """One data set at one seed: cached result, or evaluate() now.

    ``reuse``: take the cached row even if other code made it (its key
    differs), marked ``"reused": true``; for rows whose data and code path
    did not change (``--reuse lasa`` after a change to the UNIPEN reader).
    """
    from iloci.evaluation.evaluate import evaluate

    changes: dict = {"evaluation": {"seed": seed}}
    if name.startswith("unipen"):
        changes["data"] = {"path": str(unipen_dir)}
        changes["evaluation"]["split"] = "writers" if name == "unipen-writers" else "concepts"
    cfg = config.replace(**changes)
    stamp = ""
    if unipen_dir is not None and name.startswith("unipen"):
        stamp = json.loads((unipen_dir / "SOURCE.json").read_text())["checksum"]
    cache = CACHE / f"{name}-seed{seed}.json"
    key = _key(cfg.to_dict(), stamp)
    if cache.is_file() and not fresh:
        got = json.loads(cache.read_text())
        if got.get("cache_key") == key:
            print(f"{name} seed {seed}: cached ({cache.relative_to(HERE)})", file=sys.stderr)
            return got
        if reuse:
            print(f"{name} seed {seed}: reused from the cache, made by other code "
                  f"({cache.relative_to(HERE)})", file=sys.stderr)
            return {**got, "reused": True}
    print(f"{name} seed {seed}: running", file=sys.stderr)
    t0 = time.perf_counter()
    metrics, _ = evaluate(cfg, jobs=jobs)
    wall = time.perf_counter() - t0
    baselines = {b: {k: v[k] for k in ("method", "ccr_mean", "ccr_std", "ccr_folds")}
                 for b, v in metrics["baselines"].items()}
    best = max(baselines, key=lambda b: baselines[b]["ccr_mean"])
    row = {
        "dataset": name, "seed": seed, "cache_key": key,
        "data": metrics.get("dataset", {"name": "LASA", "samples": 182}),
        "split": cfg.evaluation.split, "folds": cfg.evaluation.folds,
        "iloci": {"ccr_mean": metrics["ccr_mean"], "ccr_std": metrics["ccr_std"],
                  "ccr_folds": metrics["ccr_folds"],
                  "concepts": metrics["concepts"]["mean"],
                  "purity": metrics["purity"]["mean"],
                  "interactions_per_demo": metrics["interactions_per_demo"]["mean"]},
        "baselines": baselines,
        "best_baseline": best,
        "iloci_reaches_best": metrics["ccr_mean"] >= baselines[best]["ccr_mean"],
        "wall_seconds": wall,
    }
    CACHE.mkdir(parents=True, exist_ok=True)
    cache.write_text(json.dumps(row, indent=1))
    return row


def table(rows: list[dict]) -> list[str]:
    """Markdown: one line per data set and seed, iloci and each baseline (CCR %)."""
    names = list(rows[0]["baselines"]) if rows else []
    out = ["| data set | seed | iloci | " + " | ".join(names) + " |",
           "|---|---|---|" + "---|" * len(names)]
    for r in rows:
        cells = [f"{100 * r['baselines'][b]['ccr_mean']:.2f}" for b in names]
        out.append(f"| {r['dataset']} | {r['seed']} | {100 * r['iloci']['ccr_mean']:.2f} | "
                   + " | ".join(cells) + " |")
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--unipen", metavar="PATH",
                    help="the train_r01_v07 folder (git clone; see the module docstring)")
    ap.add_argument("--datasets", nargs="+", choices=DATASETS, default=list(DATASETS))
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--quick", action="store_true", help="seed 0 only")
    ap.add_argument("--config", "-c", help="TOML config (default: the paper's settings)")
    ap.add_argument("--jobs", "-j", type=int, default=2, help="folds in parallel (default 2)")
    ap.add_argument("--fresh", action="store_true", help="ignore cached results")
    ap.add_argument("--reuse", nargs="+", choices=DATASETS, default=[],
                    help="take these data sets' cached rows even if other code made them "
                    "(marked reused in the JSON)")
    ap.add_argument("--export", metavar="DIR", default=None,
                    help="where the UNIPEN digits are exported as CSV files "
                    "(default: $ILOCI_CACHE_DIR or ~/.cache/iloci, /unipen-digits)")
    args = ap.parse_args(argv)

    from iloci.config import load_config

    config = load_config(args.config)
    _code_hash()
    seeds = [0] if args.quick else args.seeds
    wanted = list(args.datasets)
    unipen_dir = None
    unipen_info = None
    if any(d.startswith("unipen") for d in wanted):
        if not args.unipen:
            ap.error("--unipen PATH is needed for the UNIPEN data sets (or --datasets lasa)")
        cache_root = os.environ.get("ILOCI_CACHE_DIR") or os.path.join(
            os.path.expanduser("~"), ".cache", "iloci")
        unipen_dir = Path(args.export or Path(cache_root) / "unipen-digits")
        unipen_info = export_unipen(args.unipen, unipen_dir)
    load_before = os.getloadavg()
    # seed by seed, so an interrupted run has every data set at the first seeds
    done = {(d, s): run_one(d, s, config, args.jobs, unipen_dir, args.fresh,
                            reuse=d in args.reuse)
            for s in seeds for d in wanted}
    rows = [done[(d, s)] for d in wanted for s in seeds]
    out = {
        "command": "python benchmarks/datasets.py " + " ".join(argv or sys.argv[1:]),
        "back_ends": {k: getattr(config, k).name for k in
                      ("perceptual_model", "clusterer", "teacher", "ik", "simulator")},
        "unipen": unipen_info,
        "unipen_citation": ("Guyon et al. 1994, doi:10.1109/ICPR.1994.576870; data "
                            "doi:10.5281/zenodo.1195803 (CC BY 4.0)"),
        "seeds": seeds, "quick": args.quick,
        "rows": rows,
        "table": table(rows),
        "targets": {
            "iloci >= best baseline on every data set and seed":
                all(r["iloci_reaches_best"] for r in rows),
        },
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                    "load_before": load_before, "load_after": os.getloadavg()},
    }
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {RESULTS}", file=sys.stderr)
    print("\n".join(out["table"]))
    return out


if __name__ == "__main__":
    main()
