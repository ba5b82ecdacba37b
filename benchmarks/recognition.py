"""Recognition ablation: each decision rule and familiarity on the same learned memories.

Issue 25 (parts 5 and 6): recognition that beats honest baselines by the
method's own means, and "I don't know" on shapes never taught. Per data set
and seed, every fold is taught once with the default config (the oracle
teacher; with the oracle the final memory does not depend on the order of
the robot's guesses, so every decision rule below would learn this same
memory) and saved; its test set is then recognized again under each
``[learner] decision`` (rows of :data:`DECISIONS`), and the baselines of
:mod:`iloci.evaluation.baselines` run on the same folds in the same run.

Familiarity (``Recognition.familiarity`` under each ``[learner]
familiarity``): AUROC between fold 0's known test drawings and drawings of
shapes outside the taught set:

``lasa``
    the 4 ``Multi_Models_*`` files (28 drawings). 16 of them are LASA
    shapes drawn again (:data:`REDRAWN`: Spoon, WShape, JShape_2,
    Trapezoid, Line; each lies within LASA's own spread of one concept:
    its normalised path is nearer to a demonstration of that concept than
    0.066, the largest within-concept nearest-neighbour distance of LASA's
    182 demonstrations but one outlier, heee/0), so the AUROC is given
    over all 28 and over the 12 others.
``unipen``
    UNIPEN lower-case letters (single stroke, ``1c``; 10 per letter,
    seeded) against taught digits; also without the letters a digit is
    commonly written like (:data:`DIGIT_LIKE`).
``lasa`` untaught
    LASA concepts never taught: each fold learned again with
    ``[evaluation] untaught = 4`` (the concepts of quality.json's
    ``untaught`` row); its taught test drawings against the untaught
    concepts' drawings, pooled over the 5 folds; also the share of each
    answered "unknown" at familiarity 0.8 (the threshold of ``iloci teach``
    and ``iloci serve``).

Writes ``benchmarks/results/recognition.json``: per data set and seed,
CCR (mean, per fold) of each decision rule and each baseline, and the
familiarity AUROCs; ``ablation``, each row's mean over seeds beside the best
baseline. The robustness suite of each rule is measured by
``benchmarks/robustness.py`` (``--set learner.decision="..."``).

Run: ``python benchmarks/recognition.py [--unipen PATH] [--seeds 0 1 2]
[--unipen-seeds 0] [--datasets lasa unipen unipen-writers] [--rows a,b] [--jobs 2]
[--no-untaught]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "recognition.json"
DATASETS = ("lasa", "unipen", "unipen-writers")

#: row -> ``[learner]`` changes recognized with (on the same memories).
#: The ``regeneration-*`` rows are the ablation of the default's comparison
#: (``compare = "both-distances"``, ``warp = 8``, no tilt search): what
#: each of its changes does.
DECISIONS: dict[str, dict[str, Any]] = {
    "pb_distance": {"decision": "pb_distance"},          # the paper
    "regeneration": {"decision": "regeneration"},        # the default
    # the default before this change: RMS-weighed halves, tilts searched past a PB distance
    "regeneration-before": {"decision": "regeneration", "compare": "both",
                            "tilts": [8.0, 16.0], "tilt_gate": "pb_distance"},
    "regeneration-both-features": {"decision": "regeneration", "compare": "both"},
    "regeneration-tilts-pb-gate": {"decision": "regeneration", "tilts": [8.0, 16.0],
                                   "tilt_gate": "pb_distance"},
    "regeneration-tilts": {"decision": "regeneration", "tilts": [8.0, 16.0]},
    "regeneration-displacements": {"decision": "regeneration", "compare": "displacements",
                                   "warp": 0},           # the default until issue 25 part 5
    "regeneration-displacements-warp-8": {"decision": "regeneration",
                                          "compare": "displacements", "warp": 8},
    "regeneration-both-distances-no-warp": {"decision": "regeneration", "warp": 0},
    "regeneration-positions": {"decision": "regeneration", "compare": "positions"},
    "reproduction": {"decision": "reproduction"},
}
#: Rows run unless ``--rows`` says otherwise (the others cost more time).
DEFAULT_ROWS = ("regeneration", "regeneration-before", "regeneration-both-features",
                "regeneration-tilts-pb-gate", "regeneration-tilts")
#: ``[learner] familiarity`` settings compared (``unknown_below`` is set
#: just above 0 so that the reproduction errors are computed; its answers
#: are not scored here).
FAMILIARITIES = ("path", "reproduction", "prediction", "regeneration")
#: ``unknown_below`` of ``iloci teach`` / ``iloci serve`` (iloci.commands.teach.PAGE).
UNKNOWN_BELOW = 0.8

#: Multi_Models drawings that are LASA shapes drawn again (module docstring).
REDRAWN = frozenset({"Multi_Models_1/5", *(f"Multi_Models_2/{i}" for i in range(4)),
                     *(f"Multi_Models_3/{i}" for i in range(4)),
                     *(f"Multi_Models_4/{i}" for i in range(7))})
#: Lower-case letters commonly written like a digit (o 0, l i 1, z 2, s 5,
#: b 6, g q 9).
DIGIT_LIKE = frozenset("olizsbgq")


def _config(dataset: str, seed: int, data_dir: Path | None):
    from iloci.config import load_config
    changes: dict[str, Any] = {"evaluation": {"seed": seed}}
    if dataset.startswith("unipen"):
        changes["data"] = {"path": str(data_dir)}
        changes["evaluation"]["split"] = ("writers" if dataset == "unipen-writers"
                                          else "concepts")
    return load_config(changes)


def _agent(path: Path, learner: dict[str, Any]):
    from iloci.agent import Agent
    cfg = Agent.load(path).config.to_dict()
    cfg["learner"].update(learner)
    return Agent.load(path, config=cfg)


def _ccr(agent, test, truth) -> tuple[float, list]:
    from iloci.data.concepts import majority_names
    names = majority_names(agent.memory.concept_members(truth))
    recs = agent.recognize(list(test))
    predicted = [names.get(r.concept) or r.concept for r in recs]
    return float(np.mean([p == truth.of(d) for p, d in zip(predicted, test)])), recs


def _familiarity(path: Path, known, outside) -> dict[str, list[float]]:
    out = {}
    for fam in FAMILIARITIES:
        a = _agent(path, {"familiarity": fam, "unknown_below": 1e-9})
        recs = a.recognize(list(known) + list(outside))
        out[fam] = [float(r.familiarity) for r in recs]
    return out


def _auroc(known: list[float], outside: list[float]) -> float:
    from iloci.evaluation.metrics import auroc
    return float(auroc(known, outside))


def run_one(dataset: str, seed: int, jobs: int, data_dir: Path | None, root: Path,
            letters: list | None, rows_run: tuple[str, ...] = DEFAULT_ROWS,
            familiarity_on: bool = True, untaught: bool = True) -> dict[str, Any]:
    from iloci.data.concepts import GroundTruth
    from iloci.evaluation.evaluate import evaluate

    config = _config(dataset, seed, data_dir)
    memories = root / f"{dataset}-seed{seed}"
    t0 = time.perf_counter()
    metrics, results = evaluate(config, jobs=jobs, memory_dir=str(memories))
    learn_seconds = time.perf_counter() - t0
    if data_dir is not None and dataset.startswith("unipen"):
        from iloci.data.datasets import load_dataset
        demos = load_dataset(config.data.path).demos
    else:
        from iloci.data import load_lasa
        demos = load_lasa()
    by_key = {d.key: d for d in demos}
    rows: dict[str, dict[str, Any]] = {r: {"ccr_folds": [], "seconds": 0.0} for r in rows_run}
    familiarity: dict[str, Any] = {}
    for res in results:
        learn = [by_key[k] for k in res.learn]
        test = [by_key[k] for k in res.test]
        truth = GroundTruth(learn + test)
        path = memories / f"fold-{res.fold}.npz"
        for row in rows_run:
            t1 = time.perf_counter()
            if DECISIONS[row] == {"decision": "regeneration"}:
                # the default on this memory is what evaluate() just scored
                rows[row]["ccr_folds"].append(float(res.ccr))
                rows[row]["from_evaluate"] = True
                continue
            ccr, _ = _ccr(_agent(path, DECISIONS[row]), test, truth)
            rows[row]["ccr_folds"].append(ccr)
            rows[row]["seconds"] += time.perf_counter() - t1
        if familiarity_on and res.fold == 0 and dataset in ("lasa", "unipen"):
            familiarity = _unseen(dataset, path, test, letters)
    if dataset == "lasa" and untaught and familiarity_on:
        familiarity["untaught"] = _untaught(seed, jobs, root, demos)
    for row in rows.values():
        row["ccr_mean"] = float(np.mean(row["ccr_folds"]))
        row["ccr_min"] = float(np.min(row["ccr_folds"]))
    baselines = {b: {k: v[k] for k in ("method", "ccr_mean", "ccr_folds")}
                 for b, v in metrics["baselines"].items()}
    best = max(baselines, key=lambda b: baselines[b]["ccr_mean"])
    return {"dataset": dataset, "seed": seed, "data": metrics.get("dataset"),
            "split": config.evaluation.split,
            "evaluate_ccr": {"ccr_mean": metrics["ccr_mean"], "ccr_folds": metrics["ccr_folds"],
                             "decision": config.learner.decision},
            "decisions": rows, "baselines": baselines, "best_baseline": best,
            "familiarity": familiarity, "learn_and_evaluate_seconds": learn_seconds}


def _unseen(dataset: str, path: Path, test: list, letters: list | None) -> dict[str, Any]:
    """Familiarity AUROCs of fold 0's memory: known test drawings against outside ones."""
    if dataset == "lasa":
        from iloci.data import load_lasa
        from iloci.data.concepts import MULTI_MODEL_SHAPES
        outside = load_lasa(MULTI_MODEL_SHAPES)
        subset = [i for i, d in enumerate(outside) if d.key not in REDRAWN]
        label, sub_label = "multi_models_all", "multi_models_not_redrawn"
    else:
        if not letters:
            return {}
        outside = letters
        subset = [i for i, d in enumerate(outside) if d.shape not in DIGIT_LIKE]
        label, sub_label = "letters_all", "letters_not_digit_like"
    fam = _familiarity(path, test, outside)
    n = len(test)
    out: dict[str, Any] = {"known": n, label: len(outside), sub_label: len(subset)}
    for name, values in fam.items():
        k, o = values[:n], values[n:]
        out[name] = {label: _auroc(k, o), sub_label: _auroc(k, [o[i] for i in subset]),
                     f"known_unknown_below_{UNKNOWN_BELOW}": float(np.mean(
                         np.asarray(k) < UNKNOWN_BELOW)),
                     f"outside_unknown_below_{UNKNOWN_BELOW}": float(np.mean(
                         np.asarray(o) < UNKNOWN_BELOW))}
    return out


def _untaught(seed: int, jobs: int, root: Path, demos: list) -> dict[str, Any]:
    """Familiarity AUROCs, taught test drawings against never-taught LASA concepts (5 folds)."""
    from iloci.evaluation.evaluate import evaluate
    from iloci.config import load_config
    config = load_config({"evaluation": {"seed": seed, "untaught": 4}})
    memories = root / f"lasa-untaught-seed{seed}"
    _, results = evaluate(config, jobs=jobs, memory_dir=str(memories))
    by_key = {d.key: d for d in demos}
    fam: dict[str, tuple[list[float], list[float]]] = {f: ([], []) for f in FAMILIARITIES}
    left_out: list[list[str]] = []
    for res in results:
        test = [by_key[k] for k in res.test]
        taught = list(res.taught)
        left_out.append(sorted({d.true_concept for d, t in zip(test, taught) if not t}))
        for name, values in _familiarity(memories / f"fold-{res.fold}.npz", test, []).items():
            fam[name][0].extend(v for v, t in zip(values, taught) if t)
            fam[name][1].extend(v for v, t in zip(values, taught) if not t)
    out: dict[str, Any] = {"taught": len(fam[FAMILIARITIES[0]][0]),
                           "untaught": len(fam[FAMILIARITIES[0]][1]), "left_out": left_out}
    for name, (k, o) in fam.items():
        out[name] = {"auroc": _auroc(k, o),
                     f"taught_unknown_below_{UNKNOWN_BELOW}": float(np.mean(
                         np.asarray(k) < UNKNOWN_BELOW)),
                     f"untaught_unknown_below_{UNKNOWN_BELOW}": float(np.mean(
                         np.asarray(o) < UNKNOWN_BELOW))}
    return out


def _letters(root: str, seed: int, per: int = 10) -> list:
    """``per`` single-stroke lower-case letters of each letter, drawn at random (seeded)."""
    from iloci.data.unipen import unipen_letters
    samples = unipen_letters(root)
    rng = np.random.default_rng([seed, 25, 6])
    out = []
    for letter in sorted({s.label for s in samples}):
        idx = [i for i, s in enumerate(samples) if s.label == letter]
        for j, i in enumerate(sorted(rng.choice(idx, size=min(per, len(idx)), replace=False))):
            out.append(samples[int(i)].demonstration(j))
    return out


def ablation(runs: list[dict]) -> dict[str, Any]:
    """Per data set: each decision row's and each baseline's CCR, mean over seeds."""
    out: dict[str, Any] = {}
    for ds in dict.fromkeys(r["dataset"] for r in runs):
        rs = [r for r in runs if r["dataset"] == ds]
        rows = list(dict.fromkeys(row for r in rs for row in r["decisions"]))
        # a row measured on some seeds only is averaged over those (``seeds`` names them)
        table = {row: {"ccr_mean": float(np.mean([r["decisions"][row]["ccr_mean"]
                                                  for r in rs if row in r["decisions"]])),
                       "ccr_min_fold": float(min(r["decisions"][row]["ccr_min"]
                                                 for r in rs if row in r["decisions"])),
                       "seeds": {str(r["seed"]): r["decisions"][row]["ccr_mean"]
                                 for r in rs if row in r["decisions"]}}
                 for row in rows}
        base = {b: {"ccr_mean": float(np.mean([r["baselines"][b]["ccr_mean"] for r in rs])),
                    "seeds": {str(r["seed"]): r["baselines"][b]["ccr_mean"] for r in rs}}
                for b in rs[0]["baselines"]}
        best = max(base, key=lambda b: base[b]["ccr_mean"])
        out[ds] = {"decisions": table, "baselines": base, "best_baseline": best,
                   "regeneration_reaches_best_on_every_seed": all(
                       r["decisions"]["regeneration"]["ccr_mean"]
                       >= max(v["ccr_mean"] for v in r["baselines"].values()) for r in rs)}
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--unipen", metavar="PATH", help="the train_r01_v07 folder "
                    "(benchmarks/datasets.py says how to get it)")
    ap.add_argument("--datasets", nargs="+", choices=DATASETS, default=list(DATASETS))
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--unipen-seeds", type=int, nargs="+", default=None,
                    help="seeds for the UNIPEN data sets (default: --seeds)")
    ap.add_argument("--jobs", "-j", type=int, default=2)
    ap.add_argument("--rows", default=",".join(DEFAULT_ROWS),
                    help=f"comma-separated decision rows of {', '.join(DECISIONS)}")
    ap.add_argument("--familiarity-seeds", type=int, nargs="*", default=None,
                    help="seeds whose fold 0 also measures familiarity (default: every seed)")
    ap.add_argument("--runs", default="runs/recognition", help="where fold memories go")
    ap.add_argument("--no-untaught", action="store_true",
                    help="skip the LASA untaught-concepts familiarity (5 more folds learned)")
    ap.add_argument("--out", default=str(RESULTS))
    ap.add_argument("--note", help="free text recorded in the output")
    args = ap.parse_args(argv)

    rows_run = tuple(r.strip() for r in args.rows.split(",") if r.strip())
    if set(rows_run) - set(DECISIONS):
        ap.error(f"unknown rows {sorted(set(rows_run) - set(DECISIONS))}; known: "
                 f"{', '.join(DECISIONS)}")
    sys.path.insert(0, str(HERE))
    data_dir = None
    letters = None
    if any(d.startswith("unipen") for d in args.datasets):
        if not args.unipen:
            ap.error("--unipen PATH is needed for the UNIPEN data sets (or --datasets lasa)")
        from datasets import export_unipen  # benchmarks/datasets.py
        cache_root = os.environ.get("ILOCI_CACHE_DIR") or os.path.join(
            os.path.expanduser("~"), ".cache", "iloci")
        data_dir = Path(cache_root) / "unipen-digits"
        export_unipen(args.unipen, data_dir)
        letters = _letters(args.unipen, 0)
    load_before = os.getloadavg()
    t0 = time.perf_counter()
    runs: list[dict] = []

    def write() -> dict:
        out = {
            "command": "python benchmarks/recognition.py " + " ".join(argv or sys.argv[1:]),
            "decisions": {r: DECISIONS[r] for r in rows_run},
            "familiarities": list(FAMILIARITIES),
            "redrawn_multi_models": sorted(REDRAWN), "digit_like_letters": sorted(DIGIT_LIKE),
            "runs": runs, "ablation": ablation(runs),
            "wall_seconds": time.perf_counter() - t0,
            "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                        "load_before": load_before, "load_after": os.getloadavg()},
        }
        if args.note:
            out["note"] = args.note
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
        return out

    for ds in args.datasets:
        seeds = (args.unipen_seeds or args.seeds) if ds.startswith("unipen") else args.seeds
        for seed in seeds:
            print(f"[recognition] {ds} seed {seed} ...", file=sys.stderr, flush=True)
            fam = args.familiarity_seeds is None or seed in args.familiarity_seeds
            r = run_one(ds, seed, args.jobs, data_dir, Path(args.runs), letters, rows_run, fam,
                        not args.no_untaught)
            runs.append(r)
            print(f"[recognition] {ds} seed {seed}: " + ", ".join(
                f"{row} {100 * v['ccr_mean']:.2f}" for row, v in r["decisions"].items())
                + "; " + ", ".join(f"{b} {100 * v['ccr_mean']:.2f}"
                                   for b, v in r["baselines"].items()),
                file=sys.stderr, flush=True)
            write()  # after every run, so a stopped benchmark keeps what it measured
    out = write()
    print(f"wrote {args.out}", file=sys.stderr)
    return out


if __name__ == "__main__":
    main()
