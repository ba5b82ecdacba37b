"""Evaluation folds on an executor: in this process, in worker processes or on Ray.

:func:`run_folds` runs folds of :func:`iloci.evaluation.evaluate.evaluate`
on an executor (:mod:`iloci.evaluation.executors`: this process, joblib's
loky pool, or a plugin's, e.g. Ray) and relays their progress messages; it
is the one code path of serial and parallel runs (the same task functions;
in this process they get the caller's plugin manager, :class:`LocalContext`).
A worker cannot receive the caller's plugin manager (plugin objects and
modules do not pickle); when the caller has one, the worker gets the
registry entries it resolved the config's component names to
(:func:`resolved_specs`) and registers them alone (:class:`ResolvedComponents`).

On the local pool a fold is up to three tasks: its learning
(:func:`~iloci.evaluation.fold.learn_fold`, which saves the learned
agent), its baselines (:func:`~iloci.evaluation.fold.fold_baselines`) and,
queued when the learning ends, the recognition of its test set by the
saved agent, each in whichever worker is free; results are those of
:func:`~iloci.evaluation.fold.run_fold`, bit for bit. Learning is the long,
sequential part, so every learning task is queued first and the short
tasks fill the workers that would otherwise wait for the last learning;
the last learning to end has its fold's recognition split over the
workers it leaves free (:func:`run_folds`). Each task carries the
demonstrations it needs (the parent read the data set once; a worker reads
no file), and a worker converts each demonstration (preprocessing + IK)
once for all the tasks it runs
(:class:`~iloci.sensorimotor.pipeline.MotionCache`); a recognition is also
sent the motions the learnings ended so far converted, so a demonstration
met in one worker's learning is not converted again in another worker.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
import json
import os
import pickle
import tempfile
from typing import Any

import numpy as np

from iloci.agent import Agent, build
from iloci.config import load_config
from iloci.errors import InvalidInputError
from iloci.evaluation.fold import (LearnedFold, fold_baselines, learn_fold,
                                  recognize_test_set, run_fold)
from iloci.evaluation.folds import fold_memory_name
from iloci.hookspecs import hookimpl
from iloci.interfaces import ALL_KINDS, COMPONENT_KINDS, Demonstration
from iloci.plugins import DEFAULT_PLUGINS, get_plugin_manager, get_registry
from iloci.sensorimotor.pipeline import MotionCache

__all__ = ["FoldTask", "LocalContext", "ResolvedComponents", "resolved_specs", "run_folds",
           "run_folds_in_processes", "warm_up"]


@dataclass(frozen=True)
class FoldTask:
    """One fold to run: its index and the indices of its demonstrations.

    Attributes
    ----------
    fold : int
    learn : list of int
        Indices into the demonstrations given to :func:`run_folds`, in
        presentation order.
    test : list of int
    memory_dir : str, optional
        Save the fold's learned agent there as ``fold-K.npz``.
    """

    fold: int
    learn: list[int]
    test: list[int]
    memory_dir: str | None = None


class ResolvedComponents:
    """Plugin registering components another plugin manager resolved.

    A worker process cannot receive the caller's plugin manager (plugin
    objects and modules do not pickle), only the :class:`ComponentSpec` s
    its registry resolved the config's names to. Registered alone on a
    worker's plugin manager, this plugin makes that manager resolve the
    same names to the same factories and schemas, and nothing else (the
    robot preset included: the worker's manager loads no other plugin).
    """

    def __init__(self, specs: Sequence[Any]) -> None:
        self.specs = list(specs)
        self.__name__ = "iloci.evaluation.resolved"  # its name on the plugin manager

    def _add(self, registry: Any) -> None:
        for s in self.specs:
            if s.kind == registry.kind:
                registry.add(s.name, s.factory, params=s.params, requires=s.requires,
                             install=s.install, summary=s.summary, **dict(s.facts))

    @hookimpl
    def iloci_register_perceptual_models(self, registry: Any) -> None:
        self._add(registry)

    @hookimpl
    def iloci_register_clusterers(self, registry: Any) -> None:
        self._add(registry)

    @hookimpl
    def iloci_register_teachers(self, registry: Any) -> None:
        self._add(registry)

    @hookimpl
    def iloci_register_ik_solvers(self, registry: Any) -> None:
        self._add(registry)

    @hookimpl
    def iloci_register_simulators(self, registry: Any) -> None:
        self._add(registry)

    @hookimpl
    def iloci_register_robots(self, registry: Any) -> None:
        self._add(registry)


def resolved_specs(config: Any, pm: Any) -> list[Any]:
    """The specs ``pm`` resolves the config's components (and its robot preset) to,
    checked to pickle.

    Raises
    ------
    InvalidInputError
        Naming each component whose spec cannot be sent to a worker process
        (e.g. a lambda or a class defined in a function as its factory or
        schema).
    """
    registry = get_registry(pm)
    specs, problems = [], []
    # the components, and the robot when the config names a preset (not a URDF)
    wanted = [(sec, kind, getattr(config, sec).name) for sec, kind in COMPONENT_KINDS.items()]
    if not config.robot.urdf:
        wanted.append(("robot", ALL_KINDS["robot"], config.robot.name))
    for sec, kind, name in wanted:
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


#: A worker's motion caches (:class:`~iloci.sensorimotor.pipeline.MotionCache`),
#: one per config and set of components: the folds a worker runs convert each
#: demonstration once.
_MOTION_CACHES: dict[str, Any] = {}


@dataclass(frozen=True)
class LocalContext:
    """What folds run in this process share: the caller's plugin manager and a motion cache.

    Passed where a worker gets ``specs`` (:class:`~iloci.evaluation.executors.InProcessExecutor`
    needs nothing pickled): the caller's observers see every learning event,
    and the folds share one motion cache.
    """

    plugin_manager: Any
    motion_cache: MotionCache = field(default_factory=MotionCache)


def _motion_cache(config_dict: dict, specs: Sequence[Any] | LocalContext | None) -> Any:
    if isinstance(specs, LocalContext):
        return specs.motion_cache
    key = json.dumps(config_dict, sort_keys=True, default=repr) + repr(
        None if specs is None else [(s.kind, s.name, s.plugin, s.factory) for s in specs])
    if key not in _MOTION_CACHES:
        _MOTION_CACHES.clear()  # another evaluation: its cache alone is kept
        _MOTION_CACHES[key] = MotionCache()
    return _MOTION_CACHES[key]


def _run_fold_in_worker(config_dict: dict, task: FoldTask, learn: list[Any], test: list[Any],
                        baseline: bool, specs: Sequence[Any] | LocalContext | None,
                        queue: Any) -> Any:
    """One fold in an executor's worker (``learn``, ``test``: its demonstrations);
    ``queue.put`` receives its progress messages."""
    pm = _worker_plugins(specs)
    send = _fold_started(task, queue)
    return run_fold(config_dict, task.fold, learn, test, send=send, baseline=baseline,
                    plugin_manager=pm, memory_dir=task.memory_dir,
                    motion_cache=_motion_cache(config_dict, specs))


def _worker_plugins(specs: Sequence[Any] | LocalContext | None) -> Any:
    """A worker's plugin manager (None: the default one)."""
    if isinstance(specs, LocalContext):
        return specs.plugin_manager
    # specs: what the caller's plugin manager resolved; None: the default manager's
    return None if specs is None else get_plugin_manager(
        autoload=False, block=DEFAULT_PLUGINS, plugins=[ResolvedComponents(specs)])


def warm_up(config_dict: dict, specs: Sequence[Any] | None, queue: Any = None) -> None:
    """Make a worker ready for fold tasks: import and build what a fold will use.

    Run once per worker while the caller still reads the data set
    (:meth:`~iloci.evaluation.executors.LocalExecutor.start`): builds the
    config's agent (the components' modules, the robot) and converts a
    drawn circle (the preprocessing and IK code); nothing is kept but the
    imported modules, so the folds' results are the same without it.
    """
    pm = _worker_plugins(specs)
    agent = build(load_config(config_dict, registry=get_registry(pm)), plugin_manager=pm)
    t = np.linspace(0.0, 2.0 * np.pi, 400)
    agent.motion(Demonstration(np.column_stack([np.cos(t), np.sin(t)]), t))


def _fold_started(task: FoldTask, queue: Any) -> Callable[[dict], None]:
    """A worker's sender of progress messages to ``queue`` (None: none), after "fold_start".

    A fold's clock starts when a worker takes it, not when it is queued.
    """
    def send(msg: dict) -> None:
        if queue is not None:
            queue.put(msg)

    send({"kind": "fold_start", "fold": task.fold, "total": len(task.learn)})
    return send


def _learn_fold_in_worker(config_dict: dict, task: FoldTask, learn: list[Any],
                          test: list[Any], baseline: bool,
                          specs: Sequence[Any] | LocalContext | None, agent_path: str,
                          queue: Any) -> Any:
    """A fold's learning in a worker: its LearnedFold and the motions of its learning set
    (:class:`_Learned`); the agent is saved to ``agent_path``.

    ``learn``, ``test``: the fold's demonstrations. ``agent_path`` is the
    fold's file in ``task.memory_dir`` when the evaluation keeps memories
    (:func:`~iloci.evaluation.folds.fold_memory_name`), else one in a
    temporary directory: the agent is saved once, there. The baselines are
    not run here (:func:`_baselines_in_worker`); ``baseline`` still applies
    to the robustness suite, which needs the learned agent.
    """
    pm = _worker_plugins(specs)
    send = _fold_started(task, queue)
    cache = _motion_cache(config_dict, specs)
    learned, agent = learn_fold(config_dict, task.fold, learn, test, send=send,
                                baseline=baseline, plugin_manager=pm, memory_dir=None,
                                motion_cache=cache, defer_baselines=True)
    agent.save(agent_path)
    return _Learned(learned, cache.converted(learn))


@dataclass(frozen=True)
class _Learned:
    """A fold's learning, and the motions of its learning set (for other workers' caches)."""

    fold: LearnedFold
    motions: list[Any]


@dataclass(frozen=True)
class _Baselines:
    fold: int
    baselines: dict[str, dict[str, Any]]


def _baselines_in_worker(fold: int, learn: list[Any], test: list[Any], queue: Any) -> Any:
    """A fold's baselines in a worker (they need its demonstrations only)."""
    return _Baselines(fold, fold_baselines(learn, test))


@dataclass(frozen=True)
class _Recognized:
    fold: int
    recognitions: list[Any]
    seconds: float
    part: int = 0
    parts: int = 1


def _recognize_part_in_worker(config_dict: dict, fold: int, part: tuple[int, int],
                              test: list[Any], total: int,
                              specs: Sequence[Any] | LocalContext | None,
                              agent_path: str, motions: list[Any], queue: Any) -> Any:
    """Recognize part ``part = (k, parts)`` of a fold's test set with its saved agent, in a
    worker (``test``: that part's demonstrations, of ``total`` in the test set; ``(0, 1)``:
    the whole test set; ``motions``: those of their motions other workers converted).
    ``queue.put`` receives a message when the part starts and one when it ends
    (:func:`~iloci.evaluation.fold.recognize_test_set`)."""
    pm = _worker_plugins(specs)
    agent = Agent.load(agent_path, config_dict, plugin_manager=pm)
    cache = _motion_cache(config_dict, specs)
    cache.add(motions)
    agent.motion_cache = cache
    send = None if queue is None else queue.put
    recs, seconds = recognize_test_set(agent, fold, test, send=send, part=part, total=total)
    return _Recognized(fold, recs, seconds, *part)


def run_folds(config_dict: dict, tasks: Sequence[FoldTask], demos: Sequence[Any],
              runner: Any, *, baseline: bool, specs: Sequence[Any] | LocalContext | None,
              emit: Callable[[dict], None],
              on_result: Callable[[Any], None]) -> None:
    """Run ``tasks`` on ``runner``, an executor (:mod:`iloci.evaluation.executors`).

    Parameters
    ----------
    config_dict : dict
        The resolved config (:meth:`Config.to_dict`).
    tasks : sequence of FoldTask
    demos : sequence of Demonstration
        What the tasks' indices refer to (e.g. ``load_lasa(shapes)``); each
        task is sent the demonstrations it needs, so a worker reads no data.
    runner : FoldExecutor
        :class:`~iloci.evaluation.executors.InProcessExecutor` (this
        process), ``local`` (joblib's loky pool) or a plugin's (e.g. Ray).
    baseline : bool
        Run the DTW 1-NN baseline in each fold too.
    specs : sequence of ComponentSpec or LocalContext, optional
        What the caller's plugin manager resolved (see :func:`resolved_specs`);
        ``None``: each worker builds the default plugin manager; a
        :class:`LocalContext` for an executor running the folds in this process.
    emit : callable
        Receives every progress message (``fold_queued``, ``fold_start``,
        ``interaction``, ``rehearsal``, and ``recognition`` / ``recognized``
        around the recognition of each test set or part of one:
        :func:`~iloci.evaluation.fold.recognize_test_set`), in the parent process.
    on_result : callable
        Called in the parent with each :class:`~iloci.evaluation.results.FoldResult`
        as its fold finishes.

    Raises
    ------
    BaseException
        Whatever a fold raised, or KeyboardInterrupt: the executor stops
        its workers first.
    """
    def pick(indices: Sequence[int]) -> list[Any]:
        return [demos[i] for i in indices]

    for task in tasks:
        emit({"kind": "fold_queued", "fold": task.fold, "total": len(task.learn)})
    if not hasattr(runner, "run_then") or not all(t.test for t in tasks):
        calls = [(config_dict, task, pick(task.learn), pick(task.test), baseline, specs)
                 for task in tasks]
        for res in runner.run(_run_fold_in_worker, calls, emit):
            on_result(res)
        return
    # Learning a fold is sequential and by far its longest part: every
    # learning task is queued first (the pool takes tasks in the order they
    # were queued), then the baselines, and the recognition of a fold's test
    # set when its learning ends. With 5 folds on 2 workers, one worker
    # learns 3 folds and the other 2; the other runs the short tasks
    # meanwhile. The last learning to end leaves every worker free: its
    # fold's recognition is split over them (the test set in ``jobs``
    # consecutive parts, one task each; each demonstration is recognized
    # alone, so the answers are the same), not run by one worker while the
    # others wait. A part pays a recognition's fixed cost (loading the
    # agent), the split shortens the run's tail.
    with tempfile.TemporaryDirectory(prefix="iloci-evaluate-") as tmp:
        def agent_path(task: FoldTask) -> str:
            return os.path.join(task.memory_dir or tmp, fold_memory_name(task.fold))

        by_fold = {task.fold: task for task in tasks}
        # motions the learnings converted, by demonstration: sent with the recognitions
        # of other folds (a worker converts only the demonstrations no learning met)
        motions: dict[str, Any] = {}
        learned: dict[int, LearnedFold] = {}
        baselines: dict[int, dict[str, dict[str, Any]]] = {}
        recognized: dict[int, _Recognized] = {}
        parts_in: dict[int, list[_Recognized]] = {}
        workers = max(1, int(getattr(runner, "jobs", 1)))
        running = [0]  # tasks queued whose result has not arrived

        def then(res: Any) -> list[tuple[Callable[..., Any], tuple]]:
            running[0] -= 1
            if not isinstance(res, _Learned):
                return []
            motions.update((key[0], (key, motion)) for key, motion in res.motions)
            task = by_fold[res.fold.result.fold]
            n = min(workers, len(task.test)) if running[0] == 0 else 1
            cut = [len(task.test) * k // n for k in range(n + 1)]
            running[0] += n
            parts = [pick(task.test[cut[k]:cut[k + 1]]) for k in range(n)]
            return [(_recognize_part_in_worker,
                     (config_dict, task.fold, (k, n), part, len(task.test), specs,
                      agent_path(task),
                      [motions[d.key] for d in part if d.key in motions]))
                    for k, part in enumerate(parts)]

        def whole(res: _Recognized) -> _Recognized | None:
            """The fold's recognition once all its parts are in (answers in test order)."""
            if res.parts == 1:
                return res
            got = parts_in.setdefault(res.fold, [])
            got.append(res)
            if len(got) < res.parts:
                return None
            got.sort(key=lambda r: r.part)
            del parts_in[res.fold]
            # the parts ran at once: the recognition took as long as the longest
            return _Recognized(res.fold, [r for p in got for r in p.recognitions],
                               max(p.seconds for p in got))

        first: list[tuple[Callable[..., Any], tuple]] = [
            (_learn_fold_in_worker, (config_dict, task, pick(task.learn), pick(task.test),
                                     baseline, specs, agent_path(task))) for task in tasks]
        if baseline:
            first += [(_baselines_in_worker, (task.fold, pick(task.learn), pick(task.test)))
                      for task in tasks]
        running[0] = len(first)
        for res in runner.run_then(first, emit, then):
            if isinstance(res, _Learned):
                k = res.fold.result.fold
                learned[k] = res.fold
            elif isinstance(res, _Baselines):
                baselines[res.fold] = res.baselines
                k = res.fold
            else:
                rec = whole(res)
                if rec is None:
                    continue
                recognized[res.fold] = rec
                k = res.fold
            if k in learned and k in recognized and (not baseline or k in baselines):
                fold = learned.pop(k).with_baselines(baselines.pop(k, {}))
                rec = recognized.pop(k)
                on_result(fold.complete(rec.recognitions, rec.seconds))


#: The name :func:`run_folds` had before serial runs took the same path.
run_folds_in_processes = run_folds
