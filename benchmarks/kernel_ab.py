"""Reproducibility's cost: the native kernel before and after one arithmetic on every ISA.

Issue 27 makes every instruction-set path of the native kernel compute one
float32 arithmetic (explicit fused multiply-adds, our own tanh with a true
division, ``-ffp-contract=off``: "The float32 arithmetic" in
``plugins/iloci-native/iloci_native/_native.c``), so that the same seed
trains bit-identical networks on any CPU; it may cost at most 15 % against
the kernel it replaced. This benchmark builds that kernel (commit
``OLD_REV``, then ``plugins/iloci-torch``, whose paths rounded differently)
from the repository's history (``git show``) with the flags it was built
with (Python's ``sysconfig`` CFLAGS plus ``-O3 -fno-math-errno``), loads it
and the installed kernel with ctypes and times the same training on the
same data, alternating, in one process, for every instruction set this CPU
runs:

    per round and instruction set: old kernel, 200 epochs; new kernel, 200
               epochs (the order alternating from round to round)
    data: 36 LASA sequences x 50 steps x 6 joint features (fold 0's learning
          set, as benchmarks/rnnpb.py), H 60, C 25, P 4, float32, closed loop
    result: median ms per step (wall and process CPU time) over the rounds;
            new over old: each round's ratio, their median, spread and a
            bootstrap 95 % interval of the median

and, after 1500 epochs from the same start, a checksum (sha256 of weights
and PBs) per kernel and instruction set: the new kernel's agree across
instruction sets (``new_bit_identical_across_isas``), the old one's did not.

Writes ``benchmarks/results/kernel_ab.json``. Needs git history (a full
clone) and a C compiler.

    python benchmarks/kernel_ab.py [--rounds 11] [--epochs 200]
"""

from __future__ import annotations

import argparse
import ctypes
import hashlib
import json
import os
from pathlib import Path
import platform
import shlex
import statistics
import subprocess
import sys
import sysconfig
import tempfile
import time

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / "results" / "kernel_ab.json"
OLD_REV = "0fa2a1b"
OLD_DIR = "plugins/iloci-torch/iloci_torch"

sys.path.insert(0, str(HERE))


def build_old(tmp: Path) -> ctypes.CDLL:
    """The kernel of OLD_REV as a shared library, built with the flags it was built with."""
    for name in ("_native.c", "_native_kernel.h"):
        src = subprocess.run(["git", "-C", str(ROOT), "show", f"{OLD_REV}:{OLD_DIR}/{name}"],
                             check=True, capture_output=True, text=True).stdout
        (tmp / name).write_text(src)
    cc = shlex.split(sysconfig.get_config_var("CC") or "cc")
    flags = shlex.split(sysconfig.get_config_var("CFLAGS") or "")
    flags += ["-O3", "-fno-math-errno", "-fPIC", "-shared", "-DILOCI_NATIVE_NO_PYTHON"]
    so = tmp / "old_native.so"
    subprocess.run([*cc, *flags, str(tmp / "_native.c"), "-o", str(so)], check=True)
    return ctypes.CDLL(str(so))


def ratio_summary(new: list[float], old: list[float], seed: int = 0) -> dict:
    """Each round's new / old, their median, range and a bootstrap 95 % interval of the median.

    The two runs of a round are back to back, so load on the machine hits
    both alike; the interval resamples the rounds (10000 resamples, seeded).
    """
    r = np.asarray(new) / np.asarray(old)
    rng = np.random.default_rng(seed)
    boot = np.median(rng.choice(r, size=(10000, r.size)), axis=1)
    lo, hi = np.percentile(boot, [2.5, 97.5])
    return {"median": float(np.median(r)), "bootstrap_95": [float(lo), float(hi)],
            "min": float(r.min()), "max": float(r.max()),
            "rounds_new_faster": int((r < 1).sum()), "rounds": int(r.size)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=11)
    ap.add_argument("--epochs", type=int, default=200)
    args = ap.parse_args()

    from rnnpb import encoded, lasa_sequences

    from iloci.evaluation.folds import lasa_folds
    from iloci.rnnpb import WEIGHT_NAMES
    from iloci_native.native import ISAS, TrainArgs, native_isas, native_lib
    from iloci_native.rnnpb import NativeRNNPB

    demos, motions = lasa_sequences(50)
    learn, _ = lasa_folds(demos, 5, seed=0)[0]
    seqs = encoded(motions, learn)
    paper = [seqs[i] for i in learn[:36]]
    model = NativeRNNPB(seed=0)
    p = model.params
    X, mask, per_seq = model._padded(paper, geometric=False, multiple=1)
    T, R, D = X.shape
    d, h, c, pb = model._sizes
    f32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)  # noqa: E731
    Xf, mw = f32(X), f32(mask * (per_seq / R)[None, :])
    start = {k: f32(v) for k, v in model.state().items() if k in WEIGHT_NAMES}
    u0 = np.zeros((R, pb), np.float32)
    isas = native_isas()

    with tempfile.TemporaryDirectory() as tmp:
        libs = {"old": build_old(Path(tmp)), "new": native_lib()}
        libs["old"].iloci_rnnpb_train.argtypes = [ctypes.POINTER(TrainArgs)]

        def run(which: str, isa: str, epochs: int) -> tuple[float, float, str]:
            w = {k: v.copy() for k, v in start.items()}
            u = u0.copy()
            a = TrainArgs(size=ctypes.sizeof(TrainArgs), isa=ISAS[isa], epochs=epochs,
                          T=T, R=R, D=d, C=c, H=h, P=pb, warmup=int(p.warmup_epochs),
                          alpha=float(p.closed_loop), bound=float(p.pb_bound),
                          lr=float(p.learning_rate), pb_lr=float(p.pb_learning_rate),
                          decay=float(p.learning_rate_decay), clip=float(p.grad_clip),
                          X=Xf.ctypes.data, mw=mw.ctypes.data,
                          w_in=w["w_in"].ctypes.data, b_hidden=w["b_hidden"].ctypes.data,
                          w_out=w["w_out"].ctypes.data, b_out=w["b_out"].ctypes.data,
                          u=u.ctypes.data, loss_history=None)
            w0, c0 = time.perf_counter(), time.process_time()
            code = libs[which].iloci_rnnpb_train(ctypes.byref(a))
            wall = (time.perf_counter() - w0) / epochs * 1e3
            cpu = (time.process_time() - c0) / epochs * 1e3
            if code != 0:
                sys.exit(f"the {which} kernel returned {code}")
            digest = hashlib.sha256(b"".join(a.tobytes() for a in (*w.values(), u)))
            return wall, cpu, digest.hexdigest()[:16]

        times = {isa: {k: {"wall": [], "cpu": []} for k in ("old", "new")} for isa in isas}
        load_before = os.getloadavg()
        for r in range(args.rounds + 1):            # round 0 warms up, not counted
            for isa in isas:
                # the order alternates, so neither kernel always runs on a
                # cache (or a clock) the other one warmed
                for which in (("old", "new") if r % 2 else ("new", "old")):
                    wall, cpu, _ = run(which, isa, 2 if r == 0 else args.epochs)
                    if r:
                        times[isa][which]["wall"].append(wall)
                        times[isa][which]["cpu"].append(cpu)
        load_after = os.getloadavg()
        sums = {which: {isa: run(which, isa, 1500)[2] for isa in isas} for which in libs}
    med = {isa: {k: {m: statistics.median(v) for m, v in t.items()} for k, t in d.items()}
           for isa, d in times.items()}
    ratios = {isa: {m: ratio_summary(d["new"][m], d["old"][m]) for m in ("wall", "cpu")}
              for isa, d in times.items()}
    out = {
        "command": f"python benchmarks/kernel_ab.py --rounds {args.rounds} "
                   f"--epochs {args.epochs}",
        "old_kernel": f"{OLD_REV}:{OLD_DIR}/_native.c (each path its own rounding)",
        "new_kernel": "plugins/iloci-native/iloci_native/_native.c (installed build)",
        "shape": {"T": T, "R": R, "D": d, "C": c, "H": h, "P": pb},
        "epochs_per_round": args.epochs, "rounds": args.rounds,
        "step_ms": med,
        "new_over_old": {isa: {m: r[m]["median"] for m in ("wall", "cpu")}
                         for isa, r in ratios.items()},
        "new_over_old_per_round": ratios,
        "sha256_after_1500_epochs": sums,
        "new_bit_identical_across_isas": len(set(sums["new"].values())) == 1,
        "old_bit_identical_across_isas": len(set(sums["old"].values())) == 1,
        "targets": {"new_bit_identical_across_isas": len(set(sums["new"].values())) == 1,
                    **{f"{isa}_cost_le_15pct": ratios[isa]["wall"]["median"] <= 1.15
                       for isa in isas}},
        "machine": {"python": platform.python_version(), "platform": platform.platform(),
                    "cpus": os.cpu_count(), "load_average_before": load_before,
                    "load_average_after": load_after},
    }
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
