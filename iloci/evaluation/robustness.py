"""The robustness suite: a fold's test set recognized again under each perturbation.

The perturbations (time warps, resampling, pen rests, jitter, rotation,
stretch, scale) are :mod:`iloci.evaluation.perturb`'s; each is scored for
iloci and for the DTW 1-NN baseline on the same fold
(:func:`robustness_suite`), then over folds (:func:`summarize_robustness`,
``metrics.json``'s ``robustness``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
import time
from typing import Any

import numpy as np

from iloci.data.concepts import GroundTruth
from iloci.evaluation.metrics import correct_classification_rate, mean_std
from iloci.evaluation.perturb import perturb, suite

__all__ = ["robustness_suite", "summarize_robustness"]


def robustness_suite(agent: Any, learn: list[Any], test: list[Any], true: list[str],
                     truth: Callable[[str], str] | Mapping[str, str], *, seed: int = 0,
                     baseline: bool = True,
                     names: Sequence[str] | None = None) -> dict[str, dict[str, Any]]:
    """Recognize ``test`` under each perturbation; iloci and DTW 1-NN.

    Parameters
    ----------
    agent : Agent
        Taught; its memory is not changed.
    learn, test : lists of Demonstration
        The fold's learning set (the baseline's references) and test set.
    true : list of str
        True concept of each test demonstration.
    truth : GroundTruth or mapping
        Demonstration key -> true concept, to name what the nearest entry
        stands for (a mapping: the keys it knows, then
        :class:`~iloci.data.concepts.GroundTruth`'s rule).
    seed : int
        Seeds the perturbations' random draws.
    baseline : bool
        Also the DTW 1-NN baseline.
    names : sequence of str, optional
        Perturbations to run (default: the whole suite).

    Returns
    -------
    dict
        Name -> ``{"predicted", "ccr", "baseline_predicted", "baseline_ccr",
        "seconds"}``.
    """
    if isinstance(truth, Mapping):
        known = GroundTruth()
        known.known = dict(truth)
        truth = known
    out: dict[str, dict[str, Any]] = {}
    for p in suite(names):
        t0 = time.perf_counter()
        shown = perturb(test, p, seed)
        predicted = [truth(r.source) for r in agent.recognize(shown)]
        row: dict[str, Any] = {"predicted": predicted,
                               "ccr": correct_classification_rate(true, predicted)}
        if baseline:
            from iloci.evaluation.baseline import dtw_1nn  # dtaidistance: [report], checked first
            row["baseline_predicted"] = dtw_1nn(learn, shown)
            row["baseline_ccr"] = correct_classification_rate(true, row["baseline_predicted"])
        row["seconds"] = time.perf_counter() - t0
        out[p.name] = row
    return out


def summarize_robustness(results: Sequence[dict]) -> dict[str, Any]:
    """metrics.json's ``robustness``: per perturbation, CCR over folds, iloci and DTW.

    Parameters
    ----------
    results : sequence of dict
        Each fold's :meth:`~iloci.evaluation.results.FoldResult.to_dict`.

    Returns
    -------
    dict
        Each perturbation maps to ``{"group", "label", "ccr_mean", "ccr_std",
        "ccr_folds", "drop"}`` (``drop``: clean CCR minus this one, in CCR
        units, mean over folds) and, when the baseline ran, the same under
        ``"baseline"``.
    """
    out: dict[str, Any] = {}
    names = [p for p in suite() if all(p.name in r["robustness"] for r in results)]
    for p in names:
        rows = [r["robustness"][p.name] for r in results]
        entry: dict[str, Any] = {"group": p.group, "label": p.label}
        for key, into in (("ccr", entry), ("baseline_ccr", None)):
            if not all(key in row for row in rows):
                continue
            vals = [row[key] for row in rows]
            m, s = mean_std(vals)
            part = {"ccr_mean": m, "ccr_std": s, "ccr_folds": vals}
            if "clean" in results[0]["robustness"]:
                clean = [r["robustness"]["clean"][key] for r in results]
                part["drop"] = float(np.mean(np.subtract(clean, vals)))
            if into is None:
                entry["baseline"] = part
            else:
                entry.update(part)
        out[p.name] = entry
    return out
