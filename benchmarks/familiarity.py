"""Familiarity ("I don't know"): each ``[learner] familiarity`` on the same fold-0 memories.

Issue 25, part 6: familiarity must separate known test drawings from shapes
outside the taught set. Per seed, fold 0 of each data set is learned once
with the default config (oracle teacher; or its memory is read from
``--runs`` when saved there before, e.g. by ``benchmarks/recognition.py``:
its SHA-256 is recorded), and its test drawings and the drawings outside the
taught set are recognized under each familiarity of
:data:`recognition.FAMILIARITIES` (the tilt search on, as in use). AUROC of
known against outside (0.5: no better than chance), and the share answered
"unknown" at familiarity 0.8 (``iloci serve`` / ``iloci teach``):

``multi_models``
    LASA fold 0 against the 4 ``Multi_Models_*`` files (28 drawings), and
    the 12 of them that are not LASA shapes drawn again
    (:data:`recognition.REDRAWN`).
``untaught``
    LASA fold 0 learned with ``[evaluation] untaught = 4`` (4 concepts left
    out): its taught test drawings against the untaught concepts' drawings.
``letters``
    UNIPEN digits, fold 0, against 260 lower-case letters (10 per letter,
    seeded), and the 180 not commonly written like a digit
    (:data:`recognition.DIGIT_LIKE`); also only the known digits the memory
    recognizes (a digit it names wrongly is a drawing unlike what it was
    taught, like a letter).

Beside each, the baselines (:data:`BASELINES`): *not* the method, they
compare each drawing with the fold's stored raw learning demonstrations (the
taught drawings), and minus the distance to the nearest one is the novelty
score: DTW 1-NN on normalised paths resampled in time
(``baseline_dtw_normalised``, the paths of the recognition baseline
``dtw_normalised``) or by arc length (``baseline_dtw_arclength``), and
iloci's own pen-path distance to the taught drawings as encoded
(``baseline_pen_path``: the regenerated patterns replaced by the drawings
they were learned from). On the same memories and drawings, in the same
run, they say how far a method gets on these data without the network.

And the ablation (:data:`VARIANTS`, ``variant_*``): other familiarities
from what the network encodes and regenerates (PB distances, regeneration
from PB_obs, interpolated PBs, per-entry scales, combinations of the path
and regeneration distances), none with a constant fitted to these drawings.

Writes ``benchmarks/results/familiarity.json``: per seed the tables above;
``summary``: per part, subset and familiarity the AUROC per seed and its
mean; ``targets``: issue 25's (AUROC >= 0.95 with the default familiarity
on Multi_Models all 28 and on UNIPEN letters all 260, every seed), met or
not, and the default against the best baseline per seed; ``config``: the
learner settings and back ends the memories were learned and read with
(the default config), and the commit.

Run: ``python benchmarks/familiarity.py [--unipen PATH] [--seeds 0 1 2]
[--runs DIR]``; ``--merge A.json B.json ...`` writes one file from runs
made apart (e.g. one process per seed). A memory found in ``--runs`` is reused as saved (with the
config saved in it): give a fresh ``--runs`` after a default changes.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "familiarity.json"
sys.path.insert(0, str(HERE))

import recognition as rec  # noqa: E402  (benchmarks/recognition.py)
from golden import git_head  # noqa: E402  (benchmarks/golden.py)


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _fold0(config, demos: list, path: Path) -> tuple[list, list, str, bool]:
    """Fold 0's learning and test demonstrations; its memory learned into ``path`` unless there."""
    from iloci.evaluation.fold import run_fold
    from iloci.evaluation.folds import fold_plan

    learn_idx, test_idx = fold_plan(demos, config)[0]
    learn = [demos[i] for i in learn_idx]
    test = [demos[i] for i in test_idx]
    reused = (path / "fold-0.npz").is_file()
    if not reused:
        run_fold(config, 0, learn, test, baseline=False, details=False, memory_dir=str(path))
    return learn, test, _sha(path / "fold-0.npz"), reused


def _arclength_path(demo) -> np.ndarray:
    """50 points equally spaced along the path ($1's step 1, Wobbrock et al. 2007), centred,
    larger bounding-box side 1 (the normalisation of ``normalise_path``)."""
    from iloci.evaluation.baselines import DTW_POINTS, dollar1_resample

    p = dollar1_resample(np.asarray(demo.positions, dtype=np.float64), DTW_POINTS)
    p = p - p.mean(axis=0)
    size = float(np.max(np.ptp(p, axis=0)))
    return p / size if size > 0 else p


def _dtw_nearest(learn: list, drawings: list, normalise) -> list[float]:
    """Minus the DTW distance (dtaidistance, no band) of each drawing's normalised path to the
    nearest learning demonstration's (not the method)."""
    from dtaidistance import dtw_ndim

    ref = [np.ascontiguousarray(normalise(d), dtype=np.float64) for d in learn]
    query = [np.ascontiguousarray(normalise(d), dtype=np.float64) for d in drawings]
    n = len(ref)
    block = ((0, n), (n, n + len(query)))
    dist = np.asarray(dtw_ndim.distance_matrix_fast(ref + query, block=block,
                                                    parallel=False))[:n, n:].T
    return [-float(x) for x in dist.min(axis=1)]


def _encoded(agent, demos: list) -> list[np.ndarray]:
    """The demonstrations as the agent's network sees them (its preprocessing and encoder)."""
    return [agent._encode(agent.motion(d))[0] for d in demos]


def _baselines(agent, learn: list, drawings: list) -> dict[str, list[float]]:
    """:data:`BASELINES`' novelty scores (higher: more familiar) of ``drawings``."""
    from iloci.concepts.inference import path_distances
    from iloci.evaluation.baselines import normalise_path

    pen = path_distances(_encoded(agent, drawings), _encoded(agent, learn)).min(axis=1)
    return {"baseline_dtw_normalised": _dtw_nearest(learn, drawings, normalise_path),
            "baseline_dtw_arclength": _dtw_nearest(learn, drawings, _arclength_path),
            "baseline_pen_path": [-float(x) for x in pen]}


#: The baselines: novelty by the nearest taught drawing (module docstring).
BASELINES = ("baseline_dtw_normalised", "baseline_dtw_arclength", "baseline_pen_path")

#: The ablation's familiarities, each from the memory's network (higher: more familiar).
VARIANTS = {
    "variant_path_2_nearest": "mean path distance to the 2 nearest entries",
    "variant_path_concept_mean": "path distance to the nearest concept, mean over its entries",
    "variant_path_density": "log of sum over entries of exp(-path distance / path_scale)",
    "variant_path_per_entry_scale": "path distance to each entry over that entry's distance "
                                    "to the nearest entry of another concept; the lowest",
    "variant_path_plus_regeneration": "path distance / path_scale + regeneration distance / "
                                      "regeneration_scale, each the lowest over entries",
    "variant_path_max_regeneration": "the larger of the two, each on its memory scale",
    "variant_path_with_interpolations": "path distance to the entries' regenerations and "
                                        "to those of PB midpoints of two entries of one "
                                        "concept",
    "variant_self_path": "path distance of the drawing to the network's regeneration from "
                         "its own PB_obs",
    "variant_self_regeneration_to_entries": "path distance of the regeneration from PB_obs "
                                            "to the nearest entry's",
    "variant_pb_distance": "PB_obs's distance to the nearest PB_rec",
}


def _variants(agent, drawings: list) -> dict[str, list[float]]:
    """:data:`VARIANTS`' familiarities of ``drawings`` on ``agent``'s memory."""
    from scipy.spatial.distance import cdist

    from iloci.concepts.inference import (path_distances, path_scale, pattern_distances,
                                          regenerated_patterns)
    learner = agent.learner
    memory, model, pol = learner.memory, learner.model, learner.policies
    seqs = _encoded(agent, drawings)
    pats = regenerated_patterns(model, memory)
    labels = np.asarray(memory.concept_labels)
    other = labels[:, None] != labels[None, :]
    path = path_distances(seqs, pats)                                   # (B, M)
    regen = pattern_distances(seqs, pats, pol.warp, pol.compare)
    s_path = path_scale(pats, labels)
    between = np.where(other, pattern_distances(pats, pats, pol.warp, pol.compare),
                       np.inf).min(axis=1)
    s_regen = float(np.median(between[np.isfinite(between)]))
    entry_other = np.where(other, path_distances(pats, pats), np.inf).min(axis=1)
    concepts = sorted(set(labels.tolist()))
    out = {
        "variant_path_2_nearest": -np.sort(path, axis=1)[:, :2].mean(axis=1),
        "variant_path_concept_mean": -np.stack(
            [path[:, labels == c].mean(axis=1) for c in concepts], axis=1).min(axis=1),
        "variant_path_density": np.log(np.exp(-path / s_path).sum(axis=1)),
        "variant_path_per_entry_scale": -(path / entry_other[None, :]).min(axis=1),
        "variant_path_plus_regeneration": -(path.min(axis=1) / s_path
                                            + regen.min(axis=1) / s_regen),
        "variant_path_max_regeneration": -np.maximum(path.min(axis=1) / s_path,
                                                     regen.min(axis=1) / s_regen),
    }
    ents = memory.entries
    pairs = [(i, j) for i in range(len(ents)) for j in range(i + 1, len(ents))
             if ents[i].concept == ents[j].concept]
    mid = path.min(axis=1)
    if pairs:
        made = model.generate(
            np.stack([(ents[i].pb + ents[j].pb) / 2 for i, j in pairs]),
            np.stack([(ents[i].initial_input + ents[j].initial_input) / 2 for i, j in pairs]),
            [round((ents[i].num_steps + ents[j].num_steps) / 2) for i, j in pairs])
        mid = np.minimum(mid, path_distances(seqs, [np.asarray(g) for g in made]).min(axis=1))
    out["variant_path_with_interpolations"] = -mid
    pb_obs = learner.recognize_pbs(seqs)
    own = [np.asarray(g) for g in model.generate(pb_obs, np.stack([q[0] for q in seqs]),
                                                  [len(q) for q in seqs])]
    out["variant_self_path"] = -np.array([path_distances([q], [g])[0, 0]
                                          for q, g in zip(seqs, own)])
    out["variant_self_regeneration_to_entries"] = -path_distances(own, pats).min(axis=1)
    out["variant_pb_distance"] = -cdist(pb_obs, memory.pbs_rec).min(axis=1)
    return {k: [float(x) for x in v] for k, v in out.items()}


def _scores(path: Path, known: list, outside: list, learn: list
            ) -> tuple[dict[str, list[float]], list]:
    fam = rec._familiarity(path / "fold-0.npz", known, outside)
    agent = rec._agent(path / "fold-0.npz", {})
    drawings = list(known) + list(outside)
    fam |= _baselines(agent, learn, drawings)
    fam |= _variants(agent, drawings)
    return fam, agent.recognize(list(known))


def _table(fam: dict[str, list[float]], n: int, subsets: dict[str, list[int]]
           ) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, values in fam.items():
        k, o = values[:n], values[n:]
        row: dict[str, Any] = {s: rec._auroc(k, [o[i] for i in idx]) for s, idx in subsets.items()}
        if name in rec.FAMILIARITIES:   # on the familiarity scale: "unknown" at 0.8
            row[f"known_unknown_below_{rec.UNKNOWN_BELOW}"] = float(
                np.mean(np.asarray(k) < rec.UNKNOWN_BELOW))
            row[f"outside_unknown_below_{rec.UNKNOWN_BELOW}"] = float(
                np.mean(np.asarray(o) < rec.UNKNOWN_BELOW))
        out[name] = row
    return out


def lasa(seed: int, runs: Path) -> dict[str, Any]:
    from iloci.config import load_config
    from iloci.data import load_lasa
    from iloci.data.concepts import MULTI_MODEL_SHAPES

    demos = load_lasa()
    out: dict[str, Any] = {}
    path = runs / f"lasa-seed{seed}"
    learn, test, sha, reused = _fold0(load_config({"evaluation": {"seed": seed}}), demos, path)
    outside = load_lasa(MULTI_MODEL_SHAPES)
    fam, _ = _scores(path, test, outside, learn)
    out["multi_models"] = {
        "memory": {"file": str(path / "fold-0.npz"), "sha256": sha, "reused": reused},
        "known": len(test), "outside": len(outside),
        "auroc": _table(fam, len(test), {
            "all_28": list(range(len(outside))),
            "not_redrawn_12": [i for i, d in enumerate(outside) if d.key not in rec.REDRAWN]})}

    cfg = load_config({"evaluation": {"seed": seed, "untaught": 4}})
    path = runs / f"lasa-untaught-seed{seed}"
    learn, test, sha, reused = _fold0(cfg, demos, path)
    from iloci.evaluation.folds import untaught_concepts
    left = set(untaught_concepts(demos, cfg, 0))
    known = [d for d in test if d.shape not in left]
    untaught = [d for d in test if d.shape in left]
    fam, _ = _scores(path, known, untaught, learn)
    out["untaught"] = {
        "memory": {"file": str(path / "fold-0.npz"), "sha256": sha, "reused": reused},
        "left_out": sorted(left), "known": len(known), "outside": len(untaught),
        "auroc": _table(fam, len(known), {"untaught": list(range(len(untaught)))})}
    return out


def _unique_copy(src: Path, dst: Path) -> list[str]:
    """Copy ``src``'s drawing files to ``dst`` but those whose bytes repeat an earlier file's.

    Files in sorted path order; returns the left-out files (relative paths).
    """
    import shutil

    if dst.exists():
        shutil.rmtree(dst)
    seen: set[str] = set()
    removed = []
    for f in sorted(src.rglob("*.csv")):
        key = hashlib.sha256(f.read_bytes()).hexdigest()
        rel = f.relative_to(src)
        if key in seen:
            removed.append(str(rel))
            continue
        seen.add(key)
        (dst / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(f, dst / rel)
    return removed


def unipen(seed: int, runs: Path, root: str) -> dict[str, Any]:
    from iloci.data.concepts import majority_names
    from iloci.data.datasets import load_dataset

    from datasets import export_unipen  # benchmarks/datasets.py
    cache_root = os.environ.get("ILOCI_CACHE_DIR") or os.path.join(
        os.path.expanduser("~"), ".cache", "iloci")
    data_dir = Path(cache_root) / "unipen-digits"
    export_unipen(root, data_dir)
    # train_r01_v07 holds some drawings twice (one ibm writer's session files
    # share ink, e.g. ibm/r01-12 and ibm/r03-12), and the data set reader
    # refuses a drawing in two files: the later copies are left out here (the
    # export drops them itself since read_unipen(drop_copies=True); this
    # step then removes nothing, and familiarity.json predates it)
    unique = data_dir.parent / f"unipen-digits-unique-seed{seed}"
    removed = _unique_copy(data_dir, unique)
    config = rec._config("unipen", seed, unique)
    demos = load_dataset(config.data.path).demos
    path = runs / f"unipen-seed{seed}"
    learn, test, sha, reused = _fold0(config, demos, path)
    letters = rec._letters(root, 0)
    fam, recs = _scores(path, test, letters, learn)
    from iloci.agent import Agent
    from iloci.data.concepts import GroundTruth
    memory = Agent.load(path / "fold-0.npz").memory
    names = majority_names(memory.concept_members(GroundTruth(learn + test)))
    right = [(names.get(r.concept) or r.concept) == d.true_concept for r, d in zip(recs, test)]
    subsets = {"all_260": list(range(len(letters))),
               "not_digit_like_180": [i for i, d in enumerate(letters)
                                      if d.shape not in rec.DIGIT_LIKE]}
    table = _table(fam, len(test), subsets)
    # only the known digits the memory names right, against every letter
    n = len(test)
    for name, values in fam.items():
        k = [v for v, ok in zip(values[:n], right) if ok]
        table[name]["recognized_known_vs_all_260"] = rec._auroc(k, values[n:])
    per_letter = {}
    for letter in sorted({d.shape for d in letters}):
        idx = [i for i, d in enumerate(letters) if d.shape == letter]
        v = fam["path"]
        per_letter[letter] = rec._auroc(v[:n], [v[n + i] for i in idx])
    return {"letters": {
        "memory": {"file": str(path / "fold-0.npz"), "sha256": sha, "reused": reused},
        "known": n, "outside": len(letters), "known_recognized": int(sum(right)),
        "digits": len(demos), "duplicates_left_out": removed,
        "auroc": table, "path_auroc_per_letter": per_letter}}


def merge(parts: list[Path], out_path: Path, note: str | None) -> dict[str, Any]:
    """One output from several (their runs, by seed); each part's command, commit, config kept."""
    outs = [json.loads(p.read_text()) for p in parts]
    configs = {json.dumps(o.get("config"), sort_keys=True) for o in outs}
    if len(configs) > 1:
        raise SystemExit(f"{', '.join(map(str, parts))}: learned with different configs; "
                         "merge only runs of the same config")
    runs = sorted((r for o in outs for r in o["runs"]), key=lambda r: r["seed"])
    seeds = [r["seed"] for r in runs]
    if len(set(seeds)) < len(seeds):
        raise SystemExit(f"seed given twice in {', '.join(map(str, parts))}: {seeds}")
    summary, targets = summarize(runs, outs[0]["config"]["learner"]["familiarity"])
    out = {k: v for k, v in outs[0].items() if k not in ("command", "commit", "note",
                                                          "machine", "wall_seconds", "runs")}
    out |= {"command": "python benchmarks/familiarity.py --merge " + " ".join(map(str, parts)),
            "parts": [{k: o.get(k) for k in ("command", "commit", "note", "wall_seconds",
                                               "machine")} for o in outs],
            "commit": sorted({o.get("commit") or "" for o in outs}),
            "summary": summary, "targets": targets, "runs": runs}
    if note:
        out["note"] = note
    out_path.parent.mkdir(parents=True, exist_ok=True)
    out_path.write_text(json.dumps(out, indent=1) + "\n")
    for name, t in targets.items():
        print(f"{name}: {t['value']} -> {'met' if t['met'] else 'MISSED'}", file=sys.stderr)
    print(f"wrote {out_path}", file=sys.stderr)
    return out


#: Issue 25's familiarity targets: (part, subset) -> AUROC floor, for the
#: default familiarity on every seed.
TARGETS = {("multi_models", "all_28"): 0.95, ("letters", "all_260"): 0.95}


def summarize(runs: list[dict[str, Any]], default: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """Per part, subset and familiarity: AUROC per seed and mean; and the targets."""
    summary: dict[str, Any] = {}
    for r in runs:
        for part in ("multi_models", "untaught", "letters"):
            for fam, row in r.get(part, {}).get("auroc", {}).items():
                for subset, v in row.items():
                    if "unknown_below" in subset:
                        continue
                    cell = summary.setdefault(part, {}).setdefault(subset, {}).setdefault(
                        fam, {"seeds": {}})
                    cell["seeds"][str(r["seed"])] = v
    for part in summary.values():
        for subset in part.values():
            names = [b for b in BASELINES if b in subset]
            if names:   # the best baseline of each seed, on the same drawings
                seeds = subset[names[0]]["seeds"]
                subset["best_baseline"] = {"seeds": {k: max(subset[b]["seeds"][k]
                                                            for b in names) for k in seeds},
                                           "which": {k: max(names, key=lambda b: subset[b][
                                               "seeds"][k]) for k in seeds}}
            for cell in subset.values():
                cell["mean"] = float(np.mean(list(cell["seeds"].values())))
    targets: dict[str, Any] = {}
    for (part, subset), floor in TARGETS.items():
        cell = summary.get(part, {}).get(subset, {}).get(default)
        if cell:
            targets[f"{part}_{subset}_ge_{floor}"] = {
                "familiarity": default, "value": cell["seeds"],
                "met": all(v >= floor for v in cell["seeds"].values())}
            best = summary[part][subset].get("best_baseline")
            if best:
                targets[f"{part}_{subset}_ge_best_baseline"] = {
                    "familiarity": default, "value": cell["seeds"],
                    "best_baseline": best["seeds"],
                    "met": all(v >= best["seeds"][k] for k, v in cell["seeds"].items())}
    return summary, targets


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--unipen", metavar="PATH", help="the train_r01_v07 folder (without it: "
                    "LASA only)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--runs", default="runs/recognition",
                    help="fold memories: read when there, else learned and saved there")
    ap.add_argument("--out", default=str(RESULTS))
    ap.add_argument("--note", help="free text recorded in the output")
    ap.add_argument("--merge", nargs="+", metavar="JSON",
                    help="run nothing: write one file from the per-seed runs of these "
                    "outputs (e.g. one process per seed), summarised together")
    args = ap.parse_args(argv)
    if args.merge:
        return merge([Path(p) for p in args.merge], Path(args.out), args.note)
    load_before = os.getloadavg()
    t0 = time.perf_counter()
    runs = []
    for seed in args.seeds:
        print(f"[familiarity] seed {seed} ...", file=sys.stderr, flush=True)
        t_seed = time.perf_counter()
        r: dict[str, Any] = {"seed": seed, **lasa(seed, Path(args.runs))}
        if args.unipen:
            r |= unipen(seed, Path(args.runs), args.unipen)
        r["wall_seconds"] = time.perf_counter() - t_seed
        runs.append(r)
        for part in ("multi_models", "untaught", "letters"):
            if part in r:
                print(f"[familiarity] seed {seed} {part}: " + ", ".join(
                    f"{f} {v}" for f, v in r[part]["auroc"].items()), file=sys.stderr,
                    flush=True)
    from iloci.config import load_config
    config = load_config({}).to_dict()
    summary, targets = summarize(runs, config["learner"]["familiarity"])
    out = {"command": "python benchmarks/familiarity.py " + " ".join(argv or sys.argv[1:]),
           "commit": git_head(),
           "config": {"learner": config["learner"], "back_ends": {
               k: config[k]["name"] for k in ("perceptual_model", "clusterer", "teacher",
                                              "ik", "simulator")}},
           "summary": summary, "targets": targets,
           "familiarities": list(rec.FAMILIARITIES), "baselines": list(BASELINES),
           "variants": VARIANTS, "unknown_below": rec.UNKNOWN_BELOW,
           "redrawn_multi_models": sorted(rec.REDRAWN),
           "digit_like_letters": sorted(rec.DIGIT_LIKE), "runs": runs,
           "wall_seconds": time.perf_counter() - t0,
           "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                       "load_before": load_before, "load_after": os.getloadavg()}}
    if args.note:
        out["note"] = args.note
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    for name, t in targets.items():
        print(f"{name}: {t['value']} -> {'met' if t['met'] else 'MISSED'}", file=sys.stderr)
    print(f"wrote {args.out}", file=sys.stderr)
    return out


if __name__ == "__main__":
    main()
