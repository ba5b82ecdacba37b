"""Large learning sets: ``iloci evaluate --data`` per config variant, iloci beside the baselines.

On a learning set of 192 UNIPEN letters (960 letters, fold 0) the memory's
network lost what it held over the learning phase (mean generation error
0.10, CCR 37.8 % against normalised DTW's 89.7 %): every rehearsal
restarted Adam at the first training's learning rate from the trained
weights (docs/method.md, "The rehearsal learning rate"). This benchmark
runs ``iloci evaluate`` on such a data set once per variant (a set of
config overrides on the defaults) and seed, each in a process of its own,
and keeps what tells a collapse from a working memory: per fold iloci's
CCR, the memory's entries, prototypes and mean generation error, its
rehearsals, and the baselines on the same folds in the same run
(normalised DTW 1-NN, the $1 recognizer, raw DTW).

Writes ``benchmarks/results/large_sets.json`` (``--out``)::

    data            the data set's name, size, checksum (as metrics.json has it)
    variants        name -> the config overrides it applies to the defaults
    runs            one record per (variant, seed): the command, iloci's CCR,
                    per fold ccr, entries, prototypes, exemplars,
                    generation_error, rehearsals, rehearsal_seconds,
                    wall_seconds and the baselines' CCR; evaluation wall
    git_head, load_average (before and after), cpu_count, python, platform

A run directory (``--runs``/VARIANT-seedS) that already holds a
``metrics.json`` of the same data set, folds and config is read, not run
again (``--fresh`` runs it again), so an interrupted benchmark resumes;
``--reuse NAME=DIR`` reads a variant's run from an ``iloci evaluate --out``
directory made elsewhere (marked ``reused`` with its directory).

Run: ``python benchmarks/large_sets.py (--data PATH | --unipen PATH) [--folds 0]
[--seeds 0] [--jobs 1] [--variant NAME=SECTION.KEY=VALUE[,...]]... [--runs DIR]``.
Without ``--variant``: the defaults and ``rehearsal-0.005`` (every
rehearsal at the first training's rate, the default before).
``--unipen`` (UNIPEN's ``train_r01_v07`` folder) writes the data set of the
figures in docs/method.md first, to ``--runs``/letters16: 960 single-stroke
UNIPEN letters, the 16 of :data:`LETTERS16`, 6 of each by each of 10 writers
(``condense.export_letters``, the same reader and picking as
benchmarks/condense.py's 8 letters). The figures recorded before this option
existed were measured on a set made alike by a scratch script (the note in
the JSON); its checksum differs.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

# benchmarks/golden.py and rehearsal.py: this folder is on sys.path when run
from golden import git_head
from rehearsal import parse_variant

RESULTS = Path(__file__).resolve().parent / "results" / "large_sets.json"

DEFAULT_VARIANTS: dict[str, dict[str, dict[str, Any]]] = {
    "default": {},
    "rehearsal-0.005": {"perceptual_model": {"rehearsal_learning_rate": 0.005}},
}


def matches(metrics: dict, overrides: dict, data: Path, folds: list[int], seed: int) -> bool:
    """A finished run of this variant: same data set, folds, seed and overridden values."""
    cfg = metrics.get("config", {})
    if (Path(metrics.get("dataset", {}).get("path", "")) != data
            or sorted(f["fold"] for f in metrics.get("folds", [])) != sorted(folds)
            or metrics.get("seed") != seed):
        return False
    return all(cfg.get(sec, {}).get(k) == v for sec, kv in overrides.items()
               for k, v in kv.items())


def run(name: str, overrides: dict, seed: int, args: argparse.Namespace) -> dict:
    import tomli_w

    out = args.reuse.get(name) or args.runs / f"{name}-seed{seed}"
    metrics_path = out / "metrics.json"
    cfg = {sec: dict(kv) for sec, kv in overrides.items()}
    cfg.setdefault("evaluation", {})["seed"] = seed
    with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as f:
        f.write(tomli_w.dumps(cfg))
        config_file = f.name
    cmd = ["iloci", "evaluate", "--config", config_file, "--data", str(args.data),
           "--folds", *map(str, args.folds), "--jobs", str(args.jobs), "--out", str(out),
           "--quiet"]
    reused = False
    if name in args.reuse:          # measured elsewhere (e.g. by the code before a change)
        reused = True
    elif (not args.fresh and metrics_path.exists()
            and matches(json.loads(metrics_path.read_text()), overrides, args.data,
                        args.folds, seed)):
        reused = True
    else:
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "iloci", *cmd[1:]], check=True)
        print(f"{name} seed {seed}: {time.perf_counter() - t0:.0f} s", flush=True)
    os.unlink(config_file)
    m = json.loads(metrics_path.read_text())
    keep = ("ccr", "entries", "prototypes", "exemplars", "generation_error", "rehearsals",
            "rehearsal_seconds", "wall_seconds", "learn", "test", "baselines_ccr")
    rec = {"variant": name, "seed": seed, "reused": reused, "run_dir": str(out),
           "command": shlex.join(cmd[:2] + [f"(config {json.dumps(cfg)})"] + cmd[4:]),
           "ccr": m["ccr_mean"], "wall_seconds": m["wall_seconds"],
           "folds": [{"fold": f["fold"], **{k: f.get(k) for k in keep}} for f in m["folds"]],
           "baselines": {k: v["ccr_mean"] for k, v in m.get("baselines", {}).items()},
           "dataset": m.get("dataset")}
    print(f"{name:24s} seed {seed}: iloci {100 * rec['ccr']:6.2f} %  "
          + "  ".join(f"{k} {100 * v:6.2f} %" for k, v in rec["baselines"].items())
          + "  " + "; ".join(f"fold {f['fold']}: {f['entries']} entries "
                             f"({f['prototypes']} prototypes), GE {f['generation_error']:.4f}"
                             for f in rec["folds"]), flush=True)
    return rec


#: The letters of the large set (the most frequent single-stroke lower-case
#: letters of train_r01_v07 drawn by 10 writers 6 times each).
LETTERS16 = "eoanrslhucdmgwpb"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    given = ap.add_mutually_exclusive_group(required=True)
    given.add_argument("--data", type=Path, help="an `iloci evaluate --data` data set")
    given.add_argument("--unipen", type=Path, metavar="PATH",
                       help="UNIPEN's train_r01_v07 folder: the 960 letters are written "
                            "to --runs/letters16 and run")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--folds", type=int, nargs="+", default=[0])
    ap.add_argument("--jobs", type=int, default=1, help="folds at once, per run")
    ap.add_argument("--variant", action="append", default=[],
                    help="NAME=SECTION.KEY=VALUE[,...] (repeatable); 'default' is always run")
    ap.add_argument("--runs", type=Path, default=Path("runs/large_sets"))
    ap.add_argument("--fresh", action="store_true", help="run again what --runs holds")
    ap.add_argument("--reuse", action="append", default=[], metavar="NAME=DIR",
                    help="read variant NAME's run from DIR (an `iloci evaluate --out` "
                         "directory, e.g. made by other code: say which in --note) "
                         "instead of running it; one seed")
    ap.add_argument("--note", default="", help="free text recorded in the output")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args()
    if args.unipen is not None:
        from condense import export_letters  # this folder's benchmarks/condense.py

        args.data = args.runs / "letters16"
        if not args.data.is_dir():
            written = export_letters(str(args.unipen), args.data, letters=LETTERS16)
            print(f"[large_sets] {written['samples']} letters written to {args.data}",
                  file=sys.stderr, flush=True)
    args.data = args.data.resolve()
    args.reuse = dict((n, Path(d)) for n, _, d in (r.partition("=") for r in args.reuse))
    variants = {"default": {}} if args.variant else dict(DEFAULT_VARIANTS)
    variants.update(parse_variant(v) for v in args.variant)
    load0 = os.getloadavg()
    runs = [run(name, ov, s, args) for s in args.seeds for name, ov in variants.items()]
    result = {"data": runs[0]["dataset"] if runs else None, "variants": variants,
              "folds": args.folds, "seeds": args.seeds, "note": args.note,
              "runs": [{k: v for k, v in r.items() if k != "dataset"} for r in runs],
              "git_head": git_head(), "cpu_count": os.cpu_count(),
              "load_average": [load0, os.getloadavg()],
              "python": sys.version.split()[0], "platform": platform.platform()}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
