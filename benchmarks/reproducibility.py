"""Reproducibility: one seed, one result, whatever the instruction set and the BLAS kernels.

Runs the main job (``iloci evaluate``, default config, LASA, 5 folds) once
per seed and per way of running it, each in a process of its own:

* ``ILOCI_RNNPB_ISA`` forced to each instruction set of native-rnnpb's
  kernel this CPU runs (``avx512``, ``avx2``, ``portable``);
* on the first seed, ``OPENBLAS_CORETYPE`` forced to each OpenBLAS kernel
  this CPU runs (``Nehalem``, ``Haswell``, ``SkylakeX``), as numpy on
  another x86-64 CPU would pick it (the kernel's instruction set left to
  choose itself).

* with ``--python PY ...``, on the first seed, under each of those Python
  interpreters too (e.g. tox's ``.tox/test-py312/bin/python``: another
  Python and the numpy and scipy versions pip chose for it), each with
  iloci and its default back ends installed.

and records, per run, the CCR (mean and per fold), a checksum of the
results (``folds.json`` without its times: every prediction, confidence,
PB, ...) and a checksum of each fold's final network (the weights and PBs
of the learned memory saved by ``--memories``: every array of the memory
file, by name, bit for bit, but its JSON header, which records where the
robot's URDF is installed: a path of the machine, not a result). A row of
one seed with another checksum than the others is a reproducibility
failure.

Writes ``benchmarks/results/reproducibility.json`` (``--out``)::

    runs        one record per (seed, isa, coretype, python): command, environment,
                ccr_mean, ccr_folds, results_checksum, network_checksums
                (one per fold), wall_seconds
    identical   per seed: whether every run gave the same checksums
    git_head, machine (CPU model, flags used), load_average, versions

Run: ``python benchmarks/reproducibility.py [--seeds 0 1 2] [--jobs 2] [--python PY ...]``
(about 1 minute per run at 2 jobs on an idle 2-core machine; the portable
path's about 2).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
from pathlib import Path
import platform
import subprocess
import sys
import tempfile
import time
from typing import Any

import numpy as np

# benchmarks/golden.py: this folder is on sys.path when run
from golden import _timeless, git_head

RESULTS = Path(__file__).resolve().parent / "results" / "reproducibility.json"
#: OpenBLAS kernels to force and the CPU flag each needs (as tests/plugins/test_native_rnnpb.py).
CORETYPES = {"Nehalem": "sse4_2", "Haswell": "avx2", "SkylakeX": "avx512f"}


def _cpu() -> tuple[str, str]:
    """(model name, flags) from /proc/cpuinfo; empty strings where it is missing."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return "", ""
    model = next((line.split(":", 1)[1].strip() for line in text.splitlines()
                  if line.startswith("model name")), "")
    flags = next((line.split(":", 1)[1] for line in text.splitlines()
                  if line.startswith("flags")), "")
    return model, f" {flags} "


def _memory_checksum(path: Path) -> str:
    """SHA-256 (first 16 hex digits) of every array in a saved memory, by sorted name,
    but the JSON header (it names the install's URDF path)."""
    h = hashlib.sha256()
    with np.load(path, allow_pickle=False) as z:
        for name in sorted(n for n in z.files if n != "__header__"):
            a = z[name]
            h.update(name.encode())
            h.update(str(a.dtype).encode())
            h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def run_one(seed: int, isa: str, coretype: str, jobs: int, work: Path,
            python: str = sys.executable) -> dict[str, Any]:
    """One ``iloci evaluate`` with the given seed, instruction set, OpenBLAS kernel and
    Python interpreter (one with iloci and the default back ends installed)."""
    out = work / f"seed{seed}-{isa}-{coretype}-{hashlib.sha256(python.encode()).hexdigest()[:8]}"
    config = work / f"seed{seed}.toml"
    config.write_text(f"[evaluation]\nseed = {seed}\n")
    env = {k: v for k, v in os.environ.items() if k not in ("ILOCI_RNNPB_ISA", "OPENBLAS_CORETYPE")}
    if isa != "auto":
        env["ILOCI_RNNPB_ISA"] = isa
    if coretype != "auto":
        env["OPENBLAS_CORETYPE"] = coretype
    cmd = [python, "-m", "iloci", "evaluate", "--config", str(config), "--jobs", str(jobs),
           "--out", str(out), "--memories", str(out / "memories"), "--quiet"]
    t0 = time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}):\n{done.stderr[-3000:]}")
    versions = json.loads(subprocess.run(
        [python, "-c", "import json, platform; from importlib.metadata import version; "
         "print(json.dumps({'python': platform.python_version(), "
         "**{p: version(p) for p in ('numpy', 'scipy', 'pin')}}))"],
        capture_output=True, text=True, check=True).stdout)
    metrics = json.loads((out / "metrics.json").read_text())
    folds = _timeless(json.loads((out / "folds.json").read_text()))
    text = json.dumps(folds, sort_keys=True, allow_nan=True)
    memories = sorted((out / "memories").glob("fold-*.npz"))
    return {"seed": seed, "isa": isa, "openblas_coretype": coretype, "versions": versions,
            "command": " ".join(["iloci"] + cmd[3:]),
            "ccr_mean": metrics["ccr_mean"], "ccr_folds": metrics.get("ccr_folds"),
            "results_checksum": hashlib.sha256(text.encode()).hexdigest()[:16],
            "network_checksums": [_memory_checksum(m) for m in memories],
            "wall_seconds": wall}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--jobs", "-j", type=int, default=2)
    ap.add_argument("--out", default=str(RESULTS))
    ap.add_argument("--python", nargs="*", default=[],
                    help="other interpreters (with iloci installed) to run the first seed with")
    args = ap.parse_args(argv)

    from iloci_native.native import native_isas

    model, flags = _cpu()
    isas = list(native_isas())
    cores = [c for c, flag in CORETYPES.items() if f" {flag} " in flags]
    load_before = os.getloadavg()
    runs: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            ways = [(isa, "auto", sys.executable) for isa in isas]
            if seed == args.seeds[0]:  # the BLAS kernels and the Pythons on the first seed (time)
                ways += [("auto", c, sys.executable) for c in cores]
                ways += [("auto", "auto", py) for py in args.python]
            for isa, core, py in ways:
                rec = run_one(seed, isa, core, args.jobs, Path(tmp), py)
                runs.append(rec)
                print(f"seed {seed} isa {isa:8} openblas {core:8} "
                      f"python {rec['versions']['python']:7}: CCR {rec['ccr_mean']:.4f} "
                      f"results {rec['results_checksum']} networks "
                      f"{','.join(c[:8] for c in rec['network_checksums'])} "
                      f"({rec['wall_seconds']:.0f} s)", flush=True)
    identical = {}
    for seed in args.seeds:
        rows = [r for r in runs if r["seed"] == seed]
        identical[str(seed)] = len({(r["results_checksum"], tuple(r["network_checksums"]))
                                    for r in rows}) == 1
    from importlib.metadata import version
    result = {"command": "python benchmarks/reproducibility.py " + " ".join(argv or sys.argv[1:]),
              "runs": runs, "identical": identical, "git_head": git_head(),
              "machine": {"cpu": model, "isas": isas, "openblas_coretypes": cores,
                          "platform": platform.platform(), "cpus": os.cpu_count(),
                          "load_average_before": load_before,
                          "load_average_after": os.getloadavg()},
              "versions": {p: version(p) for p in ("numpy", "scipy", "pin")}}
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}; identical per seed: {identical}")
    return result


if __name__ == "__main__":
    main()
