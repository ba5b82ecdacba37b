"""``iloci teach``: learn concepts from a stream of demonstrations with feedback.

The memory is saved after every demonstration that changed it, atomically,
with how far through the stream the session got (see :mod:`iloci.progress`):
a session killed at any moment (even ``kill -9``) leaves a memory that
loads, and the same command run again resumes after the last demonstration
learned, ending with the memory an uninterrupted run gives. The memory file
is locked (``FILE.lock``) while it is taught: a second ``iloci teach`` on it
gets an error instead of racing the first.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
import contextlib
from pathlib import Path
import sys
from typing import Any
import warnings

from iloci.agent import Agent, SkippedDemonstrationWarning, build
from iloci.concepts.memory import load_memory
from iloci.config import ConfigData, load_config
from iloci.data.streams import default_stream, resolve_demos, shared_stem_notes
from iloci.data.writes import check_memory_path
from iloci.errors import IlociError, MemoryFileError, UnknownComponentError
from iloci.interfaces import Demonstration
from iloci.progress import (PROGRESS_KEY, item_digest, progress_record,
                            resume_point, teaching_lock, why_not_saved)

__all__ = ["register", "run"]

#: Memory file used when ``--memory`` is not given.
DEFAULT_MEMORY = "iloci-memory.npz"

#: The interactive protocol ``iloci teach`` and ``iloci serve`` use unless the
#: config sets these ``[learner]`` keys, or ``--protocol paper``: the novelty
#: answer ("Something new?"), asked again after 2 refused guesses, confirmed
#: rewards and new exemplars, and "unknown" under familiarity 0.8.
#: Measured in ``benchmarks/results/quality.json``: row ``best`` (the same
#: CCR as the paper's protocol on the same folds, 1.88 instead of 7.14
#: feedbacks per demonstration; with a teacher wrong 10 % of the time 99.2 %
#: instead of 52.5 %) and row ``untaught`` (91 % of never-taught shapes
#: answered unknown, 1.8 % of taught ones, with the familiarity of then,
#: ``"reproduction"``; the default ``"path"``: benchmarks/familiarity.py).
#: ``iloci evaluate`` keeps the paper's protocol (the config's own defaults).
INTERACTIVE = {"novelty_below": 0.8, "novelty_after": 2, "confirm_rewards": True,
               "confirm_new_exemplars": True, "confirm_twice_after_novelty": True,
               "unknown_below": 0.8}

#: The page's (``iloci serve``) interactive protocol: "unknown" under
#: familiarity 0.8 (quality.json row ``untaught``); a person founds a concept
#: with the page's "Something new" button and takes back a slip with Undo, so
#: the novelty answer and the confirmations stay off. Measured by
#: ``benchmarks/serve.py`` (``serve.json``, ``teaching``): founding 8 concepts
#: took 7 clicks and the first guess was right 24 of 24 times afterwards, as
#: with the paper's protocol (28 clicks); with :data:`INTERACTIVE` and the
#: button, 7 clicks too but 22 of 24 (the novelty answer came first twice for a
#: taught shape) and more clicks in all (50 against 31: the confirmations).
PAGE = {"unknown_below": 0.8}


def add_protocol_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("--protocol", choices=("interactive", "paper"), default="interactive",
                   help="interactive (default): 'unknown' for a drawing like nothing taught "
                        "and, for iloci teach, the novelty answer and confirmations (where the "
                        "config does not set these [learner] keys); paper: the paper's "
                        "protocol (the config as is)")


def command_config(config: Any, header: dict | None, protocol: str = "interactive",
                   interactive: Mapping[str, Any] = INTERACTIVE,
                   memory: str | Path | None = None):
    """The config a teaching command uses: ``--config``, else the memory's, else the defaults.

    With the interactive protocol, ``interactive`` (:data:`INTERACTIVE` for
    ``iloci teach``, :data:`PAGE` for ``iloci serve``) fills the ``[learner]``
    keys ``--config`` does not set (a memory's saved config is used as saved:
    it is what the memory was taught with).
    """
    if config:
        cfg = load_config(config)
        if isinstance(config, Mapping):
            learner = config.get("learner")
            given = set(learner) if isinstance(learner, Mapping) else set()
        else:
            given = _learner_keys(config)
    elif header is not None and isinstance(header.get("config"), dict):
        saved = ConfigData(header["config"])  # its errors name the memory, not "<dict>"
        saved.source = f"{memory} (its saved config)" if memory else "the memory's config"
        return load_config(saved)
    else:
        cfg = load_config(None)
        given = set()
    if protocol != "interactive":
        return cfg
    changes = {k: v for k, v in interactive.items() if k not in given}
    return cfg.replace(learner=changes) if changes else cfg


def _learner_keys(path: str) -> set[str]:
    """The ``[learner]`` keys a TOML file sets (every key when it cannot be read again)."""
    import tomllib
    try:
        with open(path, "rb") as fh:
            data = tomllib.loads(fh.read().decode("utf-8-sig"))
    except (OSError, ValueError):
        return set(INTERACTIVE)
    learner = data.get("learner")
    return set(learner) if isinstance(learner, dict) else set()


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "teach", help="teach the robot concepts from demonstrations, with feedback",
        description="Show demonstrations to the robot one at a time. For each one it guesses "
                    "a concept and performs it; the teacher rewards (+1) or punishes (-1) the "
                    "answer and the robot updates its memory, which is saved after every "
                    "change. With an existing --memory file, learning continues from it.")
    p.add_argument("demos", nargs="*", metavar="DEMO",
                   help="LASA demonstrations as SHAPE/INDEX (e.g. GShape/3) or SHAPE (all 7), "
                        "or trajectory files (.npy, .csv, .inkml, .xml); default: a seeded "
                        "stream of [evaluation] train_fraction of each [data] shape's "
                        "demonstrations")
    p.add_argument("--config", metavar="FILE",
                   help="TOML config (default: the one saved in --memory, else the defaults)")
    p.add_argument("--teacher", metavar="NAME",
                   help="teacher to use: console (asks you), oracle or noisy (default: the "
                        "config's)")
    p.add_argument("--memory", metavar="FILE", default=DEFAULT_MEMORY,
                   help=f"memory file to continue from and save to (default {DEFAULT_MEMORY}); "
                        "locked while teaching (FILE.lock)")
    add_protocol_argument(p)
    p.add_argument("--again", action="store_true",
                   help="go through every demonstration given, not only those after where an "
                        "interrupted earlier run of the same stream stopped; one the memory "
                        "already learned (same key and pen positions) is not learned again")
    p.set_defaults(func=run)


def _show_earlier(agent, items) -> None:
    """Show the teacher the stream's demonstrations an earlier run learned.

    A teacher that judges answers by the demonstrations the memory's entries
    stand for (the oracle) must have seen them; a resumed run skips them.
    One that cannot be read or has no concept the teacher knows is left out
    (it was skipped or refused when it was taught).
    """
    # the learner imports scipy: loaded when the command runs
    from iloci.concepts.learner import show_to_teacher
    for item in items:
        try:
            demo = item.load() if hasattr(item, "load") else item
            if isinstance(demo, Demonstration):
                show_to_teacher(agent.teacher, demo)
        except IlociError:
            continue


def _describe(outcome) -> str:
    steps = []
    previous = None
    for ev in outcome.events:
        if ev.extra.get("novel") and ev.feedback:
            steps.append(f"something new ({'+1' if ev.feedback == 1 else '-1'})")
        elif ev.guessed is not None:
            # the event after a "confirm" is the teacher's answer when asked again
            again = " again" if previous == "confirm" else ""
            steps.append(f"{ev.guessed}{again} ({'+1' if ev.feedback == 1 else '-1'})")
        previous = ev.action
    guesses = "guessed " + ", ".join(steps) if steps else "no concept to guess"
    what = {"strengthen": f"strengthened an entry of {outcome.concept}",
            "new_exemplar": f"new exemplar of {outcome.concept}",
            "new_concept": f"new concept {outcome.concept}"}[outcome.action]
    if outcome.clustered:
        what += f", {outcome.clustered} cluster(s) replaced by their medoid"
    secs = sum(r.seconds for r in outcome.rehearsals)
    tail = f" [rehearsal {secs:.1f} s]" if outcome.rehearsals else ""
    return f"{outcome.demo}: {guesses} -> {what}{tail}"


def run(args: argparse.Namespace) -> int:
    memory_path = check_memory_path(args.memory)  # before anything is learned
    with teaching_lock(memory_path):
        return _teach(args, memory_path)


def _teach(args: argparse.Namespace, memory_path: Path) -> int:
    # rich: loaded when the command runs
    from iloci.display import Bars

    header = load_memory(memory_path)[2] if memory_path.exists() else None
    cfg = command_config(args.config, header, getattr(args, "protocol", "interactive"),
                         memory=memory_path)
    if args.teacher:
        try:
            cfg = cfg.replace(teacher={"name": args.teacher})
        except UnknownComponentError as exc:
            # the flag's value, not the config file (its name led the message)
            exc.args = (f"--teacher {args.teacher}: "
                        f"{str(exc).partition('[teacher] name: ')[2] or exc}",)
            raise
    items = resolve_demos(args.demos) if args.demos else default_stream(cfg)
    for note in shared_stem_notes(items):
        print(f"note: {note}", file=sys.stderr)
    digests = [item_digest(i) for i in items]
    done = 0
    if header is not None and not args.again:
        done = resume_point(header.get(PROGRESS_KEY), digests)
    agent = Agent.load(memory_path, cfg) if header is not None else build(cfg)
    if header is not None:
        print(f"continuing from {memory_path}: {agent.memory.summary().splitlines()[0]}")
    if done == len(items) and items:
        print(f"nothing to teach: all {done} demonstration(s) of this stream were learned "
              "by an earlier run.\n"
              f"{agent.memory.summary()}\nmemory unchanged ({memory_path})")
        return 0
    if done:
        print(f"resuming: the first {done} of the {len(items)} demonstration(s) of this "
              "stream were learned by an earlier, interrupted run; teaching the other "
              f"{len(items) - done}.")
    keys = [getattr(i, "key", None) for i in items]
    position = [done]  # stream items consumed, up to the last one learned
    # A bar over the stream on a terminal or in a notebook (stderr); a log gets
    # the line per demonstration below and nothing else. None with the
    # console teacher, whose questions need the terminal.
    bars = Bars(unit="demos") if cfg.teacher.name != "console" else None
    if bars is not None and not bars.live:
        bars = None
    shown = [done]  # a resumed stream's bar starts where the earlier run stopped

    def advance() -> None:
        shown[0] += 1
        if bars is not None:
            bars.update("teach", shown[0])

    def save(outcome) -> None:
        # the learned item is the next one of the stream with the outcome's key
        # (items in between that produced no outcome were skipped)
        i = position[0]
        while i < len(items) and keys[i] != outcome.demo:
            i += 1
        position[0] = min(i + 1, len(items))
        try:
            agent.save(memory_path, extra={PROGRESS_KEY: progress_record(digests, position[0])})
        except OSError as exc:
            before = "no memory yet" if not memory_path.exists() else \
                "the memory as it was before it"
            raise MemoryFileError(
                f"{why_not_saved(memory_path, exc)} {outcome.demo} was learned but not saved: "
                f"{memory_path} still holds {before} (every demonstration saved so far is "
                "kept). Free some space or fix the permissions and run the same command "
                "again: it goes on after the last saved demonstration.") from None
        print(_describe(outcome), flush=True)
        advance()

    def show_skip(message, category, filename, lineno, file=None, line=None) -> None:
        print(f"warning: {message}", file=sys.stderr, flush=True)
        advance()

    with warnings.catch_warnings(), bars or contextlib.nullcontext():
        if bars is not None:
            bars.add("teach", "teaching", len(items))
            bars.update("teach", done)
        warnings.simplefilter("always", SkippedDemonstrationWarning)
        warnings.showwarning = show_skip
        _show_earlier(agent, items[:done])
        report = agent.teach(items[done:], on_change=save)
    fb = report.feedbacks
    rewarded = sum(f == 1 for f in fb)
    known = report.already_learned
    learned = len(report.outcomes) - len(known)
    if known:
        print(f"already learned, not learned again (the same key and pen positions): "
              f"{', '.join(known)}")
    print(f"learned {learned} demonstration(s) in {report.seconds:.1f} s, "
          + (f"{len(known)} already learned, " if known else "")
          + f"{len(report.skipped)} skipped; {rewarded}/{len(fb)} answers rewarded.")
    print(agent.memory.summary())
    print(f"memory saved to {memory_path}" if learned else
          f"memory unchanged ({memory_path})")
    return 0 if report.outcomes or not report.skipped else 2
