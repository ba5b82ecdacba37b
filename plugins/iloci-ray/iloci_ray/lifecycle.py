"""Nothing of a Ray that ``iloci sweep`` started is left running after it ends.

A Ray started here (no ``--address``) is a dozen processes: the GCS server,
the raylet, the dashboard and runtime-env agents, log monitors, and one
worker per task. ``ray.shutdown()`` stops them when the sweep ends normally
or on Ctrl-C (:func:`owned_ray` calls it on every ending it sees, SIGTERM
included). A driver killed with SIGKILL sees nothing: some of those
processes (the agents) outlive it. So every sweep that starts Ray records it
in a marker file (its own process and Ray's session directory); the next
sweep (or :func:`reap_orphans`) finds the markers of drivers that are gone and
stops every process of their Ray: the processes recorded, their descendants,
and any whose command line names the session directory.

Linux only (it reads ``/proc``); elsewhere the markers are kept and nothing
is reaped.
"""

from __future__ import annotations

from collections.abc import Iterator
import contextlib
import json
import os
from pathlib import Path
import signal
import time
from typing import Any

__all__ = ["import_ray", "marker_dir", "owned_ray", "ray_processes", "reap_orphans"]

_PROC = Path("/proc")


def import_ray(kind: str = "command", what: str = "iloci sweep") -> Any:
    """The ``ray`` module; :class:`~iloci.errors.MissingBackendError` naming ``what``
    and how to install it when Ray is not installed or does not import (a broken
    install, a version built for another Python)."""
    try:
        import ray
    except ImportError as exc:
        from iloci.errors import MissingBackendError
        raise MissingBackendError(
            kind, what, [f"ray ({type(exc).__name__}: {exc})"],
            "pip install 'ray>=2.9' (or reinstall ./plugins/iloci-ray), then run "
            "`python -c \"import ray\"` to see that it imports") from exc
    return ray


def marker_dir() -> Path:
    """Where sweeps record the Ray they started: ``$ILOCI_CACHE_DIR`` (or
    ``~/.cache/iloci``) ``/ray-sweeps``."""
    root = os.environ.get("ILOCI_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "iloci")
    return Path(root) / "ray-sweeps"


def _start_time(pid: int) -> int | None:
    """The process's start time (clock ticks since boot; /proc/PID/stat field 22), or None."""
    try:
        stat = (_PROC / str(pid) / "stat").read_text()
    except OSError:
        return None
    return int(stat.rpartition(")")[2].split()[19])


def _children() -> dict[int, list[int]]:
    out: dict[int, list[int]] = {}
    for d in _PROC.glob("[0-9]*"):
        try:
            ppid = int((d / "stat").read_text().rpartition(")")[2].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        out.setdefault(ppid, []).append(int(d.name))
    return out


def _descendants(pids: list[int]) -> list[int]:
    kids = _children()
    out, todo = [], list(pids)
    while todo:
        p = todo.pop()
        for c in kids.get(p, ()):
            if c not in out:
                out.append(c)
                todo.append(c)
    return out


def _cmdline(pid: int) -> str:
    try:
        return (_PROC / str(pid) / "cmdline").read_bytes().replace(b"\0", b" ").decode(
            errors="replace")
    except OSError:
        return ""


def ray_processes(session_dir: str, also: list[int] = ()) -> list[int]:
    """Live processes of one Ray: those naming ``session_dir`` on their command line,
    the ``also`` pids, and every descendant of either (workers, agents)."""
    if not _PROC.is_dir():
        return []
    named = [int(d.name) for d in _PROC.glob("[0-9]*")
             if session_dir and session_dir in _cmdline(int(d.name))]
    roots = [p for p in {*named, *also} if _start_time(p) is not None]
    return sorted({*roots, *_descendants(roots)} - {os.getpid()})


def _kill(pids: list[int], grace: float = 3.0) -> None:
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for p in pids:
            with contextlib.suppress(OSError):
                os.kill(p, sig)
        deadline = time.monotonic() + grace
        while time.monotonic() < deadline and any(_alive(p) for p in pids):
            time.sleep(0.1)
        pids = [p for p in pids if _alive(p)]
        if not pids:
            return


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, dead but not reaped by its parent, does not)."""
    try:
        state = (_PROC / str(pid) / "stat").read_text().rpartition(")")[2].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X")


def reap_orphans() -> int:
    """Stop the Ray of every sweep whose driver is gone (killed with SIGKILL); return how
    many processes were stopped. Markers of live drivers are left alone."""
    if not _PROC.is_dir():
        return 0
    stopped = 0
    for f in sorted(marker_dir().glob("*.json")):
        try:
            m = json.loads(f.read_text())
            pid, started, session = int(m["pid"]), m["start_time"], str(m["session_dir"])
            recorded = [int(p) for p, t in m.get("processes", []) if _start_time(int(p)) == t]
        except (OSError, ValueError, KeyError, TypeError):
            f.unlink(missing_ok=True)
            continue
        if _start_time(pid) == started and _alive(pid):
            continue  # that sweep still runs
        pids = ray_processes(session, recorded)
        _kill(pids)
        stopped += len(pids)
        f.unlink(missing_ok=True)
    return stopped


def _session_dir(ray: Any) -> str:
    try:
        return str(ray._private.worker._global_node.get_session_dir_path())
    except AttributeError:  # another Ray version: the processes recorded still count
        return ""


class _Marker:
    """This driver's record of the Ray it started (refreshed as workers come and go)."""

    def __init__(self, ray: Any) -> None:
        self.pid = os.getpid()
        self.session = _session_dir(ray)
        self.path = marker_dir() / f"{self.pid}.json"

    def write(self) -> None:
        if not _PROC.is_dir():
            return
        procs = [[p, _start_time(p)] for p in ray_processes(self.session, [self.pid])]
        data = {"pid": self.pid, "start_time": _start_time(self.pid),
                "session_dir": self.session, "processes": procs}
        with contextlib.suppress(OSError):  # a read-only home only loses the kill -9 case
            self.path.parent.mkdir(parents=True, exist_ok=True)
            tmp = self.path.with_suffix(".tmp")
            tmp.write_text(json.dumps(data))
            os.replace(tmp, self.path)

    def stop(self, ray: Any) -> None:
        """Shut Ray down, then stop whatever of it is still running; drop the marker."""
        leftover_roots = ray_processes(self.session, [])
        with contextlib.suppress(Exception):
            ray.shutdown()
        pids = [p for p in ray_processes(self.session, leftover_roots) if p != self.pid]
        _kill(pids)
        self.path.unlink(missing_ok=True)


@contextlib.contextmanager
def owned_ray(address: str | None, jobs: int | None) -> Iterator[tuple[Any, Any]]:
    """Ray for one sweep: ``(ray, refresh)``, ``refresh()`` updating the marker.

    With ``address`` None, Ray is started here and everything of it is stopped
    when the block ends, whatever the ending (return, exception, Ctrl-C,
    SIGTERM); orphans of earlier sweeps killed with SIGKILL are stopped first.
    With an address, the cluster is only connected to, and left running.
    """
    from iloci_ray.executor import connect

    if address is not None:
        yield connect(address, jobs), (lambda: None)
        return
    reap_orphans()
    was_running = _ray_initialized()
    previous = signal.getsignal(signal.SIGTERM)

    def on_term(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt  # unwinds through the finally below

    with contextlib.suppress(ValueError):  # not the main thread: no handler
        signal.signal(signal.SIGTERM, on_term)
    ray = connect(None, jobs)
    marker = _Marker(ray)
    marker.write()
    try:
        yield ray, marker.write
    finally:
        if not was_running:  # a Ray the caller started (tests) stays theirs
            marker.stop(ray)
        else:
            marker.path.unlink(missing_ok=True)
        with contextlib.suppress(ValueError, TypeError):
            signal.signal(signal.SIGTERM, previous)


def _ray_initialized() -> bool:
    return bool(import_ray().is_initialized())
