"""Kill -9 drill for ``iloci teach``: crash at random moments, resume, compare.

1. Teach a small memory from a fixed stream, uninterrupted: the reference.
2. Teach the same stream into another memory file, sending SIGKILL to the
   process at a random moment (seeded), then run the same command again,
   and again, until ``--kills`` kills have landed. After every kill the
   memory file (if one was written yet) must load. Each time a run finishes,
   its memory must equal the reference: the same entries (PB, PB_rec,
   numSamples, sources, ...), the same network weights and the same
   counters; then the next round starts from no memory.
3. While one run teaches, a second ``iloci teach`` on the same memory must
   fail with exit 2 and the lock error, changing nothing.

Usage (writes benchmarks/results/teach_kill_drill.json)::

    nice -n 10 python benchmarks/teach_kill_drill.py [--kills 20] [--seed 0]

The machine may be shared: only the outcome counts, not the timings.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

CONFIG = """\
[perceptual_model]
name = "torch-rnnpb"
hidden = 20
epochs = 80
[learner]
rehearsal_epochs = 80
num_threshold = 2
[data]
shapes = ["GShape", "Angle", "Sine", "Leaf_1"]
"""

STREAM = ["GShape/0", "Angle/1", "Sine/2", "GShape/3", "Leaf_1/4", "Angle/5", "Sine/6",
          "GShape/1", "Leaf_1/2", "Angle/3"]


def teach_cmd(memory: Path, config: Path) -> list[str]:
    return [sys.executable, "-m", "iloci", "teach", "--config", str(config),
            "--memory", str(memory), *STREAM]


def compare(a: Path, b: Path) -> dict:
    """Whether two memory files hold the same memory and network."""
    from iloci.concepts.memory import entries_equal, load_memory
    ma, na, ha = load_memory(a)
    mb, nb, hb = load_memory(b)
    same_net = set(na) == set(nb) and all(np.array_equal(na[k], nb[k]) for k in na)
    return {
        "entries_equal": entries_equal(ma.entries, mb.entries),
        "network_equal": bool(same_net),
        "counters_equal": (ma.concept_count, ma.demonstrations_seen)
        == (mb.concept_count, mb.demonstrations_seen),
        "encoder_equal": bool(np.array_equal(ma.encoder.scale_, mb.encoder.scale_)),
        "config_equal": ha.get("config") == hb.get("config"),
        "demonstrations_seen": mb.demonstrations_seen,
        "entries": len(mb.entries),
    }


def loads(path: Path) -> tuple[bool, str, int | None]:
    from iloci.concepts.memory import load_memory
    try:
        memory, _, header = load_memory(path)
    except Exception as exc:  # the drill records any failure, of any type
        return False, f"{type(exc).__name__}: {exc}", None
    progress = header.get("teach_progress") or {}
    return True, f"{len(memory.entries)} entries", progress.get("items")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kills", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" /
                                         "teach_kill_drill.json"))
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    work = Path(tempfile.mkdtemp(prefix="iloci-kill-drill-"))
    config = work / "drill.toml"
    config.write_text(CONFIG)
    env = dict(os.environ, PYTHONHASHSEED="0", OMP_NUM_THREADS="1")

    ref = work / "reference.npz"
    t0 = time.perf_counter()
    out = subprocess.run(teach_cmd(ref, config), capture_output=True, text=True, env=env)
    ref_seconds = time.perf_counter() - t0
    if out.returncode != 0:
        print(out.stdout, out.stderr)
        return 1
    print(f"reference run: {ref_seconds:.1f} s", flush=True)

    mem = work / "drill.npz"
    kills: list[dict] = []
    rounds: list[dict] = []
    runs = 0
    lock_check: dict | None = None
    # kills land uniformly over a whole run from no memory (re-measured on every
    # such run: the machine is shared); a rerun after a kill resumes, so it is
    # shorter, and the kill time may fall after it ends: then the round is complete
    # and is compared with the reference
    full_seconds = ref_seconds
    while len(kills) < args.kills:
        delay = float(rng.uniform(0.0, full_seconds))
        fresh = not mem.exists()
        started = time.perf_counter()
        proc = subprocess.Popen(teach_cmd(mem, config), stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, env=env,
                                start_new_session=True)
        runs += 1
        if lock_check is None and delay > 0.5 * ref_seconds:
            # a second process on the same memory while this one teaches
            time.sleep(0.4 * ref_seconds)
            second = subprocess.run(teach_cmd(mem, config), capture_output=True, text=True,
                                    env=env)
            lock_check = {"second_process_exit": second.returncode,
                          "first_still_running": proc.poll() is None,
                          "error": second.stderr.strip().splitlines()[-1:]}
            delay -= 0.4 * ref_seconds
        try:
            proc.wait(timeout=delay)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            exists = mem.exists()
            ok, what, items = loads(mem) if exists else (True, "no memory yet", 0)
            kills.append({"after_s": round(delay, 2), "memory_exists": exists,
                          "loads": ok, "memory": what, "stream_items_done": items})
            print(f"kill {len(kills)} at {delay:.1f} s: {what}, items done {items}",
                  flush=True)
            continue
        stdout, stderr = proc.communicate()
        if proc.returncode != 0:
            print(stdout, stderr)
            return 1
        if fresh:  # a whole run from no memory: how long one takes now
            full_seconds = time.perf_counter() - started
        result = compare(ref, mem)
        result["kills_in_round"] = len(kills) - sum(r["kills_in_round"] for r in rounds)
        result["resumed"] = "resuming:" in stdout
        rounds.append(result)
        print(f"round {len(rounds)} finished: {result}", flush=True)
        mem.unlink()
    # finish the last round after the last kill
    stdout = subprocess.run(teach_cmd(mem, config), capture_output=True, text=True,
                            env=env).stdout
    final = compare(ref, mem)
    final["kills_in_round"] = len(kills) - sum(r["kills_in_round"] for r in rounds)
    final["resumed"] = "resuming:" in stdout or "nothing to teach" in stdout
    rounds.append(final)
    equal = all(r["entries_equal"] and r["network_equal"] and r["counters_equal"]
                and r["encoder_equal"] and r["config_equal"] for r in rounds)
    report = {
        "what": "iloci teach killed with SIGKILL at random moments, then rerun; "
                "memory compared with an uninterrupted run",
        "command": "nice -n 10 python benchmarks/teach_kill_drill.py --kills "
                   f"{args.kills} --seed {args.seed}",
        "stream": STREAM, "config": CONFIG, "reference_seconds": round(ref_seconds, 1),
        "kills": kills, "runs": runs + 1, "rounds": rounds,
        "all_kills_left_a_loadable_memory": all(k["loads"] for k in kills),
        "every_round_equals_the_uninterrupted_run": equal,
        "lock": lock_check,
        "note": "shared machine: timings are not comparable between runs",
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(report, indent=2) + "\n")
    print(json.dumps({k: report[k] for k in ("all_kills_left_a_loadable_memory",
                                             "every_round_equals_the_uninterrupted_run",
                                             "lock")}, indent=2))
    return 0 if equal and report["all_kills_left_a_loadable_memory"] else 1


if __name__ == "__main__":
    sys.exit(main())
