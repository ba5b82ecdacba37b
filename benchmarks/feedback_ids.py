"""Answers with ids (issue 30): repeated and late feedback is refused and changes nothing.

Two agents learn the same LASA stream with the oracle's feedback through
the step-wise API (``Agent.observe``, ``Agent.feedback(value, answer_id)``),
as an event-driven stack would:

* ``once``   sends each feedback once;
* ``noisy``  sends every feedback twice (a bouncing button, a redelivered
             message) and, after each one, ``--late`` feedbacks for earlier
             answers (already judged, or of earlier turns), with the
             opposite value, as a late message would arrive.

Every duplicate and late feedback must be refused
(:class:`~iloci.errors.StaleAnswerError`) and change nothing: the two
memories must be identical (entries, PBs, numSamples, sources, counters and
the network's weights). Writes ``benchmarks/results/feedback_ids.json``:
feedbacks sent and taken, duplicates and late ones refused, whether the
memories are identical, and the time a refusal takes.

Run: ``python benchmarks/feedback_ids.py [--shapes 4] [--per-shape 4]
[--late 3] [--epochs 200]``.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results" / "feedback_ids.json"
SHAPES = ("GShape", "Angle", "Sine", "WShape", "Snake", "Leaf_1")


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shapes", type=int, default=4)
    ap.add_argument("--per-shape", type=int, default=4)
    ap.add_argument("--late", type=int, default=3, help="late feedbacks after each one")
    ap.add_argument("--epochs", type=int, default=200, help="torch-rnnpb epochs")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)

    import iloci
    from iloci.concepts.learner import show_to_teacher
    from iloci.concepts.memory import entries_equal
    from iloci.data import load_lasa
    from iloci.errors import StaleAnswerError

    config = {"perceptual_model": {"name": "torch-rnnpb", "epochs": args.epochs,
                                   "recognition_steps": args.epochs},
              "learner": {"rehearsal_epochs": args.epochs},
              "evaluation": {"seed": args.seed}}
    shapes = SHAPES[:args.shapes]
    demos = {d.key: d for d in load_lasa(list(shapes))}
    rng = np.random.default_rng(args.seed)
    stream = [demos[f"{s}/{i}"] for i in range(args.per_shape) for s in shapes]
    stream = [stream[i] for i in rng.permutation(len(stream))]

    once, noisy = iloci.build(config), iloci.build(config)
    sent = taken = duplicates = late = 0
    refusal_seconds: list[float] = []
    ids: list[str] = []
    t0 = time.perf_counter()
    for demo in stream:
        for agent in (once, noisy):
            show_to_teacher(agent.teacher, demo)
        turn = once.observe(demo)
        while not turn.done:
            turn.feedback(once.teacher.feedback(demo, turn.answer.response), turn.answer.id)
        noisy.observe(demo)
        while noisy.pending is not None:
            answer = noisy.pending
            value = noisy.teacher.feedback(demo, answer.response)
            noisy.feedback(value, answer.id)
            sent += 1
            taken += 1
            for kind, stale, v in [("duplicate", answer.id, value)] + [
                    ("late", old, -value) for old in ids[-args.late:]]:
                sent += 1
                t = time.perf_counter()
                try:
                    noisy.feedback(v, stale)
                except StaleAnswerError:
                    refusal_seconds.append(time.perf_counter() - t)
                    duplicates += kind == "duplicate"
                    late += kind == "late"
                else:
                    taken += 1
            ids.append(answer.id)
    wall = time.perf_counter() - t0

    a, b = once.memory, noisy.memory
    sa, sb = once.perceptual_model.state(), noisy.perceptual_model.state()
    identical = {
        "entries": entries_equal(a.entries, b.entries),
        "counters": (a.concept_count, a.demonstrations_seen,
                     [e.num_samples for e in a.entries], [e.sources for e in a.entries])
        == (b.concept_count, b.demonstrations_seen,
            [e.num_samples for e in b.entries], [e.sources for e in b.entries]),
        "network": set(sa) == set(sb) and all(np.array_equal(sa[k], sb[k]) for k in sa),
    }
    out = {
        "command": "python benchmarks/feedback_ids.py " + " ".join(argv or sys.argv[1:]),
        "demonstrations": len(stream), "shapes": list(shapes),
        "answers": len(ids), "feedbacks_sent": sent, "feedbacks_taken": taken,
        "duplicates_refused": duplicates, "late_refused": late,
        "memory_identical": identical, "concepts": len(b.concepts()), "entries": len(b),
        "refusal_seconds_median": float(np.median(refusal_seconds)),
        "refusal_seconds_max": float(np.max(refusal_seconds)),
        "wall_seconds": wall,
        "targets": {"memory_identical_to_feedback_once": all(identical.values()),
                    "every_repeated_or_late_feedback_refused": taken == len(ids)},
        "machine": {"python": platform.python_version(), "platform": platform.platform()},
    }
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps({k: out[k] for k in ("answers", "feedbacks_sent", "feedbacks_taken",
                                          "duplicates_refused", "late_refused",
                                          "memory_identical", "targets")}, indent=1))
    return out


if __name__ == "__main__":
    main()
