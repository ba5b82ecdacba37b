"""The paper's experiment: k-fold evaluation on LASA or a data set of your own (docs/method.md,
"Evaluation protocol"; docs/guide.md, "Your own shapes").

Per fold: a fresh agent is taught the learning set one demonstration at a
time (seeded random order, the configured teacher), then recognizes the
test set without feedback. A test demonstration is classified correctly
when the demonstration its nearest memory entry stands for has the same
true concept (what an oracle teacher would reward). The baselines of
:mod:`iloci.evaluation.baselines` run on the same folds.

This module is the job: what to run and where (:func:`evaluate`,
:func:`default_jobs`). The parts live beside it:

- :mod:`iloci.evaluation.folds`: the split and presentation order per fold;
- :mod:`iloci.evaluation.fold`: one fold, learned then recognized;
- :mod:`iloci.evaluation.results`: one frozen :class:`Answer` per test
  demonstration, one :class:`FoldResult` per fold;
- :mod:`iloci.evaluation.parallel`: the folds on an executor (in this
  process, worker processes or Ray), one code path;
- :mod:`iloci.evaluation.robustness`: the perturbation suite;
- :mod:`iloci.evaluation.summary` and :mod:`iloci.evaluation.provenance`:
  ``metrics.json``.

Progress (per fold and per interaction, with ETA, and the recognition of
each test set) is reported through a callback fed by the
``iloci_on_interaction`` observer hook and the fold tasks.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
import importlib.util
import os
from pathlib import Path
from typing import Any
import time
import warnings

from iloci.config import Config, check_installed, load_config
from iloci.data import load_lasa
from iloci.data.datasets import DataSet, check_protocol, load_dataset_once
from iloci.data.files import writable_dir
from iloci.errors import DataSetWarning, InvalidInputError
from iloci.evaluation.executors import InProcessExecutor, LocalExecutor, make_executor
from iloci.evaluation.fold import LearnedFold, learn_fold, run_fold
from iloci.evaluation.folds import fold_memory_name, fold_plan, untaught_concepts
from iloci.evaluation.parallel import (FoldTask, LocalContext, resolved_specs, run_folds,
                                       warm_up)
from iloci.evaluation.provenance import versions
from iloci.evaluation.report import BASELINE_MODULES, check_report_extras
from iloci.evaluation.results import Answer, Evaluation, FoldResult, memory_counts
from iloci.evaluation.robustness import robustness_suite, summarize_robustness
from iloci.evaluation.summary import data_set_records, summarize
from iloci.events import FoldEvent
from iloci.plugins import get_plugin_manager, get_registry
from iloci.sensorimotor.preprocess import lone_outlier, outlier_note, trim_rests

# The parts are imported here too, where callers have always found them.
__all__ = ["Answer", "Evaluation", "FoldResult", "LearnedFold", "default_jobs", "evaluate",
           "fold_memory_name", "fold_plan", "learn_fold", "memory_counts", "robustness_suite",
           "run_fold", "summarize", "summarize_robustness", "untaught_concepts", "versions"]


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
        "rehearsal"|"recognition"|"recognized"|"fold_done", "fold": k, ...}``
        (``recognition`` and ``recognized``: when the recognition of a fold's
        test set, or of each part of it split over workers, starts and ends;
        :func:`~iloci.evaluation.fold.recognize_test_set`), with ``jobs == 1``
        too.
    folds : sequence of int, optional
        Run only these folds (default: all).
    baseline : bool
        Run the baselines of :mod:`iloci.evaluation.baselines` too.
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
        :class:`FoldResult` per fold, in fold order. With a data set
        (``[data] path``) the metrics also hold ``samples`` (each sample's
        key -> file, concept, writer, session:
        :meth:`~iloci.data.datasets.DataSet.sample_files`) and, writer-disjoint,
        each fold's ``writers_taught`` and ``writers_recognized``.

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
    pm = plugin_manager or get_plugin_manager()
    registry = get_registry(pm)
    config = load_config(config, registry=registry)
    # everything a fold needs is checked before the first one starts
    check_installed(config, registry)
    if baseline:
        if any(importlib.util.find_spec(m) is None for m in BASELINE_MODULES):
            check_report_extras(baseline=True)
    asked = int(jobs if jobs is not None else config.evaluation.jobs)
    if asked < 0 or (jobs is not None and asked == 0):
        raise InvalidInputError(f"jobs must be >= 1, got {asked}.")
    n_folds = config.evaluation.folds
    wanted = list(range(n_folds)) if folds is None else list(folds)
    twice = sorted({k for k in wanted if wanted.count(k) > 1})
    if twice:  # run twice, a fold would count twice in the mean and its spread
        raise InvalidInputError(f"fold(s) {', '.join(map(str, twice))} named more than once "
                                f"(folds {wanted}); name each fold once.")
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
        dataset = load_dataset_once(config.data.path, warn=True)
        check_protocol(dataset, config.evaluation.folds, config.evaluation.split,
                       config.evaluation.seed)
        check_drawings(dataset, config)
        # the config names the files read (workers are sent the demonstrations)
        config = config.replace(data={"path": dataset.source})
    elif config.evaluation.split == "writers":
        fold_plan([], config)  # the error: LASA names no writers
    if memory_dir:  # before any fold is learned, not when the first one is saved
        writable_dir(memory_dir, "memory_dir")
    runner: Any = make_executor(executor, jobs, address=address, plugin_manager=pm)
    shapes = list(config.data.shapes)
    context: Any = None  # workers build the default plugin manager
    if jobs == 1 and isinstance(runner, LocalExecutor):
        # in this process: the observers see every learning event, and each
        # demonstration is converted once, not once per fold
        runner = InProcessExecutor()
        context = LocalContext(pm)
    elif plugin_manager is not None:
        # resolved (and checked to pickle) before any data is loaded or fold run
        context = resolved_specs(config, pm)
    config_dict = config.to_dict()
    if isinstance(runner, LocalExecutor):
        # the workers start (and import what a fold uses) while the data are read
        runner.start(len(wanted) * (2 if baseline else 1),
                     warm_up=(warm_up, (config_dict, context)))
    try:
        demos = dataset.demos if dataset is not None else load_lasa(shapes or None)
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

        tasks = [FoldTask(k, *plan[k], memory_dir=memory_dir) for k in wanted]
        run_folds(config_dict, tasks, demos, runner, baseline=baseline, specs=context,
                  emit=emit, on_result=finished)
    finally:
        if isinstance(runner, LocalExecutor):
            runner.close()  # the workers started for no fold (run_folds stops its own)
    wall = time.perf_counter() - t0
    results.sort(key=lambda r: r.fold)
    metrics = summarize(results, config, wall, jobs, plugin_manager=pm)
    metrics.update(data_set_records(dataset, demos))
    if dataset is not None and config.evaluation.split == "writers":
        for row in metrics["folds"]:  # who taught each fold, whose drawings it read
            learn, test = plan[row["fold"]]
            row["writers_taught"] = dataset.writers_of(learn)
            row["writers_recognized"] = dataset.writers_of(test)
    metrics["split"] = config.evaluation.split
    return Evaluation(metrics, results)


def check_drawings(dataset: DataSet, config: Config) -> None:
    """Refuse, before anything is learned, the samples too short to be read as drawings.

    A file of 3 points or more is read (:class:`~iloci.interfaces.Demonstration`),
    but perception needs ``[sensorimotor] min_points`` once the pen's rests are
    trimmed (:func:`~iloci.sensorimotor.preprocess.preprocess`, docs/guide.md,
    "How a drawing is read"); such a sample would be skipped when taught and
    stop the run when recognized.

    Raises
    ------
    InvalidInputError
        Naming each such file (its path), the points it has left and the setting.
    """
    cfg = config.sensorimotor
    short, glitches = [], []
    for s, d in zip(dataset.samples, dataset.demos):
        n = len(trim_rests(d.positions, d.times, cfg.rest_tolerance)[0])
        glitch = lone_outlier(d.positions)
        if n < cfg.min_points:
            rests = (f" once the pen's rests are trimmed (from {len(d.positions)})"
                     if n < len(d.positions) else "")
            short.append(f"{Path(dataset.root) / s.path}: {n} point(s){rests}"
                         + outlier_note(glitch))
        elif glitch is not None:
            glitches.append(f"{s.path} (sample {glitch[0]}, {glitch[1]:.3g} times its "
                            "size away)")
    if short:
        listed = short[:12] + ([f"... and {len(short) - 12} more"] if len(short) > 12 else [])
        raise InvalidInputError(
            f"data set {dataset.source}: {len(short)} drawing(s) have fewer points than "
            f"[sensorimotor] min_points = {cfg.min_points} (a tap or a click is not a "
            "drawing); nothing was learned:\n  " + "\n  ".join(listed) + "\nRemove them "
            "(or the glitch samples named), record them with more points, or lower "
            "[sensorimotor] min_points (3 at least).")
    if glitches:
        warnings.warn(
            f"data set {dataset.source}: {len(glitches)} drawing(s) have a sample far outside "
            f"the rest of the drawing, a logger's glitch? ({', '.join(glitches[:3])}"
            f"{', ...' if len(glitches) > 3 else ''}). It sets the drawing's size, so the "
            "stroke is read shrunk; remove such samples for a fair score.", DataSetWarning,
            stacklevel=1)  # one place: said once when the CLI checks before evaluate()


def _fold_event(r: FoldResult) -> FoldEvent:
    return FoldEvent(fold=r.fold, metrics={k: getattr(r, k) for k in (
        "ccr", "interactions_per_demo", "exemplars", "prototypes", "concepts",
        "generation_error", "wall_seconds", "baseline_ccr")})
