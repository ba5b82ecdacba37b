"""Learner benchmark: one evaluation-sized fold of ILoCI (learning + batched inference).

The fold is the evaluation's (:func:`iloci.evaluation.folds.lasa_folds`, 36
or 37 learning demonstrations of 182), shown one at a time in a seeded
random order to an oracle teacher; the rest is recognized in one batch.
Writes ``benchmarks/results/learner.json``::

    backend, epochs, extra   the settings: ``epochs`` is ``[learner]
                             rehearsal_epochs`` (the first training of the
                             fresh network uses the model's ``epochs``)
    learn_demos, test_demos  36 or 37, and the other 145 or 146
    learn_seconds            wall time of the learning phase (with rehearsals)
    rehearsals               count, total and max seconds, by reason
    interactions             teacher feedbacks given
    recognize_seconds        wall time of the batched inference phase
    ccr                      correct classification rate on the test set, a
                             robot concept named by the majority true
                             concept of its entries' demonstrations
    first_guess_rate         fraction of learning demonstrations (after the
                             first) whose first guess was rewarded
    entries, prototypes      memory size at the end

Target (issue 5): the full 5-fold evaluation in <= 3 minutes on 2 cores,
i.e. one fold's learning + inference in about 36 s (72 s with 2 folds in
parallel).

Run: ``python benchmarks/learner.py [--backend jax-rnnpb|torch-rnnpb]
[--epochs N] [--fold K] [--seed S] [--set perceptual_model.learning_rate=0.001]``
(``--all`` runs every fold).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results" / "learner.json"


def fold(demos, k: int, seed: int):
    """Fold ``k`` of :func:`iloci.evaluation.folds.lasa_folds`: (learning demos in a
    seeded random order, test demos)."""
    from iloci.evaluation.folds import lasa_folds

    learn_idx, test_idx = lasa_folds(demos, 5, seed)[k]
    order = np.random.default_rng([seed, k]).permutation(len(learn_idx))
    return [demos[learn_idx[i]] for i in order], [demos[i] for i in test_idx]


def run_fold(backend: str, epochs: int, fold_index: int, seed: int, extra: dict) -> dict:
    import iloci
    from iloci.data import load_lasa

    demos = load_lasa()
    learn, test = fold(demos, fold_index, seed)
    cfg = {"perceptual_model": {"name": backend, **extra.get("model", {})},
           "learner": {"rehearsal_epochs": epochs, **extra.get("learner", {})},
           "evaluation": {"seed": seed}}
    agent = iloci.build(cfg)
    t0 = time.perf_counter()
    report = agent.teach(learn)
    learn_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    answers = agent.recognize(test)
    rec_s = time.perf_counter() - t0
    from iloci.data.concepts import majority_names
    names = majority_names(agent.memory.concept_members(agent.teacher.concept_of_key))
    ccr = float(np.mean([names[a.concept] == d.true_concept for a, d in zip(answers, test)]))
    reh = report.rehearsals
    by_reason: dict[str, int] = {}
    for r in reh:
        by_reason[r.reason] = by_reason.get(r.reason, 0) + 1
    firsts = [f for f in report.first_guess_correct if f is not None]
    return {
        "backend": backend, "epochs": epochs, "fold": fold_index, "seed": seed, "extra": extra,
        "learn_demos": len(learn), "test_demos": len(test),
        "learn_seconds": round(learn_s, 2), "recognize_seconds": round(rec_s, 2),
        "rehearsals": {"count": len(reh), "seconds": round(sum(r.seconds for r in reh), 2),
                       "max_seconds": round(max((r.seconds for r in reh), default=0), 2),
                       "by_reason": by_reason,
                       "final_loss": reh[-1].loss if reh else None},
        "interactions": len(report.feedbacks),
        "rewarded": int(sum(f == 1 for f in report.feedbacks)),
        "first_guess_rate": float(np.mean(firsts)) if firsts else None,
        "ccr": ccr,
        "mean_confidence_correct": float(np.mean(
            [a.confidence for a, d in zip(answers, test) if names[a.concept] == d.true_concept]
            or [np.nan])),
        "entries": len(agent.memory),
        "prototypes": int(sum(e.prototype for e in agent.memory.entries)),
        "concepts": len(agent.memory.concepts()),
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--backend", default="jax-rnnpb")
    p.add_argument("--epochs", type=int, default=300)
    p.add_argument("--fold", type=int, default=0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--all", action="store_true", help="run all 5 folds")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="extra config value, e.g. perceptual_model.learning_rate=0.001 "
                        "(repeatable)")
    p.add_argument("--out", default=str(RESULTS))
    args = p.parse_args(argv)
    folds = range(5) if args.all else [args.fold]
    runs = []
    t0 = time.perf_counter()
    extra: dict = {}
    for item in args.set:
        key, _, value = item.partition("=")
        section, _, name = key.partition(".")
        section = {"perceptual_model": "model"}.get(section, section)
        extra.setdefault(section, {})[name] = json.loads(value)
    for k in folds:
        r = run_fold(args.backend, args.epochs, k, args.seed, extra)
        print(json.dumps(r), flush=True)
        runs.append(r)
    total = time.perf_counter() - t0
    out = {"command": " ".join([Path(sys.executable).name, *sys.argv]),
           "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                       "python": platform.python_version()},
           "total_seconds": round(total, 1),
           "ccr_mean": float(np.mean([r["ccr"] for r in runs])),
           "ccr_std": float(np.std([r["ccr"] for r in runs])),
           "runs": runs}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")
    print(f"total {total:.1f} s, CCR {out['ccr_mean']:.3f} +- {out['ccr_std']:.3f}; "
          f"written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
