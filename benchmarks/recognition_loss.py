"""Where recognition loses points: network fit, memory condensation, distance, tilt search.

Issue 25 (iloci at or above the best baseline on every seed and split).
Per data set and seed, every fold is taught with the default config (the
oracle teacher; ``iloci evaluate --memories``, or the fold memories an
earlier run of this script saved) and its test drawings are answered
five ways, with the default's distance throughout
(:func:`~iloci.concepts.inference.pattern_distances` with ``[learner] warp``
and ``compare``; each drawing encoded by the fold's own encoder):

``iloci``
    the default recognition (:meth:`Agent.recognize <iloci.agent.Agent.recognize>`):
    nearest *regenerated pattern* of the memory's entries (what the network
    performs from each entry's PB and initialInfo).
``kept``
    nearest of the same entries' *kept demonstrations* (``Entry.pattern``, the
    encoded drawing each entry was learned from, a prototype's medoid's):
    what a network that regenerates every entry exactly would answer. Not a
    recognition iloci offers (comparing with stored raw demonstrations is
    the baselines' way), a measurement of the network's fit:
    ``iloci - kept`` is what the fit costs (or gains).
``all_taught``
    nearest of *every* taught drawing, encoded: what the memory would answer
    if clustering and exemplar placement kept every drawing;
    ``kept - all_taught`` is what the condensation costs.
``dtw_normalised``
    the strongest baseline, DTW 1-NN on normalised paths
    (:func:`iloci.evaluation.baselines.dtw_normalised_1nn`), on the same folds;
    ``all_taught - dtw_normalised`` is what the robot's own reading and
    distance cost against it (the network and the memory left out).
``tilts``
    the default with the tilt search switched on (``tilts = [8, 16]``,
    ``tilt_gate = "ranking"``): the answers it turns, changes, makes wrong
    and makes right.

``variants``
    the nearest regenerated pattern (and, beside it, the nearest kept
    demonstration) under each other comparison of :data:`VARIANTS`.

Also the memory: entries, prototypes, exemplars, taught drawings (per
concept), mean generation error, and how far each entry's regenerated
pattern lies from its kept demonstration, as a share of the memory's own
between-concept scale (:func:`~iloci.concepts.inference.regeneration_scale`).

Writes ``benchmarks/results/recognition_loss.json`` (``--out``): per data set
and seed, the correct answers per fold of each way and their CCR, the
counts above, and the totals.

Run: ``python benchmarks/recognition_loss.py --unipen PATH [--datasets unipen
unipen-writers lasa] [--seeds 0] [--memories DIR] [--jobs 1]``; fold memories
are saved to (or, when present, read from) ``DIR/<data set>-seed<seed>/fold-K.npz``.
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
RESULTS = HERE / "results" / "recognition_loss.json"
DATASETS = ("unipen", "unipen-writers", "lasa")
#: The tilt search measured (recognition.py's ``regeneration-tilts`` row).
TILTS: dict[str, Any] = {"tilts": [8.0, 16.0], "tilt_gate": "ranking"}
WAYS = ("iloci", "kept", "all_taught", "dtw_normalised")
#: Other comparisons of a drawing with the memory's patterns, recognition only:
#: name -> (features of an encoded sequence, ``warp``, ``compare`` of
#: :func:`~iloci.concepts.inference.pattern_distances`). ``"pen"``: the pen's
#: two features (``dy, dz``) alone; ``"pen_path"``: its path centred and scaled
#: to unit RMS radius (:func:`~iloci.concepts.inference.pen_path`);
#: ``"pen_path_steps"``: that path beside its steps, scaled alike.
VARIANTS: dict[str, tuple[str, int, str]] = {
    "default": ("all", 8, "both-distances"),
    "both-distances-warp-16": ("all", 16, "both-distances"),
    "both-distances-full-band": ("all", 10_000, "both-distances"),
    "both-warp-8": ("all", 8, "both"),
    "positions-warp-8": ("all", 8, "positions"),
    "positions-warp-16": ("all", 16, "positions"),
    "pen-both-distances-warp-8": ("pen", 8, "both-distances"),
    "pen-path-warp-8": ("pen_path", 8, "displacements"),
    "pen-path-warp-16": ("pen_path", 16, "displacements"),
    "pen-path-full-band": ("pen_path", 10_000, "displacements"),
    "pen-path-and-steps-warp-8": ("pen_path_steps", 8, "displacements"),
}


def _features(seq: np.ndarray, kind: str) -> np.ndarray:
    """An encoded sequence (T, D) as :data:`VARIANTS`' ``kind`` compares it."""
    from iloci.concepts.inference import pen_path

    s = np.asarray(seq, dtype=np.float64)
    if kind == "all":
        return s
    if kind == "pen":
        return s[:, :2]
    p = np.vstack([np.zeros((1, 2)), np.cumsum(s[:, :2], axis=0)])
    radius = float(np.sqrt(((p - p.mean(axis=0)) ** 2).sum(axis=1).mean())) or 1.0
    path = pen_path(s)
    return path if kind == "pen_path" else np.hstack([path[1:], s[:, :2] / radius])


def variant_correct(
    seqs: list, patterns: list, names: np.ndarray, true: np.ndarray
) -> dict[str, int]:
    """Correct answers per :data:`VARIANTS` row: the nearest of ``patterns`` (named ``names``)."""
    from iloci.concepts.inference import pattern_distances

    out = {}
    for row, (kind, warp, compare) in VARIANTS.items():
        d = pattern_distances(
            [_features(x, kind) for x in seqs],
            [_features(x, kind) for x in patterns],
            warp,
            compare,
        )
        out[row] = int((names[d.argmin(axis=1)] == true).sum())
    return out


def _config(dataset: str, seed: int, data_dir: Path | None):
    from iloci.config import load_config

    changes: dict[str, Any] = {"evaluation": {"seed": seed}}
    if dataset.startswith("unipen"):
        changes["data"] = {"path": str(data_dir)}
        changes["evaluation"]["split"] = "writers" if dataset == "unipen-writers" else "concepts"
    return load_config(changes)


def _demos(config) -> tuple[list, list | None]:
    if config.data.path:
        from iloci.data.datasets import load_dataset

        ds = load_dataset(config.data.path)
        return list(ds.demos), list(ds.samples)
    from iloci.data import load_lasa

    return load_lasa(list(config.data.shapes) or None), None


def fold_loss(path: Path, learn: list, test: list) -> dict[str, Any]:
    """One fold's saved memory: correct answers of each way, the memory, the tilt search."""
    from iloci.agent import Agent
    from iloci.concepts.inference import pattern_distances, regenerated_patterns, regeneration_scale
    from iloci.data.concepts import GroundTruth, majority_names
    from iloci.evaluation.baselines import dtw_normalised_1nn

    truth = GroundTruth(list(learn) + list(test))
    true = np.array([truth.of(d) for d in test])
    agent = Agent.load(path)
    mem = agent.memory
    names = majority_names(mem.concept_members(truth))
    entry_names = np.array([names.get(e.concept) or e.concept for e in mem.entries])
    recs = agent.recognize(list(test))
    answers = {"iloci": np.array([names.get(r.concept) or r.concept for r in recs])}
    policies = agent.learner.policies

    def encoded(demos: list) -> list[np.ndarray]:
        return [agent._encode(agent.motion(d))[0] for d in demos]

    seqs = encoded(test)
    kept = [e.pattern for e in mem.entries]
    if any(p is None for p in kept):
        raise SystemExit(f"{path}: entries keep no demonstration ([learner] rehearse_from)")
    answers["kept"] = entry_names[
        pattern_distances(seqs, kept, policies.warp, policies.compare).argmin(axis=1)
    ]
    taught_names = np.array([truth.of(d) for d in learn])
    answers["all_taught"] = taught_names[
        pattern_distances(seqs, encoded(learn), policies.warp, policies.compare).argmin(axis=1)
    ]
    answers["dtw_normalised"] = np.array(dtw_normalised_1nn(list(learn), list(test)))
    right = {w: answers[w] == true for w in WAYS}

    cfg = agent.config.to_dict()
    cfg["learner"].update(TILTS)
    tilted = Agent.load(path, config=cfg).recognize(list(test))
    t_ans = np.array([names.get(r.concept) or r.concept for r in tilted])
    t_right = t_ans == true

    regen = regenerated_patterns(agent.perceptual_model, mem)
    scale = regeneration_scale(regen, mem.concept_labels, policies.warp, policies.compare)
    off = (
        np.array(
            [
                pattern_distances([k], [g], policies.warp, policies.compare)[0, 0]
                for k, g in zip(kept, regen)
            ]
        )
        / scale
    )
    per_concept = {
        c: {
            "taught": int((taught_names == c).sum()),
            "entries": int((entry_names == c).sum()),
            "prototypes": int(sum(e.prototype for e, n in zip(mem.entries, entry_names) if n == c)),
        }
        for c in sorted(set(taught_names.tolist()))
    }
    return {
        "tested": len(test),
        "taught": len(learn),
        "correct": {w: int(right[w].sum()) for w in WAYS},
        "iloci_right_kept_wrong": int((right["iloci"] & ~right["kept"]).sum()),
        "kept_right_iloci_wrong": int((right["kept"] & ~right["iloci"]).sum()),
        "iloci_right_dtw_wrong": int((right["iloci"] & ~right["dtw_normalised"]).sum()),
        "dtw_right_iloci_wrong": int((right["dtw_normalised"] & ~right["iloci"]).sum()),
        "variants": {
            "regenerated": variant_correct(seqs, regen, entry_names, true),
            "kept": variant_correct(seqs, kept, entry_names, true),
        },
        "tilts": {
            "correct": int(t_right.sum()),
            "turned": int(sum(r.tilt not in (None, 0.0) for r in tilted)),
            "changed": int((t_ans != answers["iloci"]).sum()),
            "right_to_wrong": int((right["iloci"] & ~t_right).sum()),
            "wrong_to_right": int((~right["iloci"] & t_right).sum()),
        },
        "memory": {
            "entries": len(mem.entries),
            "prototypes": int(sum(e.prototype for e in mem.entries)),
            "exemplars": int(sum(not e.prototype for e in mem.entries)),
            "mean_generation_error": float(np.mean([e.generation_error for e in mem.entries])),
            "regenerated_vs_kept_over_scale": {
                "median": float(np.median(off)),
                "max": float(np.max(off)),
            },
            "per_concept": per_concept,
        },
    }


def run_one(
    dataset: str, seed: int, data_dir: Path | None, memories: Path, jobs: int
) -> dict[str, Any]:
    """One data set at one seed: learn (or read) every fold's memory, then :func:`fold_loss`."""
    from iloci.evaluation.evaluate import evaluate
    from iloci.evaluation.folds import fold_memory_name, fold_plan

    config = _config(dataset, seed, data_dir)
    where = memories / f"{dataset}-seed{seed}"
    folds = config.evaluation.folds
    if not all((where / fold_memory_name(k)).is_file() for k in range(folds)):
        where.mkdir(parents=True, exist_ok=True)
        evaluate(config, jobs=jobs, baseline=False, memory_dir=str(where))
    demos, samples = _demos(config)
    rows = []
    for k, (li, ti) in enumerate(fold_plan(demos, config, samples)):
        rows.append(
            fold_loss(where / fold_memory_name(k), [demos[i] for i in li], [demos[i] for i in ti])
        )
        print(
            f"[recognition_loss] {dataset} seed {seed} fold {k}: {rows[-1]['correct']}",
            file=sys.stderr,
            flush=True,
        )
    tested = sum(r["tested"] for r in rows)
    total = {w: sum(r["correct"][w] for r in rows) for w in WAYS}
    tilts = {key: sum(r["tilts"][key] for r in rows) for key in rows[0]["tilts"]}
    variants = {
        src: {v: sum(r["variants"][src][v] for r in rows) / tested for v in VARIANTS}
        for src in ("regenerated", "kept")
    }
    return {
        "dataset": dataset,
        "seed": seed,
        "memories": str(where),
        "tested": tested,
        "ccr": {w: total[w] / tested for w in WAYS},
        "ccr_tilts": tilts["correct"] / tested,
        "ccr_variants": variants,
        "correct": total,
        "tilts": tilts,
        "fit_costs": total["kept"] - total["iloci"],
        "condensation_costs": total["all_taught"] - total["kept"],
        "reading_and_distance_cost": total["dtw_normalised"] - total["all_taught"],
        "folds": rows,
    }


def table(runs: list[dict]) -> list[str]:
    """Markdown: CCR % of each way per data set and seed, and the tilt search's changes."""
    out = [
        "| data set | seed | iloci | kept (exact network) | all taught (no condensation) "
        "| normalised DTW 1-NN | with tilt search | tilts: changed, right->wrong, "
        "wrong->right |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in runs:
        c, t = r["ccr"], r["tilts"]
        out.append(
            f"| {r['dataset']} | {r['seed']} | {100 * c['iloci']:.2f} | "
            f"{100 * c['kept']:.2f} | {100 * c['all_taught']:.2f} | "
            f"{100 * c['dtw_normalised']:.2f} | {100 * r['ccr_tilts']:.2f} | "
            f"{t['changed']}, {t['right_to_wrong']}, {t['wrong_to_right']} |"
        )
    return out


def variants_table(runs: list[dict]) -> list[str]:
    """Markdown: CCR % of each :data:`VARIANTS` row on the regenerated patterns, per run."""
    heads = [f"{r['dataset']} {r['seed']}" for r in runs]
    out = ["| comparison | " + " | ".join(heads) + " |", "|---|" + "---|" * len(runs)]
    for v in VARIANTS:
        cells = [f"{100 * r['ccr_variants']['regenerated'][v]:.2f}" for r in runs]
        out.append(f"| {v} | " + " | ".join(cells) + " |")
    cells = [f"{100 * r['ccr']['dtw_normalised']:.2f}" for r in runs]
    out.append("| normalised DTW 1-NN | " + " | ".join(cells) + " |")
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--unipen",
        metavar="PATH",
        help="the train_r01_v07 folder (benchmarks/datasets.py says how to get it)",
    )
    ap.add_argument("--datasets", nargs="+", choices=DATASETS, default=["unipen", "unipen-writers"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument(
        "--memories",
        default="runs/recognition_loss",
        help="fold memories: read from DIR/<data set>-seed<seed>/ when all are "
        "there, else learned and saved there",
    )
    ap.add_argument(
        "--export",
        metavar="DIR",
        default=None,
        help="where the UNIPEN digits are exported (as benchmarks/datasets.py)",
    )
    ap.add_argument("--jobs", "-j", type=int, default=1)
    ap.add_argument("--out", default=str(RESULTS))
    args = ap.parse_args(argv)

    data_dir = None
    if any(d.startswith("unipen") for d in args.datasets):
        if not args.unipen:
            ap.error("--unipen PATH is needed for the UNIPEN data sets (or --datasets lasa)")
        sys.path.insert(0, str(HERE))
        from datasets import export_unipen  # benchmarks/datasets.py

        cache_root = os.environ.get("ILOCI_CACHE_DIR") or os.path.join(
            os.path.expanduser("~"), ".cache", "iloci"
        )
        data_dir = Path(args.export or Path(cache_root) / "unipen-digits")
        export_unipen(args.unipen, data_dir)
    load_before = os.getloadavg()
    t0 = time.perf_counter()
    runs = [
        run_one(d, s, data_dir, Path(args.memories), args.jobs)
        for s in args.seeds
        for d in args.datasets
    ]
    out = {
        "command": "python benchmarks/recognition_loss.py " + " ".join(argv or sys.argv[1:]),
        "ways": list(WAYS),
        "tilt_search": TILTS,
        "runs": runs,
        "table": table(runs),
        "variants_table": variants_table(runs),
        "wall_seconds": time.perf_counter() - t0,
        "machine": {
            "platform": platform.platform(),
            "cpus": os.cpu_count(),
            "load_before": load_before,
            "load_after": os.getloadavg(),
        },
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    print("\n".join(out["table"] + [""] + out["variants_table"]))
    return out


if __name__ == "__main__":
    main()
