"""The online protocol: test-then-learn over every demonstration (``protocol = "stream"``).

Every LASA demonstration is shown once, in a seeded random order. Each is
first *recognized* without feedback and scored (the robot's answer before
it learns from it, as online-learning libraries evaluate a stream:
prequential or "test-then-train" evaluation, Gama et al., *On evaluating
stream learning algorithms*, Machine Learning 90, 2013), then *taught* with
the configured teacher. The robot's answer is its own concept label, named
by the true concept of most of the demonstrations that concept stands for
*at that moment*
(:func:`~iloci.evaluation.metrics.majority_names`). It is right when that
name is the demonstration's true concept, or, when it answers "unknown"
(``[learner] unknown_below``), when the true concept is none of the
memory's. A demonstration of a concept the robot has never been taught is
therefore always wrong unless recognition can say "unknown".

The sensorimotor encoder's scales are fitted on the motions of the whole
stream before the first demonstration (joint and plane ranges, no labels),
as :meth:`~iloci.agent.Agent.teach` does.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
import time
from typing import Any

import numpy as np

from iloci.agent import build
from iloci.config import Config, load_config
from iloci.data import load_lasa
from iloci.data.concepts import GroundTruth, majority_names
from iloci.data.datasets import load_dataset_once
from iloci.evaluation.evaluate import check_drawings
from iloci.evaluation.metrics import mean_std, purity
from iloci.evaluation.summary import data_set_records
from iloci.plugins import get_plugin_manager, get_registry

__all__ = ["StreamStep", "stream_order", "run_stream", "summarize_stream", "FIRST_SCORED"]

#: Stream position (1-based) from which first-guess accuracy is summarised:
#: the paper reports its first guess right 85 % of the time after 45
#: demonstrations.
FIRST_SCORED = 46


@dataclass
class StreamStep:
    """One demonstration of the stream: scored, then taught.

    Attributes
    ----------
    demo : str
        Its key.
    true : str
        Its true concept.
    answer : str or None
        The robot's own label before learning (``None``: empty memory).
    predicted : str
        The answer's name (majority naming at that moment), ``"unknown"``
        when recognition said so, ``"none"`` for an empty memory.
    correct : bool
    seen_before : bool
        Whether the memory already named the true concept.
    confidence, distance, error : float
        Of the recognition (NaN for an empty memory).
    feedbacks : list of int
        Every feedback the teacher gave while it was taught.
    action : str
        The learning outcome's action.
    concepts : int
        Robot concepts after it was taught.
    seconds : float
        Recognition plus learning wall time.
    """

    demo: str
    true: str
    answer: str | None
    predicted: str
    correct: bool
    seen_before: bool
    confidence: float
    distance: float
    error: float
    feedbacks: list[int]
    action: str
    concepts: int
    seconds: float


def stream_order(n: int, seed: int) -> list[int]:
    """The seeded presentation order of ``n`` demonstrations."""
    return [int(i) for i in np.random.default_rng([seed, 3]).permutation(n)]


def run_stream(config: Any = None, *, progress: Callable[[dict], None] | None = None,
               plugin_manager: Any = None, limit: int | None = None
               ) -> tuple[dict[str, Any], list[dict]]:
    """Run the test-then-learn protocol; return (metrics, per-demonstration steps).

    Parameters
    ----------
    config : Config, path, mapping or None
    progress : callable, optional
        Receives ``{"kind": "stream", "step": i, "total": n, "correct": bool}``.
    plugin_manager : pluggy.PluginManager, optional
    limit : int, optional
        Stop after this many demonstrations (for tests).

    Returns
    -------
    (dict, list of dict)
        ``metrics.json``'s content (:func:`summarize_stream`, with the
        memory's ``purity``, ``concepts``, ``entries``, and the data's
        records, :func:`~iloci.evaluation.summary.data_set_records`:
        ``dataset``, and with ``[data] path`` each sample's file, concept,
        writer and session under ``samples``), and one :class:`StreamStep`
        as a dict per demonstration (``stream.json``), in stream order.
    """

    pm = plugin_manager or get_plugin_manager()
    config = load_config(config, registry=get_registry(pm))
    dataset = None
    if config.data.path:  # a data set of the user's own (read once: the CLI read it too)
        dataset = load_dataset_once(config.data.path, warn=True)
        check_drawings(dataset, config)  # as the folds protocol: before anything is learned
        demos = dataset.demos
    else:
        demos = load_lasa(list(config.data.shapes) or None)
    order = stream_order(len(demos), config.evaluation.seed)
    if limit is not None:
        order = order[:limit]
    stream = [demos[i] for i in order]
    truth = GroundTruth(stream)

    t0 = time.perf_counter()
    agent = build(config, plugin_manager=pm)
    motions = [agent.motion(d) for d in stream]
    agent.fit_encoder(motions)
    learner = agent.learner
    steps: list[StreamStep] = []
    for i, (demo, motion) in enumerate(zip(stream, motions)):
        ts = time.perf_counter()
        seq, start = agent._encode(motion)
        true = truth.of(demo)
        mem = agent.memory
        names = majority_names(mem.concept_members(truth)) if len(mem) else {}
        seen = true in set(names.values())
        if len(mem):
            rec = learner.recognize([seq], [demo.key])[0]
            answer: str | None = rec.concept
            unknown = bool(getattr(rec, "unknown", False))
            predicted = "unknown" if unknown else (names.get(rec.concept) or rec.concept)
            correct = (not seen) if unknown else predicted == true
            conf, dist, err = rec.confidence, rec.distance, rec.error
        else:
            answer, predicted, correct = None, "none", False
            conf = dist = err = float("nan")
        outcome = learner.learn(demo, seq, start, motion.dt)
        steps.append(StreamStep(demo.key, true, answer, predicted, bool(correct), seen,
                                float(conf), float(dist), float(err),
                                [int(f) for f in outcome.feedbacks], outcome.action,
                                len(agent.memory.concepts()), time.perf_counter() - ts))
        if progress is not None:
            progress({"kind": "stream", "step": i, "total": len(stream),
                      "correct": bool(correct)})
    wall = time.perf_counter() - t0
    members = agent.memory.concept_members(truth)
    rows = [s.__dict__ for s in steps]
    metrics = summarize_stream(rows, config, wall)
    metrics["purity"] = purity(members)
    metrics["concepts"] = len(agent.memory.concepts())
    metrics["entries"] = len(agent.memory)
    metrics.update(data_set_records(dataset, demos))
    return metrics, rows


def summarize_stream(steps: list[dict], config: Config, wall_seconds: float) -> dict[str, Any]:
    """Stream metrics from per-demonstration steps.

    ``first_guess`` is the fraction of demonstrations ``FIRST_SCORED``..end
    (1-based) answered right before being taught; ``feedbacks_per_demo``
    the mean number of teacher feedbacks per demonstration (all, and from
    ``FIRST_SCORED``); ``curve`` the cumulative first-guess accuracy.
    """
    correct = np.array([s["correct"] for s in steps], dtype=float)
    fb = np.array([len(s["feedbacks"]) for s in steps], dtype=float)
    late = slice(FIRST_SCORED - 1, None)
    seen = np.array([s["seen_before"] for s in steps], dtype=bool)
    late_seen = seen[late]
    out: dict[str, Any] = {
        "protocol": "stream",
        "demonstrations": len(steps),
        "first_scored": FIRST_SCORED,
        "first_guess": float(correct[late].mean()) if correct[late].size else float("nan"),
        "first_guess_seen": (float(correct[late][late_seen].mean()) if late_seen.any()
                             else float("nan")),
        "first_guess_all": float(correct.mean()) if correct.size else float("nan"),
        "unseen_after_first_scored": int((~late_seen).sum()),
        "feedbacks_per_demo": float(fb.mean()) if fb.size else float("nan"),
        "feedbacks_per_demo_late": float(fb[late].mean()) if fb[late].size else float("nan"),
        "curve": [float(x) for x in np.cumsum(correct) / np.arange(1, len(correct) + 1)],
        "wall_seconds": wall_seconds,
        "seed": config.seed,
        "config": config.to_dict(),
    }
    m, s = mean_std([len(x["feedbacks"]) for x in steps]) if steps else (float("nan"),) * 2
    out["feedbacks"] = {"mean": m, "std": s}
    return out
