"""How far "I don't know" by the nearest known drawing can go on UNIPEN: letters against digits.

Issue 25, part 6, asks familiarity AUROC >= 0.95 for UNIPEN lower-case
letters (never taught) against the known test digits of fold 0, with a
memory taught 30 digits (3 per digit, the paper's 20 %). No familiarity of
iloci's and no baseline reached 0.82 there (``familiarity.json``). This
benchmark asks whether the *data* allow it: it gives the nearest-drawing
novelty score (the baselines of ``familiarity.py``, which are not the
method) far more known digits than any fold teaches, and measures the AUROC
as the reference set grows from the 30 taught drawings to every
single-stroke digit of train_r01_v07 (10 967 drawings, 198 writers).

Per seed, the known drawings are exactly fold 0's 120 test digits of
``familiarity.py`` (the benchmark's 150-digit export, ``fold_plan`` at that
seed), the outside drawings its 260 letters (10 per letter, seeded). The
score of a drawing is minus its distance to the nearest reference drawing,
by DTW 1-NN on normalised paths (``normalise_path``: 50 points in time,
centred, larger bounding-box side 1; dtaidistance, no band) or on 50 points
along the arc length ($1's step 1, Wobbrock et al. 2007). References by
the query's own writer are left out (a writer's own digits would make a
known drawing look familiar for the wrong reason); with them the known
test digit itself, which is in the pool. Reference sets: the fold's 30 taught digits, then
seeded random draws of 100, 300, 1000 and 3000 of the other digits, and
all of them.

Also per letter, with every digit as reference: which letters stay
indistinguishable from digits (a letter written like a digit is one).

Writes ``benchmarks/results/familiarity_ceiling.json``. Run:
``python benchmarks/familiarity_ceiling.py --unipen PATH [--seeds 0 1 2]``
(about 2 minutes per seed on 2 cores).
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "familiarity_ceiling.json"
sys.path.insert(0, str(HERE))

import familiarity as fam  # noqa: E402  (benchmarks/familiarity.py)
import recognition as rec  # noqa: E402  (benchmarks/recognition.py)
from golden import git_head  # noqa: E402  (benchmarks/golden.py)

SIZES = (100, 300, 1000, 3000)


def _paths(points: list[np.ndarray], normalise) -> list[np.ndarray]:
    from iloci.interfaces.values import Demonstration

    return [np.ascontiguousarray(normalise(Demonstration(p.astype(np.float64), index=i)),
                                 dtype=np.float64) for i, p in enumerate(points)]


def _distances(queries: list[np.ndarray], refs: list[np.ndarray]) -> np.ndarray:
    """DTW distance (dtaidistance, no band) of every query to every reference, (Q, R)."""
    from dtaidistance import dtw_ndim

    n = len(refs)
    block = ((0, n), (n, n + len(queries)))
    d = np.asarray(dtw_ndim.distance_matrix_fast(refs + queries, block=block,
                                                 parallel=True))[:n, n:]
    return d.T


def _auroc(n: int, d: np.ndarray, subset: np.ndarray | None = None) -> float:
    """AUROC of the first ``n`` rows (known) against the rest (outside, or ``subset`` of
    them), scored by minus the distance to the nearest reference (columns of ``d``)."""
    s = -d.min(axis=1)
    o = s[n:] if subset is None else s[n:][subset]
    return rec._auroc(list(s[:n]), list(o))


def _known_and_taught(root: str, seed: int, tmp: Path):
    """Fold 0's test and learning digits of the benchmark's export at ``seed``: (points, writer)."""
    from datasets import export_unipen  # benchmarks/datasets.py

    from iloci.data.datasets import load_dataset
    from iloci.evaluation.folds import fold_plan

    data_dir = tmp / "unipen-digits"
    export_unipen(root, data_dir)
    config = rec._config("unipen", seed, data_dir)
    ds = load_dataset(config.data.path)
    learn_idx, test_idx = fold_plan(ds.demos, config)[0]

    def pick(idx):
        return ([np.asarray(ds.demos[i].positions, dtype=np.float64) for i in idx],
                [ds.samples[i].writer for i in idx])
    return pick(learn_idx), pick(test_idx)


def run(root: str, seeds: list[int]) -> dict[str, Any]:
    from iloci.data.unipen import unipen_digits, unipen_letters
    from iloci.evaluation.baselines import normalise_path

    t0 = time.perf_counter()
    digits = unipen_digits(root)
    pool_points = [np.concatenate(s.strokes) for s in digits]
    # the export names a writer's folder with "-" for "/" (export_unipen)
    pool_writers = np.array([s.writer.replace("/", "-") for s in digits])
    letters_all = unipen_letters(root)
    rng = np.random.default_rng([0, 25, 6])          # rec._letters' draw, with writers
    letters, letter_writers, letter_labels = [], [], []
    for letter in sorted({s.label for s in letters_all}):
        idx = [i for i, s in enumerate(letters_all) if s.label == letter]
        for i in sorted(rng.choice(idx, size=min(10, len(idx)), replace=False)):
            s = letters_all[int(i)]
            letters.append(np.concatenate(s.strokes))
            letter_writers.append(s.writer.replace("/", "-"))
            letter_labels.append(letter)
    normalisers = {"dtw_normalised": normalise_path, "dtw_arclength": fam._arclength_path}
    pool = {name: _paths(pool_points, f) for name, f in normalisers.items()}
    out: dict[str, Any] = {"digits": len(digits), "digit_writers": int(len(set(pool_writers))),
                           "letters": len(letters), "seeds": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            (taught, taught_w), (known, known_w) = _known_and_taught(root, seed, Path(tmp))
            # the known test digits are in the pool too (the export is drawn from it):
            # each query's own writer is left out of its references, and with it the query
            row: dict[str, Any] = {"known": len(known), "taught": len(taught)}
            for name, f in normalisers.items():
                q = _paths(known, f) + _paths(letters, f)
                qw = np.array(known_w + letter_writers)
                d_taught = _distances(q, _paths(taught, f))
                d_pool = _distances(q, pool[name])
                d_pool[qw[:, None] == pool_writers[None, :]] = np.inf
                assert np.isfinite(d_pool).any(axis=1).all()
                assert d_pool[:len(known)].min() > 0, "a known digit met itself"
                n = len(known)
                auroc = functools.partial(_auroc, n)
                not_digit_like = np.array([lab not in rec.DIGIT_LIKE for lab in letter_labels])
                table = {"taught_30": {"all_260": auroc(d_taught),
                                       "not_digit_like_180": auroc(d_taught, not_digit_like)}}
                draw = np.random.default_rng([seed, 25, 7])
                for size in SIZES:
                    cols = np.sort(draw.choice(len(pool_points), size=size, replace=False))
                    table[f"random_{size}"] = {"all_260": auroc(d_pool[:, cols]),
                                               "not_digit_like_180": auroc(d_pool[:, cols],
                                                                           not_digit_like)}
                table[f"every_digit_{len(pool_points)}"] = {
                    "all_260": auroc(d_pool), "not_digit_like_180": auroc(d_pool, not_digit_like)}
                s = -d_pool.min(axis=1)
                table["per_letter_every_digit"] = {
                    lab: rec._auroc(list(s[:n]), [s[n + i] for i, x in enumerate(letter_labels)
                                                  if x == lab])
                    for lab in sorted(set(letter_labels))}
                row[name] = table
                print(f"seed {seed} {name}: " + ", ".join(
                    f"{k} {v['all_260']:.3f}/{v['not_digit_like_180']:.3f}"
                    for k, v in table.items() if k != "per_letter_every_digit"), flush=True)
            out["seeds"][str(seed)] = row
    out["wall_seconds"] = time.perf_counter() - t0
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--unipen", required=True, help="the train_r01_v07 folder")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--out", default=str(RESULTS))
    args = ap.parse_args(argv)
    result = {"command": "python benchmarks/familiarity_ceiling.py " + " ".join(
                  argv if argv is not None else sys.argv[1:]),
              "commit": git_head(),
              "machine": {"cpu": platform.processor() or platform.machine(),
                          "cores": os.cpu_count(), "python": platform.python_version()},
              **run(args.unipen, args.seeds)}
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.out}")
    return result


if __name__ == "__main__":
    main()
