"""One fold of the paper's experiment: teach a fresh agent, recognize the test set.

:func:`learn_fold` teaches (and runs the baselines and the robustness
suite); :meth:`LearnedFold.complete` scores the recognitions of the test
set. :func:`run_fold` is the two in one process; a parallel evaluation runs
the learning, the baselines (:func:`fold_baselines`) and the recognition as
three tasks (:mod:`iloci.evaluation.parallel`), with the same results.
A demonstration's true concept comes from :class:`~iloci.data.concepts.GroundTruth`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
import dataclasses
from dataclasses import dataclass
import os
import time
from typing import Any

import numpy as np

from iloci.agent import Agent, build
from iloci.config import Config, load_config
from iloci.data.concepts import GroundTruth, majority_names
from iloci.errors import InvalidInputError, ObserverError
from iloci.evaluation.folds import fold_memory_name
from iloci.evaluation.metrics import matched_names, purity
from iloci.evaluation.results import Answer, FoldResult, memory_counts
from iloci.evaluation.robustness import robustness_suite
from iloci.hookspecs import hookimpl
from iloci.plugins import get_plugin_manager, get_registry

__all__ = ["LearnedFold", "fold_baselines", "learn_fold", "recognize_test_set", "run_fold"]


class _ProgressObserver:
    """Observer plugin forwarding learning events to a progress callback."""

    def __init__(self, fold: int, total: int, send: Callable[[dict], None]) -> None:
        self.fold, self.total, self.send = fold, total, send

    @hookimpl
    def iloci_on_interaction(self, event: Any) -> None:
        self.send({"fold": self.fold, "kind": "interaction", "step": event.step,
                   "total": self.total, "feedback": event.feedback})

    @hookimpl
    def iloci_on_rehearsal(self, event: Any) -> None:
        self.send({"fold": self.fold, "kind": "rehearsal", "entries": event.entries,
                   "seconds": event.seconds})


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
        Also run the baselines of :mod:`iloci.evaluation.baselines` on this fold.
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
    recs, seconds = recognize_test_set(agent, fold, test, send=send)
    return learned.complete(recs, seconds)


def recognize_test_set(agent: Agent, fold: int, test: Sequence[Any], *,
                       send: Callable[[dict], None] | None = None,
                       part: tuple[int, int] = (0, 1), total: int | None = None
                       ) -> tuple[list[Any], float]:
    """Recognize ``test`` (a fold's test set, or part of it) with ``agent``; tell ``send``.

    ``send`` receives ``{"fold": fold, "kind": "recognition", "part": k,
    "parts": n, "drawings": len(test), "total": total}`` before the
    recognition and the same with ``"kind": "recognized"`` and
    ``"seconds"`` after it (nothing for an empty ``test``), so a progress
    display shows the fold recognizing: on a few hundred drawings it takes
    a minute or more, after the last learning message.

    Parameters
    ----------
    agent : Agent
        The fold's learned agent.
    fold : int
    test : sequence of Demonstration
    send : callable, optional
    part : (int, int)
        ``(k, n)``: ``test`` is part ``k`` (0-based) of ``n`` of the fold's
        test set (:func:`~iloci.evaluation.parallel.run_folds` splits one
        over free workers); ``(0, 1)``: the whole test set.
    total : int, optional
        Drawings in the fold's whole test set (default ``len(test)``).

    Returns
    -------
    (list of Recognition, float)
        One recognition per drawing of ``test``, in order, and the wall
        time of the recognition in seconds (the messages not counted).
    """
    if not len(test):
        return [], 0.0
    msg = {"fold": fold, "part": part[0], "parts": part[1], "drawings": len(test),
           "total": len(test) if total is None else total}
    if send is not None:
        send({**msg, "kind": "recognition"})
    t0 = time.perf_counter()
    recs = agent.recognize(list(test))
    seconds = time.perf_counter() - t0
    if send is not None:
        send({**msg, "kind": "recognized", "seconds": seconds})
    return recs, seconds


@dataclass(frozen=True)
class LearnedFold:
    """A fold whose learning is done and whose test set is still to recognize.

    What :func:`learn_fold` returns (picklable: a parallel evaluation sends
    it from the worker that learned to the parent, and recognizes the test
    set in another task on the saved agent).

    Attributes
    ----------
    result : FoldResult
        Every field but the answers (none yet); ``wall_seconds`` is the
        learning time so far.
    test : list of str
        Keys of the test demonstrations, in order.
    true, taught : lists
        Per test demonstration: true concept; was it in the learning set.
    baseline_predicted : list of str or None
        The answers of DTW 1-NN on normalised paths (None: not run).
    majority, matched : dict
        Robot concept -> true concept name
        (:func:`~iloci.data.concepts.majority_names`,
        :func:`~iloci.evaluation.metrics.matched_names`).
    truth : GroundTruth
        Over ``learn`` and ``test``.
    details : bool
        Add the test PB_obs to ``result.pb_points``.
    """

    result: FoldResult
    test: list[str]
    true: list[str]
    taught: list[bool]
    baseline_predicted: list[str] | None
    majority: dict[str, Any]
    matched: dict[str, Any]
    truth: GroundTruth
    details: bool

    def with_baselines(self, baselines: dict[str, dict[str, Any]]) -> LearnedFold:
        """This fold with the baselines' results (:func:`fold_baselines`; empty: none ran).

        The answers' baseline is the strongest, DTW 1-NN on normalised paths.
        """
        if not baselines:
            return self
        best = baselines["dtw_normalised"]
        res = dataclasses.replace(self.result, baselines=baselines,
                                  baseline_seconds=float(best["seconds"]))
        return dataclasses.replace(self, result=res,
                                   baseline_predicted=list(best["predicted"]))

    def complete(self, recs: Sequence[Any], seconds: float) -> FoldResult:
        """The fold's result with ``recs`` (one Recognition per test demonstration, in order).

        ``seconds``: the recognition's wall time, added to ``wall_seconds``.

        Raises
        ------
        InvalidInputError
            ``recs`` is not one per test demonstration.
        """
        res, majority, matched = self.result, self.majority, self.matched
        if len(recs) != len(self.true):
            raise InvalidInputError(f"fold {res.fold}: {len(recs)} recognitions for "
                                    f"{len(self.true)} test demonstrations.")
        base: list[str | None] = [None] * len(recs)
        if self.baseline_predicted is not None:
            base = list(self.baseline_predicted)
        answers = tuple(
            Answer(key=key, true_concept=true, taught=taught,
                   # a robot concept without a true name keeps its robot label: never correct
                   predicted="unknown" if r.unknown else majority.get(r.concept) or r.concept,
                   robot_predicted=r.concept,
                   matched_predicted="unknown" if r.unknown else matched.get(r.concept)
                   or r.concept,
                   source_predicted=self.truth(r.source),
                   confidence=float(r.confidence), distance=float(r.distance),
                   error=float(r.error), reproduction_error=float(r.reproduction_error),
                   familiarity=float(r.familiarity), unknown=bool(r.unknown),
                   baseline_predicted=b)
            for key, true, taught, r, b in zip(self.test, self.true, self.taught, recs, base))
        pb: tuple[list[list[float]], list[str], list[str]] = ([], [], [])
        if self.details:
            pb = ([[float(x) for x in r.pb_obs] for r in recs], list(self.true),
                  ["test"] * len(recs))
        return dataclasses.replace(res, answers=answers,
                                   wall_seconds=res.wall_seconds + seconds,
                                   pb_points=res.pb_points + pb[0],
                                   pb_concepts=res.pb_concepts + pb[1],
                                   pb_kinds=res.pb_kinds + pb[2])


def learn_fold(config: Config | dict, fold: int, learn: Sequence[Any], test: Sequence[Any], *,
               send: Callable[[dict], None] | None = None, baseline: bool = True,
               details: bool = True, plugin_manager: Any = None,
               memory_dir: str | None = None,
               overrides: dict[str, Any] | None = None,
               robustness: bool | None = None,
               motion_cache: Any = None,
               defer_baselines: bool = False) -> tuple[LearnedFold, Agent]:
    """:func:`run_fold` up to the recognition of ``test``: the learned fold and its agent.

    Parameters as for :func:`run_fold`. The baselines (unless
    ``defer_baselines``: the caller runs :func:`fold_baselines` and passes
    its result to :meth:`LearnedFold.with_baselines`) and the robustness
    suite (which recognizes perturbed copies of ``test``) run here.
    Recognizing ``test`` with the returned agent (or with one loaded from
    its saved file: the same answers) and passing the recognitions to
    :meth:`LearnedFold.complete` gives :func:`run_fold`'s result.
    """
    pm = plugin_manager or get_plugin_manager()
    config = load_config(config, registry=get_registry(pm))
    t0 = time.perf_counter()
    observer = _ProgressObserver(fold, len(learn), send) if send else None
    if observer is not None:
        pm.register(observer)
    try:
        agent = build(config, plugin_manager=pm, **(overrides or {}))
        agent.motion_cache = motion_cache
        try:
            report = agent.teach(learn)
        except ObserverError as exc:
            # the teach's advice (the demonstration is learned: do not teach it again)
            # means nothing here: the fold, and with it the evaluation, stops
            raise ObserverError(exc.hook, exc.plugin, exc.error, exc.outcome,
                                context=f"fold {fold}'s learning") from exc.error
    finally:
        if observer is not None:
            pm.unregister(observer)
    wall = time.perf_counter() - t0
    if memory_dir:
        agent.save(os.path.join(memory_dir, fold_memory_name(fold)))
    truth = GroundTruth(list(learn) + list(test))
    true = [truth.of(d) for d in test]
    learned_concepts = {truth.of(d) for d in learn}
    mem = agent.memory
    entries = mem.entries
    members = mem.concept_members(truth)
    majority, matched = majority_names(members), matched_names(members)
    counts = memory_counts(mem)
    pb_points: list[list[float]] = []
    pb_concepts: list[str] = []
    pb_kinds: list[str] = []
    shapes: dict[str, list[list[float]]] = {}
    if details:
        for e in entries:
            pb_points.append([float(x) for x in e.pb_rec])
            pb_concepts.append(majority.get(e.concept) or e.concept)
            pb_kinds.append("prototype" if e.prototype else "exemplar")
        for label in mem.concepts():
            name = majority.get(label) or label
            if name in shapes:
                continue
            # what the robot drew: executed in the simulator when one is configured
            shapes[name] = np.asarray(agent.respond(label).drawing).tolist()
    rob: dict[str, dict[str, Any]] = {}
    if config.evaluation.robustness if robustness is None else robustness:
        rob = robustness_suite(agent, list(learn), list(test), true, truth,
                               seed=config.evaluation.seed * 1000 + fold, baseline=baseline)
    res = FoldResult(
        fold=fold,
        learn=[d.key for d in learn],
        answers=(),
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
        memory_other_distance=_other_concept_distances(mem),
        memory_generation_error=[float(e.generation_error) for e in entries],
        pb_points=pb_points, pb_concepts=pb_concepts, pb_kinds=pb_kinds, shapes=shapes,
        robustness=rob,
    )
    learned = LearnedFold(res, test=[d.key for d in test], true=true,
                          taught=[t in learned_concepts for t in true],
                          baseline_predicted=None, majority=majority,
                          matched=matched, truth=truth, details=details)
    if baseline and not defer_baselines:
        learned = learned.with_baselines(fold_baselines(learn, test))
    return learned, agent


def fold_baselines(learn: Sequence[Any], test: Sequence[Any]) -> dict[str, dict[str, Any]]:
    """The baselines of :mod:`iloci.evaluation.baselines` on one fold (empty: no test set).

    What :func:`learn_fold` runs after the learning; a parallel evaluation
    runs it as a task of its own and hands the result to
    :meth:`LearnedFold.with_baselines` (the same result: the baselines see
    only the demonstrations).

    Raises
    ------
    MissingBackendError
        dtaidistance is not installed (``pip install 'iloci[report]'``).
    """
    if not len(test):
        return {}
    from iloci.evaluation.baselines import run_baselines  # dtaidistance: [report]
    return run_baselines(list(learn), list(test))


def _other_concept_distances(mem: Any) -> list[float]:
    """PB_rec distance of each entry to the nearest entry of another concept (inf: none)."""
    if not len(mem):
        return []
    x = mem.pbs_rec
    lab = np.asarray(mem.concept_labels)
    d = np.linalg.norm(x[:, None, :] - x[None, :, :], axis=2)
    d = np.where(lab[:, None] != lab[None, :], d, np.inf)
    return [float(v) for v in d.min(axis=1)]
