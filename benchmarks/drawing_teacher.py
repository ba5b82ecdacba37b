"""Can the robot's answers be judged by eye? A teacher seeing only the drawing, beside the oracle.

The oracle judges an answer by labels (the concept of the demonstration the
answering entry stands for) and never looks at it. The drawing teacher
(:class:`iloci.teachers.DrawingTeacher`) looks only at what the robot drew:
+1 when it is DTW-nearest to a reference demonstration of the shown
demonstration's concept (references: every LASA demonstration of the
config's shapes). Each fold of the evaluation (same folds, same order) is
learned once with each teacher; writes ``benchmarks/results/drawing_teacher.json``:

per teacher: ``ccr`` (mean and per fold, the evaluation's definition),
``feedbacks`` (count, +1 count), ``agreement`` (drawing teacher only: the
fraction of its feedbacks equal to what the oracle would have said for the
same answer), ``wall_seconds``.

Run: ``python benchmarks/drawing_teacher.py [--config docs/examples/tiny.toml]
[--folds K ...]``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results" / "drawing_teacher.json"


class Agreement:
    """Wraps a teacher; records whether each feedback matches the oracle's for that answer."""

    def __init__(self, teacher, oracle) -> None:
        self.teacher, self.oracle = teacher, oracle
        self.same: list[bool] = []

    def feedback(self, demo, response):
        value = self.teacher.feedback(demo, response)
        self.same.append(value == self.oracle.feedback(demo, response))
        return value


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="docs/examples/tiny.toml")
    ap.add_argument("--folds", type=int, nargs="*")
    args = ap.parse_args(argv)

    from iloci.config import load_config
    from iloci.data import LASA_SHAPES, load_lasa
    from iloci.evaluation.evaluate import fold_plan, run_fold
    from iloci.teachers import DrawingTeacher, OracleTeacher

    config = load_config(args.config)
    shapes = list(config.data.shapes) or list(LASA_SHAPES)
    demos = load_lasa(shapes)
    plan = fold_plan(demos, config)
    folds = args.folds if args.folds else list(range(len(plan)))
    out: dict = {"command": "python benchmarks/drawing_teacher.py "
                 + " ".join(argv if argv is not None else sys.argv[1:]),
                 "config": args.config, "shapes": shapes, "folds": folds}
    for name in ("oracle", "drawing"):
        ccrs, fbs, agree, wall = [], [], [], 0.0
        for k in folds:
            learn_idx, test_idx = plan[k]
            learn = [demos[i] for i in learn_idx]
            test = [demos[i] for i in test_idx]
            overrides = {}
            wrapped = None
            if name == "drawing":
                wrapped = Agreement(DrawingTeacher(demos), OracleTeacher())
                overrides["teacher"] = wrapped
            t0 = time.perf_counter()
            res = run_fold(config, k, learn, test, baseline=False, details=False,
                           overrides=overrides)
            wall += time.perf_counter() - t0
            ccrs.append(res.ccr)
            fbs.extend(res.feedbacks)
            if wrapped is not None:
                agree.extend(wrapped.same)
            print(f"{name} fold {k}: CCR {res.ccr:.3f}, {len(res.feedbacks)} feedbacks "
                  f"({sum(f == 1 for f in res.feedbacks)} +1)", flush=True)
        out[name] = {"ccr_mean": round(float(np.mean(ccrs)), 4),
                     "ccr_per_fold": [round(c, 4) for c in ccrs],
                     "feedbacks": len(fbs), "rewarded": int(sum(f == 1 for f in fbs)),
                     "wall_seconds": round(wall, 1)}
        if agree:
            out[name]["agreement_with_oracle"] = round(float(np.mean(agree)), 4)
    RESULTS.parent.mkdir(exist_ok=True)
    RESULTS.write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
