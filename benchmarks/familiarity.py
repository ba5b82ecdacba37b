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

Beside each, a reference that is *not* the method (it compares with stored
raw demonstrations): the normalised-DTW distance of each drawing to the
nearest learning demonstration of the fold (``dtw_normalised``'s paths),
as a familiarity; it says how far the raw data themselves separate the two
sets.

Writes ``benchmarks/results/familiarity.json``: per seed the tables above;
``summary``: per part, subset and familiarity the AUROC per seed and its
mean; ``targets``: issue 25's (AUROC >= 0.95 with the default familiarity
on Multi_Models all 28 and on UNIPEN letters all 260, every seed), met or
not; ``config``: the learner settings and back ends the memories were
learned and read with (the default config), and the commit.

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


def _reference(learn: list, drawings: list) -> list[float]:
    """Minus the normalised-DTW distance to the nearest learning demonstration (not the method)."""
    from dtaidistance import dtw_ndim

    from iloci.evaluation.baselines import normalise_path
    ref = [np.ascontiguousarray(normalise_path(d), dtype=np.float64) for d in learn]
    query = [np.ascontiguousarray(normalise_path(d), dtype=np.float64) for d in drawings]
    n = len(ref)
    block = ((0, n), (n, n + len(query)))
    dist = np.asarray(dtw_ndim.distance_matrix_fast(ref + query, block=block,
                                                    parallel=False))[:n, n:].T
    return [-float(x) for x in dist.min(axis=1)]


def _scores(path: Path, known: list, outside: list, learn: list
            ) -> tuple[dict[str, list[float]], list]:
    fam = rec._familiarity(path / "fold-0.npz", known, outside)
    fam["reference_dtw_nearest_learning_demo"] = _reference(learn, list(known) + list(outside))
    agent = rec._agent(path / "fold-0.npz", {})
    return fam, agent.recognize(list(known))


def _table(fam: dict[str, list[float]], n: int, subsets: dict[str, list[int]]
           ) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, values in fam.items():
        k, o = values[:n], values[n:]
        row: dict[str, Any] = {s: rec._auroc(k, [o[i] for i in idx]) for s, idx in subsets.items()}
        if not name.startswith("reference"):
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
            for cell in subset.values():
                cell["mean"] = float(np.mean(list(cell["seeds"].values())))
    targets: dict[str, Any] = {}
    for (part, subset), floor in TARGETS.items():
        cell = summary.get(part, {}).get(subset, {}).get(default)
        if cell:
            targets[f"{part}_{subset}_ge_{floor}"] = {
                "familiarity": default, "value": cell["seeds"],
                "met": all(v >= floor for v in cell["seeds"].values())}
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
           "familiarities": list(rec.FAMILIARITIES), "unknown_below": rec.UNKNOWN_BELOW,
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
