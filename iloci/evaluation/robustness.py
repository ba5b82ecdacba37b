"""The robustness suite: a fold's test set recognized again under each perturbation.

The perturbations (time warps, resampling, pen rests, jitter, rotation,
stretch, scale) are :mod:`iloci.evaluation.perturb`'s; each is scored for
iloci and for each baseline of :mod:`iloci.evaluation.baselines` on the same fold
(:func:`robustness_suite`), then over folds (:func:`summarize_robustness`,
``metrics.json``'s ``robustness``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
import time
from typing import Any

import numpy as np

from iloci.data.concepts import GroundTruth
from iloci.evaluation.baselines import run_baselines
from iloci.evaluation.metrics import correct_classification_rate, mean_std
from iloci.evaluation.perturb import perturb, suite

__all__ = ["robustness_suite", "summarize_robustness"]


def robustness_suite(agent: Any, learn: list[Any], test: list[Any], true: list[str],
                     truth: Callable[[str], str] | Mapping[str, str], *, seed: int = 0,
                     baseline: bool = True,
                     names: Sequence[str] | None = None) -> dict[str, dict[str, Any]]:
    """Recognize ``test`` under each perturbation; iloci and the baselines.

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
        Also every baseline of :mod:`iloci.evaluation.baselines`.
    names : sequence of str, optional
        Perturbations to run (default: the whole suite).

    Returns
    -------
    dict
        Name -> ``{"predicted", "ccr", "baseline_predicted", "baseline_ccr",
        "baselines", "seconds"}``: ``baseline_*`` of DTW 1-NN on normalised
        paths (the strongest), ``baselines`` name -> CCR of each.
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
            # dtaidistance: [report], checked first
            runs = run_baselines(learn, shown)
            row["baseline_predicted"] = runs["dtw_normalised"]["predicted"]
            row["baseline_ccr"] = runs["dtw_normalised"]["ccr"]
            row["baselines"] = {name: r["ccr"] for name, r in runs.items()}
        row["seconds"] = time.perf_counter() - t0
        out[p.name] = row
    return out


def summarize_robustness(results: Sequence[dict]) -> dict[str, Any]:
    """metrics.json's ``robustness``: per perturbation, CCR over folds, iloci and the baselines.

    Parameters
    ----------
    results : sequence of dict
        Each fold's :meth:`~iloci.evaluation.results.FoldResult.to_dict`.

    Returns
    -------
    dict
        Each perturbation maps to ``{"group", "label", "ccr_mean", "ccr_std",
        "ccr_folds", "drop"}`` (``drop``: clean CCR minus this one, in CCR
        units, mean over folds) and, when the baselines ran, the same under
        ``"baseline"`` (DTW 1-NN on normalised paths) and under
        ``"baselines"`` (name -> the same, for every baseline).
    """
    out: dict[str, Any] = {}
    names = [p for p in suite() if all(p.name in r["robustness"] for r in results)]
    cleans = ([r["robustness"]["clean"] for r in results]
              if all("clean" in r["robustness"] for r in results) else None)

    def part(values: list[float], clean: list[float] | None) -> dict[str, Any]:
        m, s = mean_std(values)
        got: dict[str, Any] = {"ccr_mean": m, "ccr_std": s, "ccr_folds": values}
        if clean is not None:
            got["drop"] = float(np.mean(np.subtract(clean, values)))
        return got

    for p in names:
        rows = [r["robustness"][p.name] for r in results]
        entry: dict[str, Any] = {"group": p.group, "label": p.label}
        entry.update(part([row["ccr"] for row in rows],
                          [c["ccr"] for c in cleans] if cleans else None))
        if all("baseline_ccr" in row for row in rows):
            entry["baseline"] = part(
                [row["baseline_ccr"] for row in rows],
                [c["baseline_ccr"] for c in cleans] if cleans else None)
        if all(row.get("baselines") for row in rows):
            entry["baselines"] = {
                name: part([row["baselines"][name] for row in rows],
                           [c["baselines"][name] for c in cleans] if cleans else None)
                for name in rows[0]["baselines"]}
        out[p.name] = entry
    return out
