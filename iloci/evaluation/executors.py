"""Where evaluation folds run: worker processes on this machine, or a plugin's engine.

An executor runs calls ``fn(*args, queue)`` in parallel and yields their
results as they finish; what a call puts on ``queue`` (progress messages,
plain dicts) reaches the caller's ``emit`` while the calls run. Errors raised
in a call (iloci errors survive pickling) reach the caller as themselves.

* ``local`` (:class:`LocalExecutor`, the default): joblib's loky process
  pool on this machine.
* Others come from plugins through the ``iloci_register_executors`` hook,
  as components do (the older ``iloci_make_executor`` hook still works, with
  a DeprecationWarning); the ``iloci-ray`` plugin adds ``ray`` (a local Ray
  instance or a running cluster).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
import concurrent.futures as cf
import itertools
import os
import signal
import sys
import threading
from typing import Any

from iloci.errors import InvalidInputError, PluginError, UnknownComponentError
from iloci.hookspecs import hookimpl
from iloci.interfaces import FoldExecutor, unmet_members
from iloci.plugins import get_plugin_manager, get_registry, hook_results, plugin_infos

__all__ = ["FoldExecutor", "InProcessExecutor", "LocalExecutor", "local_executor",
           "make_executor"]


def _kill(pool: Any) -> None:
    """Kill ``pool``'s workers now and drop its queued calls, without a traceback.

    loky's shutdown with ``kill_workers=True`` empties its table of queued
    calls while their ids are still in its queue; its manager thread then
    looks one up, and the ``KeyError`` it dies of was printed as "Exception
    in thread ExecutorManagerThread" on every Ctrl-C during an evaluation
    (joblib 1.5, loky/process_executor.py, ``add_call_item_to_queue``). The
    workers are killed before that lookup, so the error is harmless: it is
    not printed. The shutdown is waited for (the workers are killed, not
    joined: a fraction of a second), so the filter is removed once that
    thread has ended; every other thread's exception is printed as before.
    """
    previous = threading.excepthook

    def hook(args: Any) -> None:
        if not (args.thread is not None and args.thread.name == "ExecutorManagerThread"
                and args.exc_type is KeyError):
            previous(args)

    threading.excepthook = hook
    try:
        pool.shutdown(wait=True, kill_workers=True)
    finally:
        threading.excepthook = previous


def _worker_init() -> None:
    """Initializer of the pool's workers and of the message queue's server."""
    # The parent handles Ctrl-C and stops the workers.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        # A parent killed outright (SIGKILL) cannot stop its workers: ask the
        # kernel to send them SIGTERM when it dies (prctl PR_SET_PDEATHSIG).
        import ctypes
        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM, 0, 0, 0)
        except (OSError, AttributeError):  # pragma: no cover - no prctl
            pass


class LocalExecutor:
    """Folds in worker processes on this machine: joblib's loky process pool.

    Parameters
    ----------
    jobs : int
        Worker processes (>= 1).

    Notes
    -----
    loky starts workers as fresh interpreters (no fork: torch and JAX
    threads do not survive it), with ``OMP_NUM_THREADS=1`` unless it is set,
    and replaces a worker that crashed by raising
    ``joblib.externals.loky.process_executor.TerminatedWorkerError``. The
    pool is closed (its workers killed) when the calls end by error or
    ``KeyboardInterrupt`` too; when they all finish, the workers are told
    to exit and are not waited for. On Linux a worker also dies with its
    parent. :meth:`start` starts the workers ahead of the calls.
    """

    name = "local"

    def __init__(self, jobs: int) -> None:
        if jobs < 1:
            raise InvalidInputError(f"jobs must be >= 1, got {jobs}.")
        self.jobs = jobs
        self._started: tuple[Any, Any, Any] | None = None  # (manager, queue, pool)

    def start(self, tasks: int | None = None,
              warm_up: tuple[Callable[..., Any], tuple] | None = None) -> None:
        """Start the workers now, so they boot while the caller prepares its calls.

        The next :meth:`run` or :meth:`run_then` uses them; :meth:`close`
        stops them when no call comes (e.g. the caller failed meanwhile).

        Parameters
        ----------
        tasks : int, optional
            Calls to come: at most that many workers are started.
        warm_up : (fn, args), optional
            Called as ``fn(*args, None)`` once per worker (no queue: it
            reports nothing), e.g. to import what the calls will need; its
            result and errors are ignored (a call that needs what failed
            raises the error itself).
        """
        if self._started is None:
            # the workers first: they boot (and warm up) while the queue's server starts
            pool = self._pool(self.jobs if tasks is None else tasks)
            if warm_up is not None:
                for _ in range(self.jobs):
                    pool.submit(warm_up[0], *warm_up[1], None)
            try:
                manager = self._manager()
            except BaseException:
                _kill(pool)
                raise
            self._started = (manager, manager.Queue(), pool)

    def _pool(self, tasks: int) -> Any:
        from joblib.externals.loky import get_reusable_executor

        env = {} if "OMP_NUM_THREADS" in os.environ else {"OMP_NUM_THREADS": "1"}
        return get_reusable_executor(max_workers=min(self.jobs, max(1, tasks)),
                                     initializer=_worker_init, env=env, reuse=False)

    @staticmethod
    def _manager() -> Any:
        import multiprocessing as mp
        from multiprocessing.managers import SyncManager

        # the queue's server process dies with this one too (_worker_init)
        manager = SyncManager(ctx=mp.get_context("spawn"))
        manager.start(_worker_init)
        return manager

    def close(self) -> None:
        """Stop workers started by :meth:`start` that no call used (killed at once)."""
        if self._started is not None:
            manager, _, pool = self._started
            self._started = None
            _kill(pool)
            manager.shutdown()

    def run(self, fn: Callable[..., Any], calls: Sequence[tuple],
            emit: Callable[[dict], None]) -> Iterator[Any]:
        return self.run_then([(fn, args) for args in calls], emit)

    def run_then(self, tasks: Sequence[tuple[Callable[..., Any], tuple]],
                 emit: Callable[[dict], None],
                 then: Callable[[Any], Sequence[tuple[Callable[..., Any], tuple]]]
                 | None = None) -> Iterator[Any]:
        """:meth:`run` over ``(fn, args)`` pairs, each result able to queue more tasks.

        ``then(result)`` (called in the caller as each result arrives,
        before it is yielded) returns further ``(fn, args)`` pairs; they
        run after every task queued before them (the pool takes tasks in
        the order they were queued), so follow-up work fills the workers
        that would otherwise idle while the last long tasks finish.
        Results of every task, first or follow-up, are yielded.
        """
        started, self._started = self._started, None
        if started is None:
            manager = self._manager()
            started = (manager, manager.Queue(), self._pool(len(tasks)))
        manager, queue, pool = started
        finished = False
        try:
            # each future with its place in the queue: results that finish
            # together are handled (then, yield) in the order they were queued,
            # not in a set's order, so follow-ups queue in a fixed order too
            order = itertools.count()
            pending = {pool.submit(fn, *args, queue): next(order) for fn, args in tasks}
            while pending:
                done, _ = cf.wait(pending, timeout=0.2, return_when=cf.FIRST_COMPLETED)
                while not queue.empty():
                    emit(queue.get())
                for fut in sorted(done, key=pending.__getitem__):
                    del pending[fut]
                    result = fut.result()
                    for fn, args in (then(result) if then is not None else ()):
                        pending[pool.submit(fn, *args, queue)] = next(order)
                    yield result
            finished = True
        finally:
            # workers are killed unless every call finished: an error, Ctrl-C,
            # or a caller that stopped iterating; else they exit on their own
            # (nothing is left for them to do: not waited for)
            if finished:
                pool.shutdown(wait=False)
            else:
                _kill(pool)
            manager.shutdown()


class _Relay:
    """A queue whose ``put`` hands the message to ``emit`` at once (no process between)."""

    def __init__(self, emit: Callable[[dict], None]) -> None:
        self.put = emit


class InProcessExecutor:
    """Folds one after the other in this process: ``jobs == 1`` on the local executor.

    The same calls the worker processes get, made here: the caller's plugin
    manager (and its observers) can be handed to them, as nothing needs to
    pickle.
    """
    name = "local"
    jobs = 1

    def run(self, fn: Callable[..., Any], calls: Sequence[tuple],
            emit: Callable[[dict], None]) -> Iterator[Any]:
        """Call ``fn(*args, queue)`` for each ``args`` of ``calls`` in order; yield results."""
        queue = _Relay(emit)
        for args in calls:
            yield fn(*args, queue)


def make_executor(name: str, jobs: int, *, address: str | None = None,
                  plugin_manager: Any = None) -> FoldExecutor:
    """The executor called ``name``, with ``jobs`` parallel folds.

    Parameters
    ----------
    name : str
        ``"local"`` or one a plugin registers (``iloci_register_executors``;
        the deprecated ``iloci_make_executor`` hook is asked first).
    jobs : int
        Folds run at once.
    address : str, optional
        Where the executor's engine runs (e.g. a Ray cluster's
        ``HOST:PORT``); ``local`` takes none.
    plugin_manager : pluggy.PluginManager, optional

    Raises
    ------
    MissingBackendError
        ``ray`` without the ``iloci-ray`` plugin, or a registered
        executor's library is missing (with its install command).
    PluginError
        A plugin's ``iloci_make_executor`` returned something that is not an
        executor (naming the plugin and its distribution).
    InvalidInputError
        An unknown name, or ``address`` for ``local``.
    """
    pm = plugin_manager or get_plugin_manager()
    _warn_old_hook(pm)
    for made, plugin, distribution in hook_results(pm, "iloci_make_executor", name=name,
                                                   jobs=jobs, address=address):
        unmet = unmet_members(made, FoldExecutor)
        if unmet or isinstance(made, type):
            raise PluginError(
                f"plugin {plugin!r} (distribution {distribution or 'none'}): its "
                f"iloci_make_executor returned {type(made).__name__} {made!r:.60} for executor "
                f"{name!r}, which is not a fold executor: it lacks "
                f"{', '.join(unmet) or 'an instance'} (see iloci.interfaces.FoldExecutor). Fix "
                f"the plugin, or block it with ILOCI_BLOCK_PLUGINS={plugin}.")
        return made  # the first result, as pluggy's firstresult hook gives it
    registry = get_registry(pm)
    try:
        registry.get("executor", name)
    except UnknownComponentError as exc:
        raise InvalidInputError(f"unknown executor {name!r}: {exc}") from None
    return registry.build("executor", name, jobs=jobs, address=address)


def _warn_old_hook(pm: Any) -> None:
    """A DeprecationWarning for each plugin implementing ``iloci_make_executor``."""
    import warnings

    info = plugin_infos(pm)
    for impl in pm.hook.iloci_make_executor.get_hookimpls():
        dist = getattr(info.get(impl.plugin_name), "distribution", None)
        warnings.warn(
            f"iloci plugin {impl.plugin_name!r}" + (f" (distribution {dist})" if dist else "")
            + " implements iloci_make_executor: deprecated. Register the executor with "
            "iloci_register_executors(registry): registry.add(name, factory, requires=..., "
            "install=...), so `iloci plugins` lists it (docs/hooks.md).",
            DeprecationWarning, stacklevel=3)


def local_executor(jobs: int, address: str | None = None) -> LocalExecutor:
    """The kernel's ``local`` executor (registered through ``iloci_register_executors``).

    Raises
    ------
    InvalidInputError
        ``address`` is given: the local executor runs on this machine.
    """
    if address is not None:
        raise InvalidInputError("the local executor runs on this machine: --address "
                                "needs another executor (e.g. --executor ray).")
    return LocalExecutor(jobs)


@hookimpl
def iloci_register_executors(registry: Any) -> None:
    registry.add("local", local_executor,
                 summary="worker processes on this machine (joblib's loky pool)")
