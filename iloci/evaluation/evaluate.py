"""The paper's experiment: k-fold evaluation on LASA (DESIGN.md section 6).

Per fold: a fresh agent is taught the learning set one demonstration at a
time (seeded random order, the configured teacher), then recognizes the
test set without feedback. A test demonstration is classified correctly
when the demonstration its nearest memory entry stands for has the same
true concept (what an oracle teacher would reward). The DTW 1-NN baseline
runs on the same folds.

Folds run in parallel processes (``jobs``); progress (per fold and per
interaction, with ETA) is reported through a callback fed by the
``iloci_on_interaction`` observer hook.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
import concurrent.futures as cf
from dataclasses import dataclass, field
import importlib.metadata as md
import multiprocessing as mp
import os
import platform
import signal
import threading
import time
from typing import Any

import numpy as np

from iloci.config import Config, load_config
from iloci.data.concepts import concept_of
from iloci.errors import InvalidInputError
from iloci.evaluation.metrics import (confidence_matrix, confusion_matrix,
                                      correct_classification_rate, mean_std)
from iloci.hookspecs import hookimpl

__all__ = ["FoldResult", "run_fold", "evaluate", "fold_plan", "summarize"]


@dataclass
class FoldResult:
    """Everything one fold produced (JSON-able after :meth:`to_dict`)."""

    fold: int
    learn: list[str]
    test: list[str]
    true: list[str]
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
    baseline_predicted: list[str] = field(default_factory=list)
    baseline_ccr: float = float("nan")
    baseline_seconds: float = float("nan")
    #: Memory PB_rec, their true concepts and kinds; test PB_obs (for MDS).
    pb_points: list[list[float]] = field(default_factory=list)
    pb_concepts: list[str] = field(default_factory=list)
    pb_kinds: list[str] = field(default_factory=list)
    #: One regenerated drawing per true concept: concept -> (T, 2) as lists.
    shapes: dict[str, list[list[float]]] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def fold_plan(demos: Sequence[Any], config: Config) -> list[tuple[list[int], list[int]]]:
    """(learning indices in presentation order, test indices) per fold."""
    from iloci.evaluation.folds import lasa_folds
    ev = config.evaluation
    plan = []
    for k, (learn, test) in enumerate(lasa_folds(demos, ev.folds, ev.seed)):
        # presentation order: seeded per fold, independent of the split's draws
        rng = np.random.default_rng([ev.seed, k, 1])
        plan.append(([int(i) for i in rng.permutation(learn)], [int(i) for i in test]))
    return plan


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
             details: bool = True, plugin_manager: Any = None) -> FoldResult:
    """Teach a fresh agent ``learn`` (in order), recognize ``test``; one fold.

    Parameters
    ----------
    config : Config or mapping
    fold : int
    learn, test : sequences of Demonstration (with ``concept`` set)
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
    """
    from iloci.agent import learn_and_recognize
    from iloci.plugins import get_plugin_manager, get_registry

    pm = plugin_manager or get_plugin_manager()
    config = load_config(config, registry=get_registry(pm))
    t0 = time.perf_counter()
    observer = _ProgressObserver(fold, len(learn), send) if send else None
    if observer is not None:
        pm.register(observer)
    try:
        agent, report, recs = learn_and_recognize(config, learn, test, plugin_manager=pm)
    finally:
        if observer is not None:
            pm.unregister(observer)
    wall = time.perf_counter() - t0
    known = {d.key: d.concept for d in list(learn) + list(test) if d.concept}
    true = [d.concept or _true_concept(d.key, known) for d in test]
    predicted = [_true_concept(r.source, known) for r in recs]
    mem = agent.memory
    entries = mem.entries
    res = FoldResult(
        fold=fold,
        learn=[d.key for d in learn],
        test=[d.key for d in test],
        true=true,
        predicted=predicted,
        confidence=[float(r.confidence) for r in recs],
        ccr=correct_classification_rate(true, predicted),
        feedbacks=[int(f) for f in report.feedbacks],
        first_guess=[bool(g) for g in report.first_guess_correct],
        interactions_per_demo=len(report.feedbacks) / max(1, len(report.outcomes)),
        exemplars=sum(1 for e in entries if e.num_samples == 1),
        prototypes=sum(1 for e in entries if e.num_samples > 1),
        entries=len(entries),
        concepts=len(mem.concepts()),
        generation_error=float(np.mean([e.generation_error for e in entries])),
        rehearsals=len(report.rehearsals),
        rehearsal_seconds=float(sum(r.seconds for r in report.rehearsals)),
        wall_seconds=wall,
        skipped=[list(s) for s in report.skipped],
    )
    if details:
        names = mem.label_concepts(lambda k: _true_concept(k, known))
        for e in entries:
            res.pb_points.append([float(x) for x in e.pb_rec])
            res.pb_concepts.append(names.get(e.concept) or e.concept)
            res.pb_kinds.append("exemplar" if e.num_samples == 1 else "prototype")
        for r, c in zip(recs, true):
            res.pb_points.append([float(x) for x in r.pb_obs])
            res.pb_concepts.append(c)
            res.pb_kinds.append("test")
        for label in mem.concepts():
            name = names.get(label) or label
            if name in res.shapes:
                continue
            # what the robot drew: executed in the simulator when one is configured
            motion = np.asarray(agent.respond(label).drawing)
            res.shapes[name] = motion.tolist()
    if baseline:
        from iloci.evaluation.baseline import dtw_1nn
        tb = time.perf_counter()
        res.baseline_predicted = dtw_1nn(list(learn), list(test))
        res.baseline_seconds = time.perf_counter() - tb
        res.baseline_ccr = correct_classification_rate(true, res.baseline_predicted)
    return res


def _worker_init() -> None:
    # The parent handles Ctrl-C and terminates the workers.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    # A parent killed outright (SIGKILL, SIGTERM) cannot stop its workers;
    # they notice they were orphaned and exit instead of computing on.
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(1.0)
        os._exit(1)

    threading.Thread(target=watch, daemon=True, name="iloci-orphan-watch").start()


class _ResolvedComponents:
    """Plugin registering components another plugin manager resolved.

    A worker process cannot receive the caller's plugin manager (plugin
    objects and modules do not pickle), only the :class:`ComponentSpec` s
    its registry resolved the config's names to. Registered alone on a
    worker's plugin manager, this plugin makes that manager resolve the
    same names to the same factories and schemas, and nothing else.
    """

    def __init__(self, specs: Sequence[Any]) -> None:
        self.specs = list(specs)
        self.__name__ = "iloci.evaluation.resolved"  # its name on the plugin manager

    def _add(self, registry: Any) -> None:
        for s in self.specs:
            if s.kind == registry.kind:
                registry.add(s.name, s.factory, params=s.params, requires=s.requires,
                             install=s.install, summary=s.summary)

    @hookimpl
    def iloci_register_perceptual_models(self, registry) -> None:
        self._add(registry)

    @hookimpl
    def iloci_register_clusterers(self, registry) -> None:
        self._add(registry)

    @hookimpl
    def iloci_register_teachers(self, registry) -> None:
        self._add(registry)

    @hookimpl
    def iloci_register_ik_solvers(self, registry) -> None:
        self._add(registry)

    @hookimpl
    def iloci_register_simulators(self, registry) -> None:
        self._add(registry)


def _resolved_specs(config: Config, pm: Any) -> list[Any]:
    """The specs ``pm`` resolves the config's components to, checked to pickle.

    Raises InvalidInputError naming each component whose spec cannot be
    sent to a worker process (e.g. a lambda or a class defined in a
    function as its factory or schema).
    """
    import pickle

    from iloci.interfaces import COMPONENT_KINDS
    from iloci.plugins import get_registry
    registry = get_registry(pm)
    specs, problems = [], []
    for sec, kind in COMPONENT_KINDS.items():
        name = getattr(config, sec).name
        if name == "none":
            continue
        spec = registry.get(sec, name)
        try:
            pickle.dumps(spec)
        except (pickle.PicklingError, AttributeError, TypeError) as exc:  # e.g. local objects
            problems.append(f"{kind.label} {name!r} (plugin {spec.plugin!r}): "
                            f"{type(exc).__name__}: {exc}")
        specs.append(spec)
    if problems:
        raise InvalidInputError(
            "jobs > 1 runs each fold in a worker process, which builds the components "
            "the given plugin_manager resolved from their pickled registry entries, and "
            "these do not pickle: " + "; ".join(problems) + ". Register the factory as a "
            "'module:attribute' string (or a module-level callable) and the params "
            "schema as a module-level dataclass, or evaluate with jobs=1.")
    return specs


def _run_fold_in_worker(config_dict: dict, fold: int, learn_idx: list[int],
                        test_idx: list[int], shapes: list[str], queue: Any,
                        baseline: bool, specs: Sequence[Any] | None = None) -> dict:
    from iloci.data import load_lasa
    from iloci.plugins import DEFAULT_PLUGINS, get_plugin_manager
    demos = load_lasa(shapes or None)
    # specs: what the caller's plugin manager resolved; None: the default manager's
    pm = None if specs is None else get_plugin_manager(
        autoload=False, block=DEFAULT_PLUGINS, plugins=[_ResolvedComponents(specs)])

    def send(msg: dict) -> None:
        if queue is not None:
            queue.put(msg)

    # a fold's clock starts when a worker takes it, not when it is queued
    send({"kind": "fold_start", "fold": fold, "total": len(learn_idx)})
    res = run_fold(config_dict, fold, [demos[i] for i in learn_idx],
                   [demos[i] for i in test_idx], send=send, baseline=baseline,
                   plugin_manager=pm)
    return res.to_dict()


def _versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for dist in ("iloci", "numpy", "scipy", "pluggy", "torch", "jax", "pin", "scikit-learn",
                 "dtaidistance", "pybullet", "mujoco", "iloci-torch", "iloci-jax",
                 "iloci-scipy", "iloci-sklearn", "iloci-pinocchio"):
        try:
            out[dist] = md.version(dist)
        except md.PackageNotFoundError:
            pass
    return out


def summarize(results: Sequence[dict], config: Config, wall_seconds: float,
              jobs: int) -> dict[str, Any]:
    """metrics.json content from per-fold results."""
    results = sorted(results, key=lambda r: r["fold"])

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
        "interactions_per_demo": ms("interactions_per_demo"),
        "exemplars": ms("exemplars"),
        "prototypes": ms("prototypes"),
        "entries": ms("entries"),
        "concepts": ms("concepts"),
        "generation_error": ms("generation_error"),
        "fold_wall_seconds": [r["wall_seconds"] for r in results],
        "folds": [{k: r[k] for k in ("fold", "ccr", "interactions_per_demo", "exemplars",
                                       "prototypes", "entries", "concepts",
                                       "generation_error", "rehearsals", "rehearsal_seconds",
                                       "wall_seconds", "baseline_ccr", "skipped")}
                  | {"learn": len(r["learn"]), "test": len(r["test"])} for r in results],
        "paper": {"ccr_mean": 0.91346, "ccr_std": 0.03511},
        "seed": config.seed,
        "config": config.to_dict(),
        "versions": _versions(),
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count()},
    }
    if all(r.get("baseline_predicted") for r in results):
        bm, bs = mean_std([r["baseline_ccr"] for r in results])
        out["baseline"] = {"method": "DTW 1-NN (dtaidistance), positions resampled to 50",
                           "ccr_mean": bm, "ccr_std": bs,
                           "ccr_folds": [r["baseline_ccr"] for r in results],
                           "seconds": [r["baseline_seconds"] for r in results]}
    return out


def evaluate(config: Any = None, *, jobs: int | None = None,
             progress: Callable[[dict], None] | None = None,
             folds: Sequence[int] | None = None, baseline: bool = True,
             plugin_manager: Any = None) -> tuple[dict[str, Any], list[dict]]:
    """Run the k-fold protocol; return (metrics, per-fold results).

    Parameters
    ----------
    config : Config, path, mapping or None
    jobs : int, optional
        Parallel processes (default ``config.evaluation.jobs``).
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

    Notes
    -----
    With ``jobs > 1`` the folds run in spawned worker processes, which
    cannot receive a plugin manager (its plugin objects do not pickle).
    Without ``plugin_manager``, each worker builds the default one from the
    installed plugins, as the parent does. With one, the parent resolves
    the config's component names through it and sends each worker how to
    build those components (their registry entries: factory, schema,
    requirements); a worker's plugin manager holds those and nothing else,
    so the learning events in a worker reach no observer. A component
    whose factory or schema cannot be pickled (a lambda, a class defined
    in a function) cannot be sent: that is an :class:`InvalidInputError`
    before any fold runs, rather than a silent serial run.

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
    jobs = int(jobs or config.evaluation.jobs)
    if jobs < 1:
        raise InvalidInputError(f"jobs must be >= 1, got {jobs}.")
    # resolved (and checked to pickle) before any data is loaded or fold run
    specs = _resolved_specs(config, pm) if jobs > 1 and plugin_manager is not None else None
    shapes = list(config.data.shapes)
    demos = load_lasa(shapes or None)
    plan = fold_plan(demos, config)
    wanted = list(range(len(plan))) if folds is None else list(folds)
    for k in wanted:
        if not 0 <= k < len(plan):
            raise InvalidInputError(f"fold {k} does not exist; folds are 0..{len(plan) - 1}.")
    emit = progress or (lambda msg: None)
    t0 = time.perf_counter()
    results: list[dict] = []
    cfg_dict = config.to_dict()
    if jobs == 1:
        for k in wanted:
            learn_idx, test_idx = plan[k]
            emit({"kind": "fold_start", "fold": k, "total": len(learn_idx)})
            res = run_fold(config, k, [demos[i] for i in learn_idx],
                           [demos[i] for i in test_idx], send=emit, baseline=baseline,
                           plugin_manager=pm)
            results.append(res.to_dict())
            pm.hook.iloci_on_fold_finished(event=_fold_event(results[-1]))
            emit({"kind": "fold_done", "fold": k, "ccr": res.ccr,
                  "seconds": res.wall_seconds})
    else:
        ctx = mp.get_context("spawn")  # no fork: torch/JAX threads do not survive it
        manager = ctx.Manager()
        queue = manager.Queue()
        pool = cf.ProcessPoolExecutor(max_workers=min(jobs, len(wanted)), mp_context=ctx,
                                      initializer=_worker_init)
        try:
            futures = {}
            for k in wanted:
                learn_idx, test_idx = plan[k]
                futures[pool.submit(_run_fold_in_worker, cfg_dict, k, learn_idx, test_idx,
                                    shapes, queue, baseline, specs)] = k
                emit({"kind": "fold_queued", "fold": k, "total": len(learn_idx)})
            pending = set(futures)
            while pending:
                done, pending = cf.wait(pending, timeout=0.2,
                                        return_when=cf.FIRST_COMPLETED)
                while not queue.empty():
                    emit(queue.get())
                for fut in done:
                    res = fut.result()
                    results.append(res)
                    pm.hook.iloci_on_fold_finished(event=_fold_event(res))
                    emit({"kind": "fold_done", "fold": res["fold"], "ccr": res["ccr"],
                          "seconds": res["wall_seconds"]})
        except BaseException:
            for proc in list(getattr(pool, "_processes", {}).values()):
                proc.terminate()
            pool.shutdown(wait=False, cancel_futures=True)
            manager.shutdown()
            raise
        pool.shutdown()
        manager.shutdown()
    wall = time.perf_counter() - t0
    results.sort(key=lambda r: r["fold"])
    return summarize(results, config, wall, jobs), results


def _fold_event(r: dict):
    from iloci.events import FoldEvent
    return FoldEvent(fold=r["fold"], metrics={k: r[k] for k in (
        "ccr", "interactions_per_demo", "exemplars", "prototypes", "concepts",
        "generation_error", "wall_seconds", "baseline_ccr")})
