"""``iloci recognize``: the inference phase on demonstrations, with a saved memory."""

from __future__ import annotations

import argparse
import json
import sys

from iloci.agent import Agent
from iloci.data.files import TrajectoryFile
from iloci.data.streams import resolve_demos, shared_stem_notes

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "recognize", help="recognize the concept of demonstrations with a taught memory",
        description="Recognize each demonstration's concept (no feedback, the memory is not "
                    "changed): the concept of the memory entry whose PB_rec is nearest to the "
                    "demonstration's PB. Confidence is 1 - d_best / d_other, the margin to "
                    "the nearest entry of another concept (0: ambiguous, 1: clear).")
    p.add_argument("files", nargs="+", metavar="FILE",
                   help="trajectory files (.npy, .csv, .inkml, .xml), or LASA demonstrations as "
                        "SHAPE/INDEX")
    p.add_argument("--memory", metavar="FILE", required=True,
                   help="memory file written by `iloci teach`")
    p.add_argument("--json", action="store_true", help="print one JSON object per line")
    p.set_defaults(func=run)


def _number(x: float) -> float | None:
    """``x``, or None (JSON null) for NaN: ``NaN`` is not JSON, and strict readers refuse it."""
    return None if x != x else x


def run(args: argparse.Namespace) -> int:
    # recognition never clusters nor asks a teacher: their plugins need not be installed
    agent = Agent.load(args.memory, purpose="recognize")
    items = resolve_demos(args.files)
    for note in shared_stem_notes(items):
        print(f"note: {note}", file=sys.stderr)
    demos = [d.load() if isinstance(d, TrajectoryFile) else d for d in items]
    for r in agent.recognize(demos):
        if args.json:
            print(json.dumps({"demo": r.demo, "concept": r.concept,
                              "confidence": _number(r.confidence),
                              "distance": _number(r.distance),
                              "source": r.source, "sources": list(r.sources),
                              "familiarity": _number(r.familiarity),
                              "unknown": r.unknown, "tilt": r.tilt}, allow_nan=False))
        else:
            answer = (f"unknown (nearest concept {r.concept}, familiarity "
                      f"{r.familiarity:.2f})" if r.unknown else f"concept {r.concept}")
            turned = f"; read turned by {r.tilt:+g} degrees" if r.tilt else ""
            print(f"{r.demo}: {answer} (confidence {r.confidence:.2f}, PB distance "
                  f"{r.distance:.3f}; nearest entry stands for {r.source}{turned})")
    return 0
