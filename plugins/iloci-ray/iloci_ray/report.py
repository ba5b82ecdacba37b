"""A sweep's outputs: ``results.csv``, ``report.md`` and figures.

Per setting, each metric is averaged over the folds of each seed, then
given as mean ± std over the seeds (population std, ddof=0, as the
evaluation report does over folds). The best setting has the highest mean
CCR (ties: fewer teacher feedbacks).
"""

from __future__ import annotations

from collections.abc import Sequence
import csv
import io
import json
from pathlib import Path
from typing import Any

import numpy as np

from iloci.data.writes import write_atomic, write_text_atomic
from iloci_ray.sweep import BASELINES_METRIC, RUN_METRICS, SweepSpec

__all__ = ["summarize", "write_report"]


def _label(setting: dict[str, Any]) -> str:
    return ", ".join(f"{k} = {v:g}" if isinstance(v, float) else f"{k} = {v}"
                     for k, v in setting.items())


def summarize(records: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per setting: ``{setting, seeds, runs, <metric>_mean, <metric>_std}``.

    Metrics: :data:`iloci_ray.sweep.RUN_METRICS`; ``feedbacks`` is the
    number of teacher feedbacks (+1 or -1) of a fold's learning phase. When
    every run of a setting has them, ``baselines``: name -> ``{"mean",
    "std"}`` of each baseline's CCR on the same folds, aggregated the same
    way.
    """
    groups: dict[str, list[dict[str, Any]]] = {}
    for r in records:
        groups.setdefault(json.dumps(r["setting"], sort_keys=True), []).append(r)
    rows = []
    for runs in groups.values():
        seeds = sorted({r["seed"] for r in runs})
        row: dict[str, Any] = {"setting": runs[0]["setting"], "seeds": len(seeds),
                               "runs": len(runs)}
        for m in RUN_METRICS:
            per_seed = [float(np.mean([r[m] for r in runs if r["seed"] == s])) for s in seeds]
            row[f"{m}_mean"] = float(np.mean(per_seed))
            row[f"{m}_std"] = float(np.std(per_seed))
        if all(r.get(BASELINES_METRIC) for r in runs):
            row["baselines"] = {}
            for name in runs[0][BASELINES_METRIC]:
                per_seed = [float(np.mean([r[BASELINES_METRIC][name] for r in runs
                                           if r["seed"] == s])) for s in seeds]
                row["baselines"][name] = {"mean": float(np.mean(per_seed)),
                                          "std": float(np.std(per_seed))}
        rows.append(row)
    return rows


def best(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    return max(rows, key=lambda r: (r["ccr_mean"], -r["feedbacks_mean"]))


def write_csv(path: Path, records: Sequence[dict[str, Any]]) -> Path:
    keys = list(records[0]["setting"]) if records else []
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["key", *keys, "seed", "fold", *RUN_METRICS])
    for r in records:
        w.writerow([r["key"], *(r["setting"][k] for k in keys), r["seed"], r["fold"],
                    *(r[m] for m in RUN_METRICS)])
    write_text_atomic(path, buf.getvalue())
    return path


def plot_against(rows: Sequence[dict[str, Any]], key: str, path: Path) -> Path | None:
    """CCR and teacher feedbacks per fold against swept value ``key`` (mean ± std).

    With other keys swept too, one line per value of the others. None when
    ``key``'s values are not numbers (the table gives them).
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not all(isinstance(r["setting"][key], (int, float)) for r in rows):
        return None
    others: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        rest = {k: v for k, v in r["setting"].items() if k != key}
        others.setdefault(_label(rest), []).append(r)
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4))
    for (label, group), marker in zip(others.items(), "osd^v<>ph*"):
        group = sorted(group, key=lambda r: r["setting"][key])
        x = [r["setting"][key] for r in group]
        for ax, m, scale in ((axes[0], "ccr", 100.0), (axes[1], "feedbacks", 1.0)):
            ax.errorbar(x, [scale * r[f"{m}_mean"] for r in group],
                        yerr=[scale * r[f"{m}_std"] for r in group], marker=marker,
                        capsize=3, label=label or None)
    axes[0].set_ylabel("CCR (%)")
    axes[1].set_ylabel("teacher feedbacks per fold")
    for ax in axes:
        ax.set_xlabel(key)
        ax.grid(alpha=0.3)
    if len(others) > 1:
        axes[1].legend(fontsize=7)
    seeds = max(r["seeds"] for r in rows)
    fig.suptitle(f"mean ± std over {seeds} seed(s) (each the mean over its folds)",
                 fontsize=9)
    fig.tight_layout()
    try:  # whole or not at all: a full disk leaves no cut image
        write_atomic(path, lambda fh: fig.savefig(fh, format="png", dpi=110), mkdir=True)
    finally:
        plt.close(fig)
    return path


def _baseline_lines(top: dict[str, Any]) -> list[str]:
    """The baselines on the best setting's folds, and how far its CCR is from the best one."""
    bases = top.get("baselines")
    if not bases:
        return ["Baselines: not run (they need dtaidistance, the `report` extra).", ""]
    name = max(bases, key=lambda n: bases[n]["mean"])
    gap = round(100 * (top["ccr_mean"] - bases[name]["mean"]), 2)
    return ["Baselines on the same folds (iloci.evaluation.baselines; each stores every "
            "learning demonstration with its true concept, no feedback): "
            + ", ".join(f"{n} {100 * b['mean']:.2f} ± {100 * b['std']:.2f} %"
                        for n, b in bases.items())
            + ". The best setting "
            + (f"equals the best baseline ({name})." if gap == 0 else
               f"{'beats' if gap > 0 else 'trails'} the best baseline ({name}) by "
               f"{abs(gap):.2f} points."), ""]


def write_report(out: str | Path, spec: SweepSpec, records: Sequence[dict[str, Any]],
                 info: dict[str, Any]) -> Path:
    """Write results.csv, summary.json, figures/*.png and report.md; return report.md."""
    out = Path(out)
    rows = summarize(records)
    write_csv(out / "results.csv", records)
    top = best(rows)
    write_text_atomic(out / "summary.json", json.dumps(
        {"settings": rows, "best": top, "info": info, "spec": spec.source}, indent=1))
    lines = [f"# Sweep: {spec.source}", "",
             f"{len(rows)} setting(s) ({spec.search} search) x {len(spec.seeds)} seed(s) "
             f"x folds: {info['runs']} runs; {info['computed']} computed now, "
             f"{info['reused']} found stored (not recomputed); wall {info['wall_seconds']:.0f} s"
             f" on Ray ({info['address'] or 'started on this machine'}, "
             f"{info['jobs']} at once).", "",
             *([f"**{len(info['failed'])} run(s) failed** (after {info['retries']} "
                "retries for a worker that died; not in the table below); run the same "
                "command again to resume: " + "; ".join(
                    f"run {f['key']} ({_label(f['setting'])}, seed {f['seed']}, fold "
                    f"{f['fold']}): {f['error']}" for f in info["failed"]), ""]
               if info.get("failed") else []),
             "Each metric: the mean over a seed's folds, then mean ± std over the seeds. "
             "Feedbacks: the teacher's +1/-1 answers in a fold's learning phase (a "
             "demonstration shown before any concept is learned gets none); rewarded: the "
             "share of them that were +1. Rows per run: `results.csv`.", "",
             f"**Best setting** (highest mean CCR): {_label(top['setting'])}: CCR "
             f"{100 * top['ccr_mean']:.2f} ± {100 * top['ccr_std']:.2f} %, "
             f"{top['feedbacks_mean']:.1f} feedbacks per fold.", "",
             *_baseline_lines(top),
             "| setting | CCR (%) | feedbacks per fold | rewarded (%) | entries | concepts "
             "| runs |", "|---|---|---|---|---|---|---|"]
    for r in sorted(rows, key=lambda r: -r["ccr_mean"]):
        lines.append(
            f"| {_label(r['setting'])} | {100 * r['ccr_mean']:.2f} ± {100 * r['ccr_std']:.2f}"
            f" | {r['feedbacks_mean']:.1f} ± {r['feedbacks_std']:.1f}"
            f" | {100 * r['rewarded_mean']:.1f} ± {100 * r['rewarded_std']:.1f}"
            f" | {r['entries_mean']:.1f} | {r['concepts_mean']:.1f} | {r['runs']} |")
    lines.append("")
    for key in spec.values:
        safe = key.replace(".", "-")
        fig = plot_against(rows, key, out / "figures" / f"{safe}.png")
        if fig is not None:
            lines += [f"## Against `{key}`", "", f"![CCR and feedbacks against {key}]"
                      f"(figures/{safe}.png)", ""]
    path = out / "report.md"  # \xNN for bytes of a file name that are not UTF-8
    write_text_atomic(path, "\n".join(lines))
    return path
