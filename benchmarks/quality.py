"""Learning-quality benchmark: accuracy, teacher effort, a teacher who errs, "unknown".

Runs the evaluation protocols over several seeds (each seed: its own fold
split, presentation order, network initialisation and noisy-teacher draws)
and writes ``benchmarks/results/quality.json``::

    ccr                 the k-fold CCR with the chosen settings: mean, std over
                        every (seed, fold), per fold ``folds`` (seed -> 5
                        values), per seed; the robot's own labels are scored
    dtw_ccr             the evaluation's ``baseline`` on the same folds: DTW 1-NN on
                        normalised paths (runs made before the baselines module:
                        raw positions; ``baselines_method`` says which)
    baselines           every baseline of iloci.evaluation.baselines on the same
                        folds (seed -> name -> CCR mean over folds), best_baseline
    feedbacks_per_demo  teacher feedbacks per learning demonstration
    stream              test-then-learn: first guess right over
                        demonstrations 46-182, feedbacks per demonstration
    noisy               teacher error p -> CCR, one-to-one CCR, purity,
                        concepts, feedbacks
    unknown_auroc       AUROC of recognition's familiarity between taught and
                        untaught concepts (``[evaluation] untaught = 4``), and
                        the unknown answers' confusion
    ablation            one row per setting: what each change buys
    targets             each target of the issue, the measured value, met or not

Each (row, seed) run is cached in ``--cache`` (a JSON file per run) so an
interrupted benchmark resumes; ``--fresh`` ignores the cache.

Run: ``python benchmarks/quality.py [--seeds 0 1 2] [--jobs 2]
[--rows default,paper,...] [--config base.toml]``. The base config is the
project's default config (``load_config({})``: ``native-rnnpb``, the
default perceptual model, and every other default), so row ``default`` is
exactly what ``iloci evaluate`` runs; ``--config`` gives another base (e.g.
a TOML naming ``torch-rnnpb`` or ``jax-rnnpb``). The back ends are recorded
in the output.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

# benchmarks/golden.py: this folder is on sys.path when run, or imported by golden.py
from golden import git_head

RESULTS = Path(__file__).resolve().parent / "results" / "quality.json"

#: The novelty answer with confirmed rewards and the paper's PB-distance
#: decision: what this issue recommended before a teacher who errs was
#: made robust (rows ``pb-*``). The decision is the PB distance: once
#: recognition's steps ran in the native kernel, ``decision =
#: "reproduction"`` scored below it with the oracle (99.41 against 99.73 %
#: pooled over seeds 0-2) and no better with the noisy teacher at p = 0.1
#: (95.97 against 96.07 %), measured on main 87b65f2 / 6370d09.
BASE: dict[str, Any] = {"learner": {"novelty_below": 0.8, "confirm_rewards": True,
                                    "decision": "pb_distance"}}

#: The settings this issue recommends (``[learner]`` keys), measured here as
#: ``best``: the base above, the novelty answer asked again after 2 refused
#: guesses, rewards that make a new exemplar confirmed, and a reward after
#: the novelty answer asked again was refused confirmed twice. With the
#: noisy teacher at p = 0.1 each raised the CCR on seeds 0-2 (rows
#: ``pb-noisy-0.1``, ``novelty-after-2-noisy-0.1``,
#: ``novelty-after-2-confirm-exemplars-noisy-0.1``, ``noisy-0.1``); with
#: the oracle none changed it (docs/method.md).
BEST: dict[str, Any] = {"learner": {**BASE["learner"], "novelty_after": 2,
                                    "confirm_new_exemplars": True,
                                    "confirm_twice_after_novelty": True}}

#: The paper's learning phase: every setting of this issue off.
PAPER: dict[str, Any] = {"learner": {"novelty_below": 0.0, "unknown_below": 0.0,
                                     "confirm_rewards": False, "decision": "pb_distance"}}


def _with(*parts: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for part in parts:
        for sec, values in part.items():
            out[sec] = {**out.get(sec, {}), **values}
    return out


NOISY_01 = {"teacher": {"name": "noisy", "p": 0.1}}
#: The default decision (``[learner] decision``), for rows built on BASE.
REGENERATION = {"learner": {"decision": "regeneration"}}

#: row name -> changes on top of the base config.
ROWS: dict[str, dict[str, Any]] = {
    "best": BEST,
    "paper": PAPER,
    "untaught": _with(BEST, {"evaluation": {"untaught": 4}, "learner": {"unknown_below": 0.8}}),
    "paper-untaught": _with(PAPER, {"evaluation": {"untaught": 4}}),
    "noisy-0.05": _with(BEST, {"teacher": {"name": "noisy", "p": 0.05}}),
    "noisy-0.1": _with(BEST, NOISY_01),
    "noisy-0.2": _with(BEST, {"teacher": {"name": "noisy", "p": 0.2}}),
    "paper-noisy-0.1": _with(PAPER, NOISY_01),
    "stream": _with(BEST, {"evaluation": {"protocol": "stream"}}),
    "paper-stream": _with(PAPER, {"evaluation": {"protocol": "stream"}}),
    # ablation, each with the oracle (its cost) and the noisy teacher: the
    # base alone, then what each setting of BEST adds to it
    "pb-decision": BASE,
    "pb-noisy-0.1": _with(BASE, NOISY_01),
    "novelty-only": _with(BASE, {"learner": {"confirm_rewards": False}}),
    # the novelty answer's familiarity of the PB_obs error (instead of the
    # best entry's reproduction error, the default)
    "novelty-prediction": _with(BASE, {"learner": {"familiarity": "prediction"}}),
    "reproduction-decision": _with(BASE, {"learner": {"decision": "reproduction"}}),
    "reproduction-only": _with(PAPER, {"learner": {"decision": "reproduction"}}),
    # a reward that makes a new exemplar is confirmed too
    "confirm-exemplars": _with(BASE, {"learner": {"confirm_new_exemplars": True}}),
    "pb-confirm-exemplars-noisy-0.1": _with(BASE, {"learner": {"confirm_new_exemplars": True}},
                                            NOISY_01),
    # the novelty answer asked again after 2 refused guesses
    "novelty-after-2": _with(BASE, {"learner": {"novelty_after": 2}}),
    "novelty-after-2-noisy-0.1": _with(BASE, {"learner": {"novelty_after": 2}}, NOISY_01),
    "novelty-after-2-confirm-exemplars-noisy-0.1": _with(
        BASE, {"learner": {"novelty_after": 2, "confirm_new_exemplars": True}}, NOISY_01),
    # BEST but a reward after the novelty answer asked again is confirmed once
    "confirm-once": _with(BEST, {"learner": {"confirm_twice_after_novelty": False}}),
    # the defaults (decision "regeneration", familiarity "path", the paper's
    # learning phase), with every baseline on the same folds
    "default": {},
    # the rows above with the default decision instead of the PB distance
    "best-regeneration": _with(BEST, REGENERATION),
    "untaught-regeneration": _with(BEST, REGENERATION, {"evaluation": {"untaught": 4},
                                                        "learner": {"unknown_below": 0.8}}),
    "noisy-0.1-regeneration": _with(BEST, REGENERATION, NOISY_01),
    # the untaught row with the familiarity of the previous default
    "untaught-reproduction": _with(BEST, {"evaluation": {"untaught": 4}, "learner": {
        "unknown_below": 0.8, "familiarity": "reproduction"}}),
}

#: Rows whose runs also score every baseline of iloci.evaluation.baselines.
BASELINE_ROWS = ("best", "default")
#: Rows whose untaught concepts are scored for "unknown" (``unknown_auroc``:
#: the first present; every one present in ``unknown_auroc_rows``).
UNTAUGHT_ROWS = ("untaught", "untaught-regeneration", "untaught-reproduction", "paper-untaught")

#: Rows run by default, in order (the cheap, decisive ones first).
DEFAULT_ROWS = ("best", "paper", "noisy-0.1", "untaught", "paper-noisy-0.1", "noisy-0.05",
                "noisy-0.2", "stream", "pb-decision", "pb-noisy-0.1", "confirm-exemplars",
                "pb-confirm-exemplars-noisy-0.1", "novelty-after-2", "novelty-after-2-noisy-0.1",
                "novelty-after-2-confirm-exemplars-noisy-0.1", "confirm-once",
                "novelty-prediction", "novelty-only", "reproduction-decision",
                "reproduction-only", "paper-stream", "default", "best-regeneration",
                "untaught-regeneration", "noisy-0.1-regeneration", "untaught-reproduction")


def _merge(base: dict, changes: dict) -> dict:
    out = json.loads(json.dumps(base))
    for sec, values in changes.items():
        if sec in out and isinstance(values, dict) and "name" in values \
                and values["name"] != out[sec].get("name"):
            out[sec] = dict(values)
        else:
            out.setdefault(sec, {}).update(values)
    return out


def run_one(base: dict, row: str, seed: int, jobs: int, cache: Path, fresh: bool,
            cached_only: bool = False) -> dict | None:
    """One (row, seed) run, from the cache when there (``None``: not cached, not run)."""
    from iloci.config import load_config

    data = _merge(base, ROWS[row])
    data.setdefault("evaluation", {})["seed"] = seed
    # the noisy teacher's draws are seeded by the config's seed
    config = load_config(data)
    key = cache / f"{row}-seed{seed}.json"
    if key.is_file() and not fresh:
        cached = json.loads(key.read_text())
        if cached.get("config") == config.to_dict():
            return cached
        if cached_only:
            # summarising only: a run made by older code (whose config had other
            # keys) is still what ran; it is marked, with the config it ran with
            cached["config_differs_from_current"] = True
            return cached
    if cached_only:
        return None
    t0 = time.perf_counter()
    if config.evaluation.protocol == "stream":
        from iloci.evaluation.stream import run_stream
        metrics, steps = run_stream(config)
        out = {"row": row, "seed": seed, "protocol": "stream", "metrics": metrics,
               "correct": [s["correct"] for s in steps],
               "feedbacks": [len(s["feedbacks"]) for s in steps]}
    else:
        from iloci.evaluation.evaluate import evaluate
        metrics, results = evaluate(config, jobs=jobs, baseline=row in BASELINE_ROWS,
                                    memory_dir=str(cache / f"{row}-seed{seed}-memories"))
        out = {"row": row, "seed": seed, "protocol": "folds", "metrics": {
            k: v for k, v in metrics.items() if k not in ("versions", "machine")},
            "folds": [{k: r[k] for k in (
                "fold", "ccr", "ccr_matched", "ccr_source", "purity", "concepts",
                "named_concepts", "interactions_per_demo", "baseline_ccr", "true_concepts",
                "predicted", "robot_predicted", "taught", "confidence", "distance", "error",
                "reproduction_error", "familiarity", "unknown", "first_guess") if k in r}
                for r in (f.to_dict() for f in results)]}
    out["config"] = config.to_dict()
    out["seconds"] = time.perf_counter() - t0
    out["commit"] = git_head()
    cache.mkdir(parents=True, exist_ok=True)
    key.write_text(json.dumps(out))
    return out


def _folds(runs: list[dict], key: str) -> list[float]:
    return [f.get(key, float("nan")) for r in runs for f in r["folds"]]


def _ms(values: list[float]) -> dict[str, float]:
    a = np.asarray(values, dtype=float)
    a = a[np.isfinite(a)]
    if not a.size:
        return {"mean": None, "std": None, "min": None, "n": 0}
    return {"mean": float(a.mean()), "std": float(a.std()), "min": float(a.min()),
            "n": int(a.size)}


def summarize_folds(runs: list[dict]) -> dict[str, Any]:
    return {
        "ccr": _ms(_folds(runs, "ccr")) | {
            "folds": {str(r["seed"]): [f["ccr"] for f in r["folds"]] for r in runs},
            "seeds": {str(r["seed"]): r["metrics"]["ccr_mean"] for r in runs}},
        "ccr_matched": _ms(_folds(runs, "ccr_matched")),
        "purity": _ms(_folds(runs, "purity")),
        "concepts": _ms(_folds(runs, "concepts")),
        "feedbacks_per_demo": _ms(_folds(runs, "interactions_per_demo")),
        "seeds": [r["seed"] for r in runs],
        "seconds": sum(r["seconds"] for r in runs),
    }


def _unknown_score(f: dict) -> tuple[str, list[float]]:
    """Familiarity when the run recorded it, else the negative prediction error."""
    if f.get("familiarity") and all(np.isfinite(f["familiarity"])):
        return "familiarity", list(f["familiarity"])
    return "-prediction_error", [-e for e in f["error"]]


def summarize_unknown(runs: list[dict]) -> dict[str, Any]:
    from iloci.evaluation.metrics import auroc
    taught, untaught, names, per_seed = [], [], set(), {}
    for r in runs:
        tt, uu = [], []
        for f in r["folds"]:
            name, score = _unknown_score(f)
            names.add(name)
            for t, x in zip(f["taught"], score):
                (tt if t else uu).append(x)
        per_seed[str(r["seed"])] = auroc(tt, uu)
        taught += tt
        untaught += uu
    unknown_t = [u for r in runs for f in r["folds"] for t, u in zip(
        f["taught"], f.get("unknown", [False] * len(f["taught"]))) if t]
    unknown_u = [u for r in runs for f in r["folds"] for t, u in zip(
        f["taught"], f.get("unknown", [False] * len(f["taught"]))) if not t]
    def by(key: str, sign: float) -> float:
        """AUROC of ``sign * f[key]`` pooled over every fold (NaN when not recorded)."""
        pairs = [(t, sign * x) for r in runs for f in r["folds"]
                 for t, x in zip(f["taught"], f.get(key) or [float("nan")] * len(f["taught"]))]
        if not pairs or not all(np.isfinite(x) for _, x in pairs):
            return float("nan")
        return auroc([x for t, x in pairs if t], [x for t, x in pairs if not t])

    return {"auroc": auroc(taught, untaught), "score": sorted(names),
            "auroc_seeds": per_seed,
            "auroc_prediction_error": by("error", -1.0),
            "auroc_reproduction_error": by("reproduction_error", -1.0),
            "auroc_pb_distance": auroc(
                [-d for r in runs for f in r["folds"] for t, d in zip(f["taught"], f["distance"])
                 if t],
                [-d for r in runs for f in r["folds"] for t, d in zip(f["taught"], f["distance"])
                 if not t]),
            "auroc_margin_confidence": auroc(
                [c for r in runs for f in r["folds"] for t, c in zip(f["taught"],
                                                                     f["confidence"]) if t],
                [c for r in runs for f in r["folds"] for t, c in zip(f["taught"],
                                                                     f["confidence"]) if not t]),
            "untaught_answered_unknown": float(np.mean(unknown_u)) if unknown_u else None,
            "taught_answered_unknown": float(np.mean(unknown_t)) if unknown_t else None,
            "taught_demos": len(taught), "untaught_demos": len(untaught),
            "seeds": [r["seed"] for r in runs]}


def summarize_stream(runs: list[dict]) -> dict[str, Any]:
    return {
        "first_guess": _ms([r["metrics"]["first_guess"] for r in runs]),
        "first_guess_seen": _ms([r["metrics"]["first_guess_seen"] for r in runs]),
        "feedbacks_per_demo": _ms([r["metrics"]["feedbacks_per_demo"] for r in runs]),
        "feedbacks_per_demo_late": _ms([r["metrics"]["feedbacks_per_demo_late"]
                                        for r in runs]),
        "concepts": _ms([r["metrics"]["concepts"] for r in runs]),
        "purity": _ms([r["metrics"]["purity"] for r in runs]),
        "curves": {str(r["seed"]): r["metrics"]["curve"] for r in runs},
        "seeds": [r["seed"] for r in runs],
        "seconds": sum(r["seconds"] for r in runs),
    }


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", "-c", help="base TOML config (default: the project's "
                    "default config, native-rnnpb)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--jobs", "-j", type=int, default=2)
    ap.add_argument("--rows", default=",".join(DEFAULT_ROWS),
                    help=f"comma-separated rows of {', '.join(ROWS)}")
    ap.add_argument("--cache", default="runs/quality-cache", help="per-run result cache")
    ap.add_argument("--fresh", action="store_true", help="ignore cached runs")
    ap.add_argument("--cached-only", action="store_true",
                    help="summarise the cached runs only (also those made by older code "
                    "whose config had other keys: marked in the output); run nothing")
    ap.add_argument("--out", default=str(RESULTS))
    ap.add_argument("--keep-previous", action="store_true",
                    help="keep the output file's previous contents under 'previous_run' "
                    "(its rows that this run does not repeat stay readable, marked as "
                    "measured by older code, with the runs before it nested in it; when "
                    "this run repeats every row of the file's latest run, the file's own "
                    "previous_run is kept instead)")
    ap.add_argument("--note", help="free text recorded in the output (e.g. what shared the "
                    "machine, which code the cached runs came from)")
    args = ap.parse_args(argv)

    from iloci.config import load_config
    from iloci.evaluation import figures
    from iloci.evaluation.report import write_json_atomic

    base = (load_config(args.config) if args.config else load_config({})).to_dict()
    rows = [r.strip() for r in args.rows.split(",") if r.strip()]
    unknown = set(rows) - set(ROWS)
    if unknown:
        ap.error(f"unknown rows {sorted(unknown)}; known: {', '.join(ROWS)}")
    cache = Path(args.cache)
    load_before = os.getloadavg()
    t0 = time.perf_counter()
    runs: dict[str, list[dict]] = {}
    for row in rows:
        for seed in args.seeds:
            print(f"[quality] {row} seed {seed} ...", file=sys.stderr, flush=True)
            r = run_one(base, row, seed, args.jobs, cache, args.fresh, args.cached_only)
            if r is None:
                print(f"[quality] {row} seed {seed}: not cached, skipped", file=sys.stderr)
                continue
            runs.setdefault(row, []).append(r)
            m = r["metrics"]
            print(f"[quality] {row} seed {seed}: "
                  + (f"CCR {100 * m['ccr_mean']:.2f} %" if r["protocol"] == "folds"
                     else f"first guess {100 * m['first_guess']:.1f} %")
                  + f" ({r['seconds']:.0f} s)", file=sys.stderr, flush=True)

    out: dict[str, Any] = {
        "command": "python benchmarks/quality.py " + " ".join(argv or sys.argv[1:]),
        "back_ends": {k: base[k]["name"] for k in ("perceptual_model", "clusterer", "teacher",
                                                    "ik", "simulator")},
        "learner": base["learner"],
        "sensorimotor": base["sensorimotor"],
        "seeds": args.seeds,
    }
    rows = [r for r in rows if r in runs]
    out["rows_run"] = {r: [x["seed"] for x in runs[r]] for r in rows}
    out["commits"] = {r: {str(x["seed"]): x.get("commit") for x in runs[r]} for r in rows}
    out["config_differs_from_current"] = {
        r: [x["seed"] for x in runs[r] if x.get("config_differs_from_current")] for r in rows}
    if args.note:
        out["note"] = args.note
    if "best" in runs:
        d = summarize_folds(runs["best"])
        out["ccr"] = d["ccr"] | {"row": "best"}
        out["feedbacks_per_demo"] = d["feedbacks_per_demo"]
        base_runs = [r for r in runs["best"] if all(
            np.isfinite(f["baseline_ccr"]) for f in r["folds"])]
        if base_runs:
            out["dtw_ccr"] = _ms(_folds(base_runs, "baseline_ccr")) | {
                "folds": {str(r["seed"]): [f["baseline_ccr"] for f in r["folds"]]
                          for r in base_runs}}
            out["baselines_method"] = {
                str(r["seed"]): (r["metrics"].get("baseline") or {}).get("method")
                for r in base_runs}
        with_all = [r for r in runs["best"] if r["metrics"].get("baselines")]
        if with_all:
            out["baselines"] = {str(r["seed"]): {n: b["ccr_mean"] for n, b in
                                                 r["metrics"]["baselines"].items()}
                                for r in with_all}
            out["best_baseline"] = {str(r["seed"]): r["metrics"].get("best_baseline")
                                    for r in with_all}
    noisy = {}
    for row in rows:
        # best and noisy-<p> only (not noisy-0.1-regeneration: another decision)
        if re.fullmatch(r"noisy-[0-9.]+", row) or row == "best":
            p = 0.0 if row == "best" else float(row.split("-", 1)[1])
            s = summarize_folds(runs[row])
            noisy[str(p)] = {k: s[k] for k in ("ccr", "ccr_matched", "purity", "concepts",
                                                "feedbacks_per_demo")}
    if len(noisy) > 1:
        out["noisy"] = dict(sorted(noisy.items(), key=lambda kv: float(kv[0])))
        ps = sorted(float(p) for p in noisy)
        fig = Path(args.out).with_name("quality_noisy.png")
        figures.plot_noisy(ps, [_folds(runs["best" if p == 0 else f"noisy-{p:g}"], "ccr")
                                for p in ps],
                           [_folds(runs["best" if p == 0 else f"noisy-{p:g}"],
                                   "interactions_per_demo") for p in ps], fig)
        out["noisy_figure"] = fig.name
    for row in UNTAUGHT_ROWS:
        if row in runs:
            out.setdefault("unknown_auroc", summarize_unknown(runs[row]) | {"row": row})
            out.setdefault("unknown_auroc_rows", {})[row] = summarize_unknown(runs[row]) | {
                "familiarity": runs[row][0]["config"]["learner"].get("familiarity"),
                "decision": runs[row][0]["config"]["learner"].get("decision")}
    if "default" in runs:
        # the defaults against every baseline on the same folds (a seed fixes them)
        with_all = [r for r in runs["default"] if r["metrics"].get("baselines")]
        out["default"] = {
            "ccr": {str(r["seed"]): r["metrics"]["ccr_mean"] for r in runs["default"]},
            "ccr_folds": {str(r["seed"]): [f["ccr"] for f in r["folds"]]
                          for r in runs["default"]},
            "baselines": {str(r["seed"]): {n: b["ccr_mean"] for n, b in
                                           r["metrics"]["baselines"].items()}
                          for r in with_all},
            "best_baseline": {str(r["seed"]): r["metrics"].get("best_baseline")
                              for r in with_all}}
    if "stream" in runs:
        out["stream"] = summarize_stream(runs["stream"])
    out["ablation"] = {}
    for row in rows:
        if runs[row][0]["protocol"] == "stream":
            out["ablation"][row] = {k: v for k, v in summarize_stream(runs[row]).items()
                                    if k != "curves"}
        else:
            out["ablation"][row] = summarize_folds(runs[row])
        out["ablation"][row]["changes"] = ROWS[row]
        learner = runs[row][0]["config"]["learner"]
        out["ablation"][row]["decision"] = learner.get("decision")
        out["ablation"][row]["familiarity"] = learner.get("familiarity")

    targets: dict[str, Any] = {}
    if "ccr" in out:
        targets["ccr_mean_ge_99.3"] = {"value": out["ccr"]["mean"],
                                       "met": out["ccr"]["mean"] >= 0.993}
        targets["every_fold_ge_97.5"] = {"value": out["ccr"]["min"],
                                         "met": out["ccr"]["min"] >= 0.975}
        if "dtw_ccr" in out:
            targets["ccr_ge_dtw"] = {"value": [out["ccr"]["mean"], out["dtw_ccr"]["mean"]],
                                     "met": out["ccr"]["mean"] >= out["dtw_ccr"]["mean"]}
        targets["best_feedbacks_le_3"] = {"value": out["feedbacks_per_demo"]["mean"],
                                          "met": out["feedbacks_per_demo"]["mean"] <= 3.0}
        if "paper" in runs:
            # on the seeds both rows ran
            seeds = {r["seed"] for r in runs["best"]}
            paper_runs = [r for r in runs["paper"] if r["seed"] in seeds]
            if paper_runs:
                paper = summarize_folds(paper_runs)["ccr"]["mean"]
                targets["best_ccr_not_lower"] = {
                    "value": [out["ccr"]["mean"], paper],
                    "seeds": sorted(r["seed"] for r in paper_runs),
                    "met": out["ccr"]["mean"] >= paper}
    if "paper" in runs and "dtw_ccr" in out:
        # the defaults (row paper: every setting of this issue off) against
        # DTW 1-NN on the same folds (a seed fixes the folds), seed by seed
        pap = {r["seed"]: r for r in runs["paper"]}
        dtw = out["dtw_ccr"]["folds"]
        both = sorted(s for s in pap if str(s) in dtw)
        if both:
            folds = [f["ccr"] for s in both for f in pap[s]["folds"]]
            per_seed = {str(s): float(np.mean([f["ccr"] for f in pap[s]["folds"]]))
                        for s in both}
            dtw_seed = {str(s): float(np.mean(dtw[str(s)])) for s in both}
            targets["defaults_ccr_mean_ge_99.3"] = {"value": float(np.mean(folds)),
                                                    "per_seed": per_seed, "seeds": both,
                                                    "met": float(np.mean(folds)) >= 0.993}
            targets["defaults_every_fold_ge_97.5"] = {"value": min(folds), "seeds": both,
                                                      "met": min(folds) >= 0.975}
            targets["defaults_ccr_ge_dtw_every_seed"] = {
                "value": {s: [per_seed[s], dtw_seed[s]] for s in per_seed}, "seeds": both,
                "met": all(per_seed[s] >= dtw_seed[s] for s in per_seed)}
    if "best" in runs and "paper" in runs:
        # the settings of this issue against the paper's protocol on the same
        # seeds (the decision is the same: PB distance)
        nov = {r["seed"]: summarize_folds([r]) for r in runs["best"]}
        pap = {r["seed"]: summarize_folds([r]) for r in runs["paper"]}
        both = sorted(set(nov) & set(pap))
        if both:
            fb = [nov[s]["feedbacks_per_demo"]["mean"] for s in both]
            out["novelty"] = {
                "row": "best", "against": "paper", "seeds": both,
                "feedbacks_per_demo": {str(s): f for s, f in zip(both, fb)},
                "paper_feedbacks_per_demo": {str(s): pap[s]["feedbacks_per_demo"]["mean"]
                                             for s in both},
                "ccr": {str(s): nov[s]["ccr"]["mean"] for s in both},
                "paper_ccr": {str(s): pap[s]["ccr"]["mean"] for s in both}}
            targets["novelty_feedbacks_le_3"] = {
                "value": float(np.mean(fb)), "seeds": both, "met": max(fb) <= 3.0}
            targets["novelty_ccr_not_lower"] = {
                "value": [[nov[s]["ccr"]["mean"], pap[s]["ccr"]["mean"]] for s in both],
                "seeds": both,
                "met": all(nov[s]["ccr"]["mean"] >= pap[s]["ccr"]["mean"] for s in both)}
    if "stream" in out:
        targets["stream_first_guess_ge_85"] = {
            "value": out["stream"]["first_guess"]["mean"], "seeds": out["stream"]["seeds"],
            "met": out["stream"]["first_guess"]["mean"] >= 0.85}
    if "noisy-0.1" in runs:
        s01 = summarize_folds(runs["noisy-0.1"])
        v = s01["ccr"]["mean"]
        targets["noisy_0.1_ccr_ge_96"] = {"value": v, "seeds": s01["seeds"],
                                          "per_seed": s01["ccr"]["seeds"], "met": v >= 0.96}
    if "default" in out and out["default"]["baselines"]:
        d = out["default"]
        both = sorted(d["baselines"])
        targets["default_ccr_ge_best_baseline_every_seed"] = {
            "value": {sd: [d["ccr"][sd], max(d["baselines"][sd].values()),
                           d["best_baseline"][sd]] for sd in both},
            "seeds": both,
            "met": all(d["ccr"][sd] >= max(d["baselines"][sd].values()) for sd in both)}
        targets["default_every_fold_ge_98.5"] = {
            "value": min(min(v) for v in d["ccr_folds"].values()),
            "met": min(min(v) for v in d["ccr_folds"].values()) >= 0.985}
    # the rows of the recommended settings with the default decision, against
    # the best baseline on the same folds (a seed fixes them; the baselines
    # ran in row default or best)
    scored = {str(r["seed"]): r["metrics"]["baselines"] for row in BASELINE_ROWS
              for r in runs.get(row, []) if r["metrics"].get("baselines")}
    for row in ("best-regeneration", "noisy-0.1-regeneration"):
        both = [r for r in runs.get(row, []) if str(r["seed"]) in scored]
        if both:
            value = {str(r["seed"]): [r["metrics"]["ccr_mean"], max(
                b["ccr_mean"] for b in scored[str(r["seed"])].values())] for r in both}
            targets[f"{row}_ccr_ge_best_baseline_every_seed"] = {
                "value": value, "seeds": sorted(r["seed"] for r in both),
                "met": all(a >= b for a, b in value.values())}
    if "noisy-0.1-regeneration" in runs:
        s01 = summarize_folds(runs["noisy-0.1-regeneration"])
        targets["noisy_0.1_regeneration_ccr_ge_96"] = {
            "value": s01["ccr"]["mean"], "seeds": s01["seeds"],
            "per_seed": s01["ccr"]["seeds"], "met": s01["ccr"]["mean"] >= 0.96}
    if "unknown_auroc" in out:
        v = out["unknown_auroc"]["auroc"]
        targets["untaught_auroc_ge_0.95"] = {"value": v, "seeds": out["unknown_auroc"]["seeds"],
                                             "per_seed": out["unknown_auroc"]["auroc_seeds"],
                                             "met": v >= 0.95}
    out["targets"] = targets
    out["wall_seconds"] = time.perf_counter() - t0
    out["machine"] = {"python": platform.python_version(), "platform": platform.platform(),
                      "cpus": os.cpu_count(), "load_average_before": load_before,
                      "load_average_after": os.getloadavg(),
                      "note": "shared with other work; wall times are not comparable"}
    if args.keep_previous and Path(args.out).is_file():
        previous = json.loads(Path(args.out).read_text())
        older = previous.get("previous_run")
        if older is not None and all(r in runs for r in previous.get("ablation", {})):
            # this run repeats every row of the file's latest run: the run
            # before that (whose rows this one may not repeat) is what stays
            previous = older
            previous.pop("rows_not_repeated", None)
        # otherwise the latest run stays whole, its own previous_run in it
        out["previous_run"] = previous | {
            "rows_not_repeated": [r for r in previous.get("ablation", {}) if r not in runs]}
    write_json_atomic(args.out, out)
    for name, t in targets.items():
        print(f"{name}: {t['value']} -> {'met' if t['met'] else 'MISSED'}")
    print(f"wrote {args.out}")
    return out


if __name__ == "__main__":
    main()
