"""Evaluation folds as Ray tasks (``iloci evaluate --executor ray``)."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
import logging
import os
from typing import Any

from iloci.errors import IlociError, InvalidInputError

__all__ = ["RayExecutor", "connect"]

#: Each task is one fold on one core; its numerical libraries use one thread.
TASK_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
            "XLA_FLAGS": "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"}


def connect(address: str | None, num_cpus: int | None = None) -> Any:
    """Ray, initialized once per process: started here, or the cluster at ``address``.

    Parameters
    ----------
    address : str or None
        ``HOST:PORT`` of a running cluster (``ray start --head`` prints
        it), ``"auto"`` for the one this machine runs, or None to start Ray
        on this machine (stopped when this process exits). A cluster with
        token authentication needs ``RAY_AUTH_MODE=token`` in the
        environment for an explicit ``HOST:PORT`` (Ray's rule).
    num_cpus : int, optional
        CPUs of a Ray started here (default: all); ignored with ``address``.

    Raises
    ------
    InvalidInputError
        No cluster answers at ``address``.
    """
    from iloci_ray.lifecycle import import_ray
    ray = import_ray("fold executor", "ray")

    if ray.is_initialized():
        return ray
    if address not in (None, "auto"):
        _check_reachable(address)
    env = {k: os.environ.get(k, v) for k, v in TASK_ENV.items()}
    kwargs: dict[str, Any] = {"runtime_env": {"env_vars": env}, "include_dashboard": False,
                              "logging_level": logging.WARNING, "log_to_driver": True}
    if address is None:
        # "local": a new Ray of this process's own, never a cluster that
        # happens to run on this machine (what ray.init() would join)
        address = "local"
        kwargs["num_cpus"] = num_cpus
    # Ray sends the driver's command line (read from /proc) to its C++ core as UTF-8:
    # a file name the OS gave as bytes that are not UTF-8 (lone surrogates) made
    # ray.init fail; it is passed with those bytes written \xNN
    from ray._private import utils as ray_utils
    entrypoint = getattr(ray_utils, "get_entrypoint_name", None)
    if entrypoint is not None:
        ray_utils.get_entrypoint_name = lambda: _utf8(entrypoint())
    try:
        ray.init(address=address, **kwargs)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        auth = ("" if os.environ.get("RAY_AUTH_MODE") else
                " A cluster with token authentication (Ray's default) also needs "
                "RAY_AUTH_MODE=token in this environment (the token is read from "
                "RAY_AUTH_TOKEN or ~/.ray/auth_token): Ray never sends it to an address "
                "given explicitly unless told to.")
        raise InvalidInputError(f"no Ray cluster at {address!r}: {exc}. Start one with "
                                "`ray start --head` and pass the address it prints "
                                "(HOST:PORT), or omit --address to start Ray here." + auth
                                ) from exc
    finally:
        if entrypoint is not None:
            ray_utils.get_entrypoint_name = entrypoint
    return ray


def _utf8(text: str) -> str:
    """``text`` encodable as UTF-8: lone surrogates (undecodable bytes) written ``\\xNN``."""
    return text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace") \
        if isinstance(text, str) else text


def _check_reachable(address: str, timeout: float = 5.0) -> None:
    """Fail fast when nothing listens at ``HOST:PORT`` (ray.init retries for minutes)."""
    import socket

    host, sep, port = address.rpartition(":")
    if not sep or not port.isdigit():
        raise InvalidInputError(f"--address must be HOST:PORT (e.g. 10.0.0.5:6379), got "
                                f"{address!r}.")
    host = host.removeprefix("ray://").strip("[]")
    try:
        socket.create_connection((host, int(port)), timeout=timeout).close()
    except OSError as exc:
        raise InvalidInputError(f"no Ray cluster at {address!r}: {exc}. Start one with "
                                "`ray start --head` and pass the address it prints "
                                "(HOST:PORT), or omit --address to start Ray here.") from None


def unwrap(exc: BaseException) -> BaseException:
    """The iloci error a Ray task raised (Ray wraps it), else ``exc``."""
    cause = getattr(exc, "cause", None)
    return cause if isinstance(cause, IlociError) else exc


class RayExecutor:
    """Runs calls as Ray tasks, at most ``jobs`` at once, one CPU each.

    Parameters
    ----------
    jobs : int
        Tasks in flight at once (>= 1).
    address : str, optional
        A running cluster (see :func:`connect`); None starts Ray here with
        ``jobs`` CPUs.

    Notes
    -----
    Progress messages travel through a ``ray.util.queue.Queue`` (an actor)
    from the tasks to the caller. Every task is cancelled when the caller
    stops early (an error, Ctrl-C).
    """

    name = "ray"

    def __init__(self, jobs: int, *, address: str | None = None) -> None:
        if jobs < 1:
            raise InvalidInputError(f"jobs must be >= 1, got {jobs}.")
        self.jobs = jobs
        self.address = address

    def run(self, fn: Callable[..., Any], calls: Sequence[tuple],
            emit: Callable[[dict], None]) -> Iterator[Any]:
        ray = connect(self.address, self.jobs)
        from ray.util.queue import Queue

        queue = Queue()
        remote = ray.remote(num_cpus=1, max_retries=0)(fn)
        waiting = list(calls)
        running: list[Any] = []
        try:
            while waiting or running:
                while waiting and len(running) < self.jobs:
                    running.append(remote.remote(*waiting.pop(0), queue))
                done, running = ray.wait(running, num_returns=1, timeout=0.2)
                _drain(queue, emit)
                for ref in done:
                    try:
                        result = ray.get(ref)
                    except Exception as exc:
                        raise unwrap(exc) from None
                    yield result
            _drain(queue, emit)
        finally:
            for ref in running:
                ray.cancel(ref, force=True)
            ray.kill(queue.actor)


def _drain(queue: Any, emit: Callable[[dict], None]) -> None:
    n = queue.qsize()
    if n:
        for msg in queue.get_nowait_batch(n):
            emit(msg)
