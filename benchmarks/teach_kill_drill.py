"""Kill -9 drill for ``iloci teach``: crash at random moments, resume, compare.

1. Teach a small memory from a fixed stream, uninterrupted: the reference.
2. Teach the same stream into another memory file, sending SIGKILL to the
   process at a random moment (seeded), then run the same command again,
   and again, until ``--kills`` kills have landed. After every kill the
   memory file (if one was written yet) must load. Each time a run finishes,
   its memory must equal the reference: the same entries (PB, PB_rec,
   numSamples, sources, ...), the same network weights and the same
   counters; then the next round starts from no memory.
3. While one run teaches (it has learned its first demonstration and is
   paused with SIGSTOP, so it surely still runs), a second ``iloci teach`` on
   the same memory must fail with exit 2 and the lock error; the first then
   finishes its stream.

Kill moments: each kill waits for a random number (0 to all that are left)
of demonstrations to be learned in the run it hits, then a random fraction
of one demonstration's time (of start-up, for 0), so kills land anywhere in
the stream and in any phase: start-up, learning, rehearsal, saving.

Usage (writes benchmarks/results/teach_kill_drill.json)::

    nice -n 10 python benchmarks/teach_kill_drill.py [--kills 20] [--seed 0]

The machine may be shared: only the outcome counts, not the timings.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

CONFIG = """\
[perceptual_model]
name = "torch-rnnpb"
hidden = 30
epochs = 400
[learner]
rehearsal_epochs = 400
num_threshold = 2
[data]
shapes = ["GShape", "Angle", "Sine", "Leaf_1"]
"""

STREAM = ["GShape/0", "Angle/1", "Sine/2", "GShape/3", "Leaf_1/4", "Angle/5", "Sine/6",
          "GShape/1", "Leaf_1/2", "Angle/3"]


def teach_cmd(memory: Path, config: Path) -> list[str]:
    return [sys.executable, "-m", "iloci", "teach", "--config", str(config),
            "--memory", str(memory), *STREAM]


class Run:
    """An ``iloci teach`` process whose stdout lines are timed as they arrive."""

    LEARNED = re.compile(r"^\S+/\d+: ")  # "GShape/0: guessed ... -> ..." per demonstration

    def __init__(self, cmd: list[str], env: dict) -> None:
        self.started = time.monotonic()
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, env=env, start_new_session=True)
        self.lines: list[str] = []
        self.learned: list[float] = []
        self._err: list[str] = []
        self._out = threading.Thread(target=self._read, daemon=True)
        self._out.start()
        self._errt = threading.Thread(target=lambda: self._err.extend(self.proc.stderr),
                                      daemon=True)
        self._errt.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line)
            if self.LEARNED.match(line):
                self.learned.append(time.monotonic())

    def wait_for_learned(self, n: int) -> None:
        """Until ``n`` demonstrations are learned in this run, or it ends."""
        while len(self.learned) < n and self.proc.poll() is None:
            time.sleep(0.02)

    def kill(self) -> bool:
        """SIGKILL the process group if it still runs; True if it was killed."""
        if self.proc.poll() is not None:
            self.wait()
            return False
        os.killpg(self.proc.pid, signal.SIGKILL)
        self.wait()
        return True

    def wait(self) -> int:
        code = self.proc.wait()
        self._out.join()
        self._errt.join()
        return code

    def output(self) -> str:
        return "".join(self.lines)

    def errors(self) -> str:
        return "".join(self._err)


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


def round_result(ref, mem, run, n_kills: int, rounds: list) -> dict:
    """A finished round: the memory compared with the reference, the kills it took, how it ended."""
    result = compare(ref, mem)
    result["kills_in_round"] = n_kills - sum(r["kills_in_round"] for r in rounds)
    result["last_run"] = ("resumed" if "resuming:" in run.output() else
                          "nothing left" if "nothing to teach" in run.output() else
                          "whole stream")
    return result


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
    ref_run = Run(teach_cmd(ref, config), env)
    if ref_run.wait() != 0:
        print(ref_run.output(), ref_run.errors())
        return 1
    ref_seconds = time.perf_counter() - t0
    startup = ref_run.learned[0] - ref_run.started
    per_demo = (ref_run.learned[-1] - ref_run.learned[0]) / max(1, len(STREAM) - 1)
    print(f"reference run: {ref_seconds:.1f} s (first demonstration learned after "
          f"{startup:.1f} s, then {per_demo:.1f} s per demonstration)", flush=True)

    # the lock: a second process on a memory another one is teaching
    locked = work / "locked.npz"
    first = Run(teach_cmd(locked, config), env)
    first.wait_for_learned(1)
    os.killpg(first.proc.pid, signal.SIGSTOP)  # paused mid-stream, holding the lock
    second = subprocess.run(teach_cmd(locked, config), capture_output=True, text=True,
                            env=env, check=False)
    lock_check = {"first_was_teaching": first.proc.poll() is None,
                  "second_process_exit": second.returncode,
                  "second_process_error": second.stderr.strip().splitlines()[-1:]}
    os.killpg(first.proc.pid, signal.SIGCONT)
    lock_check["first_exit"] = first.wait()
    lock_check["first_learned"] = len(first.learned)

    # kills: each at a random moment of the run it hits, spread over the stream:
    # after a random number of the demonstrations still to learn have been
    # learned (0: during start-up or the first one), then a random fraction of
    # one demonstration's time, so a kill lands in start-up, learning, rehearsal,
    # clustering or saving alike
    mem = work / "drill.npz"
    kills: list[dict] = []
    rounds: list[dict] = []
    runs = 0
    while len(kills) < args.kills:
        done_before = (loads(mem)[2] if mem.exists() else 0) or 0
        remaining = len(STREAM) - done_before
        # with nothing left to learn, the next run only says so (not a kill target)
        wait_learned = int(rng.integers(0, remaining + 1)) if remaining else len(STREAM)
        extra = float(rng.uniform(0.0, startup if wait_learned == 0 else per_demo))
        run = Run(teach_cmd(mem, config), env)
        runs += 1
        run.wait_for_learned(wait_learned)
        time.sleep(extra)
        if run.kill():
            exists = mem.exists()
            ok, what, items = loads(mem) if exists else (True, "no memory yet", 0)
            kills.append({"after_learned_in_run": len(run.learned),
                          "then_s": round(extra, 2),
                          "after_s": round(time.monotonic() - run.started, 2),
                          "stream_items_done_before": done_before,
                          "memory_exists": exists, "loads": ok, "memory": what,
                          "stream_items_done": items})
            print(f"kill {len(kills)}: {len(run.learned)} learned in this run + "
                  f"{extra:.1f} s; memory: {what}, stream items done {done_before} -> "
                  f"{items}", flush=True)
            continue
        if run.proc.returncode != 0:
            print(run.output(), run.errors())
            return 1
        result = round_result(ref, mem, run, len(kills), rounds)
        rounds.append(result)
        print(f"round {len(rounds)} finished: {result}", flush=True)
        mem.unlink()
    # finish the last round after the last kill
    last = Run(teach_cmd(mem, config), env)
    if last.wait() != 0:
        print(last.output(), last.errors())
        return 1
    rounds.append(round_result(ref, mem, last, len(kills), rounds))
    runs += 1
    equal = all(r["entries_equal"] and r["network_equal"] and r["counters_equal"]
                and r["encoder_equal"] and r["config_equal"] for r in rounds)
    report = {
        "what": "iloci teach killed with SIGKILL at random moments, then rerun; "
                "memory compared with an uninterrupted run",
        "command": "nice -n 10 python benchmarks/teach_kill_drill.py --kills "
                   f"{args.kills} --seed {args.seed}",
        "stream": STREAM, "config": CONFIG, "reference_seconds": round(ref_seconds, 1),
        "kills": kills, "runs": runs, "rounds": rounds,
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
    lock_ok = lock_check["first_was_teaching"] and lock_check["second_process_exit"] == 2
    report["lock_refused_the_second_process"] = bool(lock_ok)
    Path(args.out).write_text(json.dumps(report, indent=2) + "\n")
    return 0 if equal and report["all_kills_left_a_loadable_memory"] and lock_ok else 1


if __name__ == "__main__":
    sys.exit(main())
