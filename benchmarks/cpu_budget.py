"""CPU budget of the main job: how much work the default evaluation is, and the shortest wall
any schedule of it over N cores can give.

``benchmarks/evaluate.py`` times the main job; this says why it takes what it takes.
In one run, with the instruction set in force (``ILOCI_RNNPB_ISA``, as evaluate.py):

``serial``
    The 5-fold LASA evaluation with the default config in this process
    (``jobs = 1``): CPU seconds (``time.process_time``), wall, CCR per fold,
    and the rehearsals' share (``FoldResult.rehearsal_seconds``: nearly all
    of it is native-rnnpb's training kernel).
``parallel``
    The same evaluation with ``--jobs N`` worker processes: wall, the
    workers' CPU seconds (``RUSAGE_CHILDREN`` once the pool is closed), and
    the CCR, which must equal the serial run's.

The two evaluations alternate ``--repeats`` times (the machine's speed drifts
by 10 % from minute to minute here); the budget takes the medians.
``kernel``
    native-rnnpb's training step at paper size (the 36 first sequences of
    LASA fold 0's learning set, 50 steps), median ms of ``--rounds``, and
    the GFLOP/s of its matrix products: per row and step six products of
    ``S x H`` (``S = input_size + context``, ``H = hidden``): the forward
    pass's two, the two that carry the error back, the two weight
    gradients; 2 FLOP per multiply-add, padding not counted.
``blas``
    OpenBLAS's single-thread SGEMM (numpy float32 ``matmul`` of 1024 x 1024
    matrices, in a child process with ``OPENBLAS_NUM_THREADS=1`` and, when
    an instruction set is forced, the OpenBLAS core type that uses the same
    one: ``OPENBLAS_CORETYPE`` Haswell for avx2, SkylakeX for avx512,
    Nehalem for portable), median GFLOP/s: what a well-tuned library gets
    from one core of this machine.
``bound``
    ``serial CPU / N``: no schedule of this work over N cores is shorter
    (the parallel run does slightly more work: each worker process imports
    and converts on its own). ``if_kernel_at_blas_rate``: the same bound if
    the rehearsals' time shrank by the ratio of the kernel's rate to
    BLAS's, a generous upper limit of what a faster kernel could win
    (BLAS's rate is reached on large products; a training step's are
    36 x 31 x 60, in sequence, 50 steps deep).

Writes ``benchmarks/results/cpu_budget.json`` (``--out``).

Run: ``ILOCI_RNNPB_ISA=avx2 python benchmarks/cpu_budget.py [--jobs 2] [--rounds 7]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "cpu_budget.json"

#: The OpenBLAS core type whose SGEMM uses the instruction set iloci's kernel is forced to
#: (OpenBLAS's DYNAMIC_ARCH names; numpy's wheels are built with it).
CORETYPE = {"avx2": "Haswell", "avx512": "SkylakeX", "portable": "Nehalem"}

_BLAS_CHILD = """
import json, statistics, sys, time
import numpy as np
n = 1024
rng = np.random.default_rng(0)
a = rng.standard_normal((n, n)).astype(np.float32)
b = rng.standard_normal((n, n)).astype(np.float32)
a @ b
runs = []
for _ in range(int(sys.argv[1])):
    t0 = time.perf_counter()
    for _ in range(4):
        a @ b
    runs.append(4 * 2 * n ** 3 / (time.perf_counter() - t0) / 1e9)
print(json.dumps({"gflops": statistics.median(runs), "runs": runs,
                  "config": np.show_config(mode="dicts").get("Build Dependencies", {})
                  .get("blas", {})}))
"""


def blas_gflops(isa: str | None, rounds: int) -> dict:
    """Single-thread SGEMM rate of numpy's OpenBLAS, in a child process (its env set first)."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    coretype = CORETYPE.get(isa or "")
    if coretype:
        env["OPENBLAS_CORETYPE"] = coretype
    out = subprocess.run([sys.executable, "-c", _BLAS_CHILD, str(rounds)], env=env,
                         capture_output=True, text=True, check=True)
    res = json.loads(out.stdout)
    res["openblas_coretype"] = coretype or "auto"
    return res


def kernel_step(rounds: int, epochs: int = 200) -> dict:
    """native-rnnpb's training step at paper size: median ms and GFLOP/s of its products."""
    sys.path.insert(0, str(HERE))
    from rnnpb import encoded, lasa_sequences  # benchmarks/rnnpb.py

    from iloci.config import load_config
    from iloci.evaluation.folds import lasa_folds
    from iloci_native.rnnpb import NativeRNNPB

    demos, motions = lasa_sequences(50)
    learn, _ = lasa_folds(demos, 5, seed=0)[0]
    every = encoded(motions, learn)
    seqs = [every[i] for i in learn[:36]]
    model = NativeRNNPB(seed=0, kernel="native")
    model.train(seqs, epochs=2)
    runs = []
    for _ in range(rounds):
        t0 = time.process_time()
        model.train(seqs, epochs=epochs)
        runs.append((time.process_time() - t0) / epochs * 1e3)
    p = load_config(None).perceptual_model.params  # the default back end's sizes
    rows, steps = len(seqs), int(seqs[0].shape[0]) - 1  # each step predicts the next
    s = p.input_size + p.context
    flop = 2 * 6 * s * p.hidden * rows * steps
    ms = statistics.median(runs)
    return {"sequences": rows, "steps": steps, "S": s, "H": p.hidden,
            "mflop_per_step": flop / 1e6, "step_ms_cpu": ms, "step_ms_cpu_runs": runs,
            "gflops": flop / (ms * 1e-3) / 1e9}


def evaluation(jobs: int) -> dict:
    """The default 5-fold LASA evaluation with ``jobs``: CPU of this process, wall, CCR."""
    from iloci.config import load_config
    from iloci.evaluation.evaluate import evaluate

    def children() -> float:
        r = resource.getrusage(resource.RUSAGE_CHILDREN)
        return r.ru_utime + r.ru_stime

    config = load_config(None)
    c0, k0, t0 = time.process_time(), children(), time.perf_counter()
    metrics, results = evaluate(config, jobs=jobs)
    wall = time.perf_counter() - t0
    time.sleep(1.0)  # the pool's workers exit and are reaped: their CPU time is counted
    return {"jobs": jobs, "cpu_seconds_this_process": time.process_time() - c0,
            "cpu_seconds_workers": children() - k0,
            "wall_seconds": wall,
            "ccr_mean": metrics["ccr_mean"], "ccr_folds": metrics["ccr_folds"],
            "rehearsal_seconds": sum(r.rehearsal_seconds for r in results),
            "fold_wall_seconds": [r.wall_seconds for r in results]}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", "-j", type=int, default=2, help="cores of the bound and of the "
                    "parallel run (default 2)")
    ap.add_argument("--rounds", type=int, default=7, help="timed rounds of the kernel step "
                    "and of SGEMM (medians)")
    ap.add_argument("--repeats", type=int, default=3, help="serial and parallel runs, "
                    "alternating (default 3; medians)")
    ap.add_argument("--out", default=str(RESULTS))
    args = ap.parse_args(argv)

    from iloci_native.native import ISA_ENV, kernel_info

    isa = os.environ.get(ISA_ENV)
    load_before = os.getloadavg()
    serial_runs, parallel_runs = [], []
    for r in range(args.repeats):
        print(f"[{r + 1}/{args.repeats}] the evaluation in this process (jobs 1) ...", flush=True)
        serial_runs.append(evaluation(1))
        print(f"   cpu {serial_runs[-1]['cpu_seconds_this_process']:.1f} s, rehearsals "
              f"{serial_runs[-1]['rehearsal_seconds']:.1f} s", flush=True)
        print(f"[{r + 1}/{args.repeats}] the evaluation with {args.jobs} jobs ...", flush=True)
        parallel_runs.append(evaluation(args.jobs))
        print(f"   wall {parallel_runs[-1]['wall_seconds']:.1f} s, workers' cpu "
              f"{parallel_runs[-1]['cpu_seconds_workers']:.1f} s", flush=True)

    def median(runs: list[dict], key: str) -> float:
        return statistics.median(run[key] for run in runs)

    print("the training kernel's step at paper size ...", flush=True)
    kernel = kernel_step(args.rounds)
    print(f"   {kernel['step_ms_cpu']:.3f} ms, {kernel['gflops']:.1f} GFLOP/s", flush=True)
    print("OpenBLAS SGEMM, one thread ...", flush=True)
    blas = blas_gflops(isa, args.rounds)
    print(f"   {blas['gflops']:.1f} GFLOP/s", flush=True)

    cpu = median(serial_runs, "cpu_seconds_this_process")
    rehearsal = median(serial_runs, "rehearsal_seconds")
    faster = rehearsal * (1 - kernel["gflops"] / blas["gflops"])
    out = {
        "command": "python benchmarks/cpu_budget.py " + " ".join(argv or sys.argv[1:]),
        "isa_forced": isa, "rnnpb_kernel": kernel_info(),
        "serial": {"cpu_seconds_median": cpu, "rehearsal_seconds_median": rehearsal,
                   "runs": serial_runs},
        "parallel": {"wall_seconds_median": median(parallel_runs, "wall_seconds"),
                     "cpu_seconds_workers_median": median(parallel_runs, "cpu_seconds_workers"),
                     "runs": parallel_runs},
        "kernel": kernel, "blas": blas,
        "kernel_share_of_blas_rate": kernel["gflops"] / blas["gflops"],
        "rehearsal_share_of_cpu": rehearsal / cpu,
        "bound": {"cores": args.jobs, "wall_seconds": cpu / args.jobs,
                  "if_kernel_at_blas_rate": (cpu - faster) / args.jobs},
        "same_ccr_every_run": all(run["ccr_folds"] == serial_runs[0]["ccr_folds"]
                                  for run in serial_runs + parallel_runs),
        "machine": {"python": platform.python_version(), "platform": platform.platform(),
                    "processor": platform.processor(), "cpus": os.cpu_count(),
                    "load_average_before": load_before, "load_average_after": os.getloadavg()},
    }
    path = Path(args.out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=1) + "\n")
    print(f"bound on {args.jobs} cores: {out['bound']['wall_seconds']:.1f} s "
          f"({out['bound']['if_kernel_at_blas_rate']:.1f} s with the kernel at BLAS's rate); "
          f"parallel wall {out['parallel']['wall_seconds_median']:.1f} s (median); wrote {path}")
    return out


if __name__ == "__main__":
    main()
