"""Fault drill for ``iloci sweep`` on a Ray started on this machine (issue 29).

1. *Worker killed*: a sweep of 8 runs (4 ``learner.k_cutoff`` values x 2 folds,
   2 LASA shapes, 60 epochs, 2 at once) whose first ``ray::fold_run`` worker
   is sent SIGKILL a few seconds into its run, as the out-of-memory killer does.
   Expected: exit 0, 8 runs stored, 1 of them after a retry, and no process of
   the sweep's session left once it has ended.
2. *Driver killed*: the same sweep in a new folder, its driver (``iloci sweep``
   itself) sent SIGKILL while runs are in flight; the Ray processes it leaves
   are counted, then the same command is started again: it must stop them
   first and finish the sweep (8 runs stored), leaving nothing behind.
3. *Ctrl-C*: a third sweep sent SIGINT while runs are in flight: exit 130 and
   nothing left.

Every sweep runs in its own session (``setsid``); "left" is a process of that
session, or one naming the sweep's Ray session directory, alive after it ended.

Usage (writes benchmarks/results/ray_sweep_drill.json)::

    nice -n 10 python benchmarks/ray_sweep_drill.py
"""

from __future__ import annotations

import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
import time

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results" / "ray_sweep_drill.json"
FAST = """[perceptual_model]
epochs = 60
[learner]
rehearsal_epochs = 60
[data]
shapes = ["GShape", "Sine"]
[evaluation]
folds = 2
"""
SPEC = 'base = "fast.toml"\nseeds = [0]\n[values]\n"learner.k_cutoff" = [0.25, 0.5, 1.0, 2.0]\n'


def procs() -> dict[int, tuple[int, str]]:
    """pid -> (session id, command line) of every process."""
    out = {}
    for d in Path("/proc").glob("[0-9]*"):
        try:
            stat = (d / "stat").read_text().rpartition(")")[2].split()
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if stat[0] not in ("Z", "X"):
            out[int(d.name)] = (int(stat[3]), cmd)
    return out


def left(sid: int, sessions: set[str]) -> list[str]:
    return [f"{p} {c[:120]}" for p, (s, c) in procs().items()
            if p != os.getpid() and (s == sid or any(x in c for x in sessions))]


def ray_sessions(pid: int) -> set[str]:
    """Ray session directories whose name ends with the driver's pid."""
    return {str(p) for p in Path("/tmp/ray").glob(f"session_*_{pid}")}


def start(folder: Path, extra: tuple[str, ...] = ()) -> subprocess.Popen:
    iloci = Path(sys.executable).with_name("iloci")
    # SIGINT as a terminal gives it, even when this drill runs as a background job (whose
    # children inherit SIGINT ignored, and Python then never turns it into Ctrl-C)
    return subprocess.Popen(["setsid", "nice", "-n", "10", str(iloci), "sweep", "spec.toml",
                             "--out", "out", "--jobs", "2", "-q", *extra], cwd=folder,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def worker(sid: int, timeout: float = 180) -> int | None:
    t = time.monotonic()
    while time.monotonic() - t < timeout:
        for p, (s, c) in procs().items():
            if s == sid and c.startswith("ray::fold_run"):
                return p
        time.sleep(0.5)
    return None


def stored(folder: Path) -> int:
    return len(list((folder / "out" / "runs").glob("*.json")))


def folder(base: Path, name: str) -> Path:
    f = base / name
    f.mkdir()
    (f / "fast.toml").write_text(FAST)
    (f / "spec.toml").write_text(SPEC)
    return f


def main() -> None:
    res: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp)
        # 1. a worker killed
        f = folder(base, "worker")
        t0 = time.perf_counter()
        d = start(f)
        w = worker(d.pid)
        time.sleep(3)
        os.kill(w, signal.SIGKILL)
        log = d.communicate(timeout=1800)[0]
        time.sleep(2)
        res["worker_killed"] = {
            "exit": d.returncode, "runs_stored": stored(f), "runs_planned": 8,
            "summary": [ln for ln in log.splitlines() if "runs:" in ln or "failed" in ln][:3],
            "retried": json.loads((f / "out" / "summary.json").read_text())["info"]["retried"],
            "left_after": left(d.pid, ray_sessions(d.pid)),
            "wall_seconds": round(time.perf_counter() - t0, 1)}
        # 2. the driver killed, then the same command again
        f = folder(base, "driver")
        d = start(f)
        worker(d.pid)
        time.sleep(3)
        os.kill(d.pid, signal.SIGKILL)
        d.wait()
        time.sleep(5)
        orphans = left(d.pid, ray_sessions(d.pid))
        before = stored(f)
        d2 = start(f)
        log2 = d2.communicate(timeout=1800)[0]
        time.sleep(2)
        res["driver_killed"] = {
            "runs_stored_at_kill": before, "left_after_kill_9": orphans,
            "left_after_kill_9_and_next_start": left(d.pid, ray_sessions(d.pid)),
            "next_exit": d2.returncode, "runs_stored": stored(f),
            "left_after_next": left(d2.pid, ray_sessions(d2.pid)),
            "summary": [ln for ln in log2.splitlines() if "runs:" in ln][:1]}
        # 3. Ctrl-C
        f = folder(base, "ctrl_c")
        d = start(f)
        worker(d.pid)
        time.sleep(3)
        os.kill(d.pid, signal.SIGINT)
        log3 = d.communicate(timeout=300)[0]
        time.sleep(2)
        res["ctrl_c"] = {"exit": d.returncode, "runs_stored": stored(f),
                         "last_line": (log3.strip().splitlines() or [""])[-1][:200],
                         "left_after": left(d.pid, ray_sessions(d.pid))}
    res["python"] = sys.version.split()[0]
    OUT.write_text(json.dumps(res, indent=1) + "\n")
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
