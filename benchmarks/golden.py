"""Golden outputs of the expensive runs (issue 28's guard): record them, or check them.

The runs a refactoring must leave bit for bit as they were:

    main-seed0, main-seed1          the main job (``iloci evaluate``, default
                                    config) on seeds 0 and 1: ``metrics.json``
    quality-best-seed0              ``benchmarks/quality.py``'s rows ``best``
    quality-noisy-0.1-seed0         and ``noisy-0.1`` on seed 0

Each is kept in ``benchmarks/results/golden.json`` as the deterministic part
of ``metrics.json`` (every ``...seconds`` key at any depth, job counts,
versions and the machine dropped) in full, and, per fold, a digest of each
field of the fold's record (``folds.json``: predictions, confidences, PB
points, ..., times dropped), so a mismatch names the fold and the field
that moved. The cheap golden outputs
(a scripted step-wise session and its saved memory file) are held by
``tests/test_golden.py`` on every test run.

Run::

    python benchmarks/golden.py --check            # compare (exit 1 on a difference)
    python benchmarks/golden.py --write            # record (a change that moves results)
    python benchmarks/golden.py --check --only main-seed0
    python benchmarks/golden.py --write --only stepwise   # tests/golden/stepwise.json

A change that legitimately moves a result (other arithmetic, another
default) records them again with ``--write`` in a commit of its own whose
message says which outputs moved and why. About 1 to 2 minutes per run with
2 jobs on an idle 2-core machine.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import subprocess
import sys
import time
from typing import Any

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "golden.json"

#: metrics.json keys that are not results (times, the machine, versions).
VOLATILE = {"wall_seconds", "fold_wall_seconds", "jobs", "versions", "machine"}
#: FoldResult fields that are times.
VOLATILE_FOLD = {"wall_seconds", "rehearsal_seconds", "baseline_seconds"}


def _quality_config(row: str, seed: int) -> dict[str, Any]:
    sys.path.insert(0, str(HERE))
    import quality  # benchmarks/quality.py: its rows and base config

    from iloci.config import load_config
    base = load_config({"perceptual_model": {"name": "native-rnnpb"}}).to_dict()
    data = quality._merge(base, quality.ROWS[row])
    data.setdefault("evaluation", {})["seed"] = seed
    return data


#: run name -> (config as a dict, whether the DTW baseline runs too)
def runs() -> dict[str, tuple[dict[str, Any], bool]]:
    return {"main-seed0": ({"evaluation": {"seed": 0}}, True),
            "main-seed1": ({"evaluation": {"seed": 1}}, True),
            "quality-best-seed0": (_quality_config("best", 0), True),
            "quality-noisy-0.1-seed0": (_quality_config("noisy-0.1", 0), False)}


def _timeless(value: Any) -> Any:
    """``value`` without any key that holds a time (``...seconds``), at any depth."""
    if isinstance(value, dict):
        return {k: _timeless(v) for k, v in value.items() if not str(k).endswith("seconds")}
    if isinstance(value, list):
        return [_timeless(v) for v in value]
    return value


def record(config: dict[str, Any], baseline: bool, jobs: int) -> dict[str, Any]:
    """One run's golden record (see the module docstring)."""
    from iloci.config import load_config
    from iloci.evaluation.evaluate import evaluate
    from iloci.testing.golden import canonical, digest

    metrics, results = evaluate(load_config(config), jobs=jobs, baseline=baseline)
    folds = []
    for r in results:
        d = r.to_dict()
        robust = d.pop("robustness", {})
        fields = {k: digest(_timeless(v)) for k, v in d.items() if k not in VOLATILE_FOLD}
        if robust:
            fields["robustness"] = digest({name: {k: v for k, v in part.items()
                                                  if k != "seconds"}
                                           for name, part in robust.items()})
        folds.append(fields)
    kept = {k: v for k, v in metrics.items() if k not in VOLATILE}
    if isinstance(kept.get("folds"), list):
        kept["folds"] = [{k: v for k, v in f.items() if k not in VOLATILE_FOLD}
                         for f in kept["folds"]]
    if "baseline" in kept:
        kept["baseline"] = {k: v for k, v in kept["baseline"].items() if k != "seconds"}
    return canonical({"metrics": _timeless(kept), "folds": folds})


def git_head() -> str | None:
    """The checkout's commit (``None`` outside a git checkout), recorded beside results."""
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                              check=True, cwd=HERE).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def main(argv: list[str] | None = None) -> int:
    from iloci.testing.golden import differences, read_golden, write_golden

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    mode = ap.add_mutually_exclusive_group(required=True)
    mode.add_argument("--check", action="store_true", help="compare with golden.json")
    mode.add_argument("--write", action="store_true", help="record golden.json again")
    ap.add_argument("--only", nargs="+", metavar="RUN",
                    help="these runs only (names above; 'stepwise' runs tests/test_golden.py)")
    ap.add_argument("--jobs", "-j", type=int, default=2, help="folds in parallel (default 2)")
    args = ap.parse_args(argv)

    names = list(args.only or runs())
    status = 0
    if "stepwise" in names:
        names.remove("stepwise")
        env = dict(os.environ, **({"ILOCI_WRITE_GOLDEN": "1"} if args.write else {}))
        status |= subprocess.call([sys.executable, "-m", "pytest", "-q", "-rs",
                                   str(HERE.parent / "tests" / "test_golden.py")], env=env)
    table = runs()
    unknown = [n for n in names if n not in table]
    if unknown:
        ap.error(f"unknown run(s) {unknown}; choose from {list(table)} or 'stepwise'")
    golden = read_golden(RESULTS) if RESULTS.is_file() else {"runs": {}}
    for name in names:
        config, baseline = table[name]
        t0 = time.perf_counter()
        got = record(config, baseline, args.jobs)
        seconds = time.perf_counter() - t0
        if args.write:
            golden["runs"][name] = got
            golden.setdefault("recorded_at", {})[name] = git_head()
            print(f"{name}: recorded ({seconds:.0f} s), CCR {got['metrics']['ccr_mean']:.4f}")
            continue
        expected = golden["runs"].get(name)
        if expected is None:
            print(f"{name}: no golden record; run --write first")
            status = 1
            continue
        diff = differences(expected, got)
        print(f"{name}: {'identical' if not diff else f'{len(diff)} difference(s)'} "
              f"({seconds:.0f} s)")
        for line in diff[:30]:
            print("   ", line)
        status |= bool(diff)
    if args.write and names:
        write_golden(RESULTS, golden)
        print(f"wrote {RESULTS}")
    return status


if __name__ == "__main__":
    raise SystemExit(main())
