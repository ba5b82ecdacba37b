"""Rehearsal schedule benchmark: CPU seconds and CCR of the evaluation's folds, per config variant.

Each (variant, seed, fold) runs the evaluation's own fold
(:func:`iloci.evaluation.evaluate.fold_plan` and
:func:`~iloci.evaluation.evaluate.run_fold`, without the DTW baseline) in a
process of its own, one thread (``OMP_NUM_THREADS=1``), so its CPU time
(``time.process_time`` around ``run_fold``: learning, rehearsals,
recognition of the test set; not the imports) is that fold's alone, whatever
else the machine runs. CPU time, unlike wall time, can be compared between
variants measured under load; still, run the variants side by side in one
run (tasks are interleaved variant by variant) and compare medians.

Writes ``benchmarks/results/rehearsal.json``::

    variants        name -> the config overrides it applies to the defaults
    runs            one record per (variant, seed, fold): ccr, cpu_seconds,
                    wall_seconds, rehearsals, rehearsal_seconds (wall),
                    generation_error, entries, concepts
    summary         per variant: CCR mean (over every fold of every seed) and
                    per seed, CPU seconds per fold (median, sum)
    cpu_count, load_average (before and after), python, platform

Why: issue 16 asks to cut rehearsal cost (most of the 5-fold CPU time is
rehearsal training for a fixed number of epochs) without losing accuracy.
Fold CCR varies by several points from fold to fold and seed to seed, so a
schedule is judged on every fold of at least two seeds.

Run: ``python benchmarks/rehearsal.py [--seeds 0 1] [--folds 0 1 2 3 4] [--jobs 2]
[--variant NAME=SECTION.KEY=VALUE,...]...`` (without ``--variant``: the
defaults and ``rehearsal_epochs`` 1000 with a 200-epoch warm-up).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results" / "rehearsal.json"

DEFAULT_VARIANTS = {
    "default": {},
    "warmup200_rehearsal1000": {"perceptual_model": {"warmup_epochs": 200},
                                "learner": {"rehearsal_epochs": 1000}},
}


def parse_variant(text: str) -> tuple[str, dict]:
    """``NAME=section.key=value,...`` -> (name, {section: {key: value}}); values as TOML scalars."""
    import tomllib

    name, _, rest = text.partition("=")
    if not name or not rest:
        raise SystemExit(f"--variant {text!r}: expected NAME=SECTION.KEY=VALUE[,...]")
    out: dict[str, dict] = {}
    for item in rest.split(","):
        dotted, _, value = item.partition("=")
        section, _, key = dotted.partition(".")
        if not (section and key and value):
            raise SystemExit(f"--variant {text!r}: bad item {item!r}")
        try:
            out.setdefault(section, {})[key] = tomllib.loads(f"v = {value}")["v"]
        except tomllib.TOMLDecodeError:
            raise SystemExit(f"--variant {text!r}: {value!r} is not a TOML value; quote "
                             f"strings, e.g. --variant '{name}={dotted}=\"{value}\"'") from None
    return name, out


def one_fold(overrides: dict, seed: int, fold: int) -> dict:
    """Run one fold in this process; its record."""
    from iloci.config import load_config
    from iloci.data import load_lasa
    from iloci.evaluation.evaluate import fold_plan, run_fold

    cfg = {k: dict(v) for k, v in overrides.items()}
    cfg.setdefault("evaluation", {})["seed"] = seed
    config = load_config(cfg)
    demos = load_lasa(list(config.data.shapes) or None)
    learn, test = fold_plan(demos, config)[fold]
    t0, w0 = time.process_time(), time.perf_counter()
    res = run_fold(config, fold, [demos[i] for i in learn], [demos[i] for i in test],
                   baseline=False, details=False)
    return {"seed": seed, "fold": fold, "ccr": res.ccr,
            "cpu_seconds": time.process_time() - t0, "wall_seconds": time.perf_counter() - w0,
            "rehearsals": res.rehearsals, "rehearsal_seconds": res.rehearsal_seconds,
            "generation_error": res.generation_error, "entries": res.entries,
            "concepts": res.concepts}


def run_task(name: str, overrides: dict, seed: int, fold: int) -> dict:
    env = dict(os.environ, OMP_NUM_THREADS="1")
    out = subprocess.run([sys.executable, __file__, "--worker", json.dumps(overrides),
                          str(seed), str(fold)], env=env, check=True, capture_output=True,
                         text=True)
    rec = json.loads(out.stdout.strip().splitlines()[-1])
    print(f"{name:28s} seed {seed} fold {fold}: CCR {100 * rec['ccr']:6.2f} %  "
          f"CPU {rec['cpu_seconds']:6.1f} s", flush=True)
    return {"variant": name, **rec}


def summarize(variants: dict, runs: list[dict]) -> dict:
    out = {}
    for name in variants:
        mine = [r for r in runs if r["variant"] == name]
        seeds = sorted({r["seed"] for r in mine})
        out[name] = {
            "ccr_mean": statistics.fmean(r["ccr"] for r in mine),
            "ccr_by_seed": {str(s): statistics.fmean(r["ccr"] for r in mine if r["seed"] == s)
                            for s in seeds},
            "cpu_seconds_median": statistics.median(r["cpu_seconds"] for r in mine),
            "cpu_seconds_sum": sum(r["cpu_seconds"] for r in mine),
            "folds_run": len(mine)}
    return out


def main() -> None:
    if len(sys.argv) == 5 and sys.argv[1] == "--worker":
        print(json.dumps(one_fold(json.loads(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]))))
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--folds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--jobs", type=int, default=2, help="folds run at once (processes)")
    ap.add_argument("--variant", action="append", default=[],
                    help="NAME=SECTION.KEY=VALUE[,...] (repeatable); 'default' is always run")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args()
    variants = {"default": {}} if args.variant else dict(DEFAULT_VARIANTS)
    variants.update(parse_variant(v) for v in args.variant)
    tasks = [(name, ov, s, k) for s in args.seeds for k in args.folds
             for name, ov in variants.items()]
    load0 = os.getloadavg()
    with ThreadPoolExecutor(args.jobs) as pool:
        runs = list(pool.map(lambda t: run_task(*t), tasks))
    result = {"variants": variants, "runs": runs, "summary": summarize(variants, runs),
              "cpu_count": os.cpu_count(), "load_average": [load0, os.getloadavg()],
              "python": sys.version.split()[0], "platform": platform.platform()}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps(result["summary"], indent=1))


if __name__ == "__main__":
    main()
