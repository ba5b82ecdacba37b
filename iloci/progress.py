"""Progress through a learning stream, kept in the memory file, and the memory's lock;
progress of one long step (:func:`long_step`).

``iloci teach`` saves the memory after every demonstration that changed it
(atomically: a kill at any moment leaves the previous file or the new one).
With each save it records how far through its stream it got: the number of
stream items consumed and a digest of those items. Run again with the same
stream, it finds that the recorded digest is that of the stream's first
items and skips them, so no demonstration is learned twice and the memory
ends as an uninterrupted run's would.

The digest of an item is what it *is*, not where it came from: a
demonstration's key, concept, positions and times; a trajectory file's key
and bytes. Editing a file, or reordering the stream before the recorded
point, is therefore a different stream, which is taught from its start
(continuing the memory, as ``iloci teach`` always does).
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from iloci.errors import IlociError
from iloci.interfaces import Demonstration

__all__ = [
    "PROGRESS_KEY",
    "MemoryLockedError",
    "SHOW_AFTER",
    "acquire_memory_lock",
    "lock_path_of",
    "memory_lock",
    "saving",
    "why_not_saved",
    "why_not_written",
    "item_digest",
    "long_step",
    "progress_sink",
    "prefix_digest",
    "progress_record",
    "resume_point",
    "teaching_lock",
]

#: Header key of the progress record in a memory file.
PROGRESS_KEY = "teach_progress"


class MemoryLockedError(IlociError, RuntimeError):
    """Another process is teaching the same memory file."""


#: A trajectory file larger than this (bytes) is digested by its size and first 64 kB:
#: every reader refuses such a file (iloci.data.csvfile.MAX_BYTES is 512 MB) before
#: reading it, so reading gigabytes to digest it would only delay that error.
DIGEST_WHOLE_UP_TO = 1 << 30


def item_digest(item: Any) -> str:
    """A digest (hex) of one stream item: a Demonstration, a trajectory file, or an array.

    Two items get one digest exactly when they would teach the same thing.
    """
    h = hashlib.sha256()
    if isinstance(item, Demonstration):
        h.update(b"demo\0" + item.key.encode("utf-8", "surrogatepass") + b"\0"
                 + str(item.true_concept).encode("utf-8", "surrogatepass"))
        h.update(np.ascontiguousarray(item.positions, dtype=np.float64).tobytes())
        h.update(np.ascontiguousarray(item.times, dtype=np.float64).tobytes())
    elif isinstance(item, (str, os.PathLike)):
        key = getattr(item, "key", None) or Path(item).stem
        h.update(b"file\0" + str(key).encode("utf-8", "surrogatepass") + b"\0")
        try:
            with open(os.fspath(item), "rb") as fh:
                size = os.fstat(fh.fileno()).st_size
                if size > DIGEST_WHOLE_UP_TO:  # no drawing: its reader refuses it unread
                    h.update(b"large\0" + str(size).encode() + b"\0" + fh.read(65536))
                else:  # in pieces: a big file is never held whole for its digest
                    for block in iter(lambda: fh.read(1 << 20), b""):
                        h.update(block)
        except OSError as exc:
            h.update(f"unreadable: {type(exc).__name__}".encode())
    else:
        try:
            arr = np.asarray(item, dtype=np.float64)
        except (TypeError, ValueError):
            h.update(b"other\0" + repr(item).encode("utf-8", "surrogatepass"))
        else:
            h.update(b"array\0" + repr(arr.shape).encode() + arr.tobytes())
    return h.hexdigest()


def prefix_digest(digests: Sequence[str], n: int) -> str:
    """Digest of the first ``n`` item digests, in order."""
    h = hashlib.sha256(b"iloci-stream-v1")
    for d in digests[:n]:
        h.update(bytes.fromhex(d))
    return h.hexdigest()


def progress_record(digests: Sequence[str], consumed: int) -> dict[str, Any]:
    """The header value recording that the first ``consumed`` items were taught."""
    return {"items": int(consumed), "of": len(digests),
            "digest": prefix_digest(digests, consumed)}


def resume_point(record: Any, digests: Sequence[str]) -> int:
    """How many leading items of a stream are already taught (0: none, or another stream).

    Parameters
    ----------
    record : mapping or None
        The memory header's :data:`PROGRESS_KEY` value.
    digests : sequence of str
        :func:`item_digest` of each item of the stream about to be taught.
    """
    if not isinstance(record, Mapping):
        return 0
    n = record.get("items")
    if not isinstance(n, int) or isinstance(n, bool) or not 0 < n <= len(digests):
        return 0
    return n if record.get("digest") == prefix_digest(digests, n) else 0


#: errno values of a write the machine refused (not a fault of iloci or of the input):
#: no space, a file size limit, a quota; no permission, a read-only disk.
FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EFBIG, getattr(errno, "EDQUOT", errno.ENOSPC)})
REFUSED_ERRNOS = FULL_ERRNOS | {errno.EACCES, errno.EPERM, errno.EROFS}


def why_not_written(path: str | os.PathLike[str], exc: OSError,
                    what: str = "write") -> str:
    """``"could not write PATH: the disk is full (...)."``: a failed write in words.

    ``what``: the verb phrase before the path (``"save the memory to"``).
    """
    why = exc.strerror or str(exc)
    if exc.errno in FULL_ERRNOS:
        cause = "the disk is full (or the file size limit is reached)"
    elif exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        cause = "it may not be written (permissions, or a read-only disk)"
    else:
        cause = "the system refused"
    target = os.path.realpath(path)
    where = str(path) if target == os.fspath(path) else f"{path} (a link to {target})"
    return f"could not {what} {where}: {cause} ({why})."


def why_not_saved(path: str | os.PathLike[str], exc: OSError) -> str:
    """``"could not save the memory to PATH: the disk is full (...)."``: a failed save in words."""
    return why_not_written(path, exc, "save the memory to")


#: Memory locks this process holds: real path of the memory -> (lock, holder record).
_HELD: dict[str, tuple[Any, dict[str, Any], list[int | None]]] = {}
_HELD_GUARD = threading.Lock()


def lock_path_of(memory: str | os.PathLike[str]) -> Path:
    """The lock file of a memory: ``TARGET.lock`` beside the file a symlink points to."""
    target = Path(os.path.realpath(os.fspath(memory)))
    return target.with_name(target.name + ".lock")


def _holder_path(lock_path: Path) -> Path:
    # the lock file itself is truncated by whoever tries it, so the holder's
    # record is kept beside it
    return lock_path.with_name(lock_path.name + ".json")


def _holder_text(lock_path: Path) -> str:
    """``"iloci serve, pid 123, since 2026-12-01 21:40:03 UTC"`` or a vaguer phrase."""
    try:
        rec = json.loads(_holder_path(lock_path).read_text(encoding="utf-8"))
        when = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(float(rec["since"])))
        return f"{str(rec['command'])[:60]}, pid {int(rec['pid'])}, since {when}"
    except (OSError, ValueError, KeyError, TypeError, OverflowError):
        return "another process (it did not say which)"


def _locked_error(memory: str | os.PathLike[str], lock_path: Path) -> MemoryLockedError:
    return MemoryLockedError(
        f"the memory {memory} is being taught by another process or session: "
        f"{_holder_text(lock_path)} (it holds {lock_path}). Stop that one first, or "
        "use another --memory file. Nothing was changed.")


def acquire_memory_lock(memory: str | os.PathLike[str],
                        command: str = "iloci") -> Callable[[], None]:
    """Lock ``memory`` for one writer (``iloci teach``, ``iloci serve``); never wait.

    The lock is an OS file lock (:mod:`filelock`) on ``TARGET.lock``, where
    TARGET is the file a symlinked memory path points to, so every path to
    one file shares one lock. The kernel releases it when the process dies,
    even by ``kill -9``: a crashed session never leaves the memory locked.
    Beside it, ``TARGET.lock.json`` names the holder (``command``, pid,
    since when) for the error a second writer gets. While it is held,
    :meth:`Agent.save <iloci.agent.Agent.save>` in this process writes
    ``memory``, and any other process's save of it is refused.

    Returns
    -------
    callable
        Releases the lock (idempotent).

    Raises
    ------
    MemoryLockedError
        Another process, or another session of this one, holds it; the
        message names the holder.
    """
    from filelock import FileLock, Timeout
    lock_path = lock_path_of(memory)
    key = str(lock_path)
    with _HELD_GUARD:
        if key in _HELD:
            raise _locked_error(memory, lock_path)
        lock = FileLock(lock_path, timeout=0, thread_local=False)
        try:
            lock.acquire()
        except Timeout:
            raise _locked_error(memory, lock_path) from None
        except OSError as exc:
            raise MemoryLockedError(f"cannot lock the memory {memory} ({lock_path}: "
                                    f"{exc.strerror or exc}).") from None
        try:
            file_lock = _lock_the_file(memory)
        except BaseException:
            lock.release()
            raise
        record = {"command": command, "pid": os.getpid(), "since": time.time()}
        with contextlib.suppress(OSError):
            _holder_path(lock_path).write_text(json.dumps(record), encoding="utf-8")
        # the file's own lock, moved to each new file a save writes (saving())
        _HELD[key] = (lock, record, [file_lock])

    def release() -> None:
        with _HELD_GUARD:
            held = _HELD.pop(key, None)
            if held is None:
                return
            with contextlib.suppress(OSError):
                _holder_path(lock_path).unlink()
            for fd in held[2]:
                if fd is not None:
                    with contextlib.suppress(OSError):
                        os.close(fd)
            held[0].release()
    return release


def _relock_the_file(key: str, memory: str | os.PathLike[str]) -> None:
    """After a save by the lock's holder: its file lock moves to the file just written.

    A save replaces the memory file by a new one (a new inode); a hard link made
    to it after the save names that new file, which the old lock does not cover.
    """
    with _HELD_GUARD:
        held = _HELD.get(key)
        if held is None:
            return
        fds = held[2]
        try:
            new = _lock_the_file(memory)
        except MemoryLockedError:
            return  # another name of the new file is already locked: its writer's error
        for fd in fds:
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        fds[:] = [new]


def _lock_the_file(memory: str | os.PathLike[str]) -> int | None:
    """An OS lock on the memory file itself (its inode), held through an open descriptor.

    ``TARGET.lock`` is one per name; a hard link is another name of the same
    file, so two writers through two names would each hold their own
    ``.lock``. The file's own lock is shared by all its names. (A save
    replaces the file by a new one, so the lock stays on the file as it was
    when the writer started: what another name of it still shows.)
    Returns the descriptor (closed to release), or None where the file does
    not exist yet or the platform has no ``flock``.

    Raises
    ------
    MemoryLockedError
        Another process holds it: the memory is taught under another name.
    """
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        return None
    try:
        fd = os.open(os.path.realpath(os.fspath(memory)), os.O_RDONLY)
    except OSError:
        return None                                 # a new memory: nothing to share
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        st = os.fstat(fd)
        os.close(fd)
        raise MemoryLockedError(
            f"the memory {memory} is being taught by another process under another name "
            f"(a hard link to the same file): {_flock_holder(st)}. Stop that one first, or "
            "copy the file (cp) to teach a separate memory. Nothing was changed.") from None
    return fd


def _flock_holder(st: os.stat_result) -> str:
    """``"iloci serve, pid 123"``: who holds an flock on the file ``st`` (from /proc/locks)."""
    want = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    try:
        with open("/proc/locks", encoding="ascii", errors="replace") as fh:
            for line in fh:
                parts = line.split()
                if len(parts) > 5 and parts[1] == "FLOCK" and parts[5] == want:
                    pid = int(parts[4])
                    cmd = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
                    words = [Path(cmd[0].decode(errors="replace")).name,
                             *(c.decode(errors="replace") for c in cmd[1:3] if c)]
                    return f"{' '.join(words)[:60]}, pid {pid}"
    except (OSError, ValueError):
        pass
    return "another process"


@contextlib.contextmanager
def memory_lock(memory: str | os.PathLike[str], command: str = "iloci") -> Iterator[Path]:
    """:func:`acquire_memory_lock` as a context manager; yields the lock file's path."""
    release = acquire_memory_lock(memory, command)
    try:
        yield lock_path_of(memory)
    finally:
        release()


@contextlib.contextmanager
def teaching_lock(memory: str | os.PathLike[str]) -> Iterator[Path]:
    """Hold the memory's lock while ``iloci teach`` teaches it (see :func:`memory_lock`).

    Raises
    ------
    MemoryLockedError
        Another process holds the lock.
    """
    with memory_lock(memory, "iloci teach") as path:
        yield path


@contextlib.contextmanager
def saving(memory: str | os.PathLike[str]) -> Iterator[None]:
    """Around one save of ``memory``: the lock this process holds, or the lock for the save.

    Raises
    ------
    MemoryLockedError
        Another process (``iloci serve``, ``iloci teach``) holds the
        memory's lock: its work would be overwritten. Nothing is written.
    """
    key = str(lock_path_of(memory))
    with _HELD_GUARD:
        mine = key in _HELD
    if mine:
        yield
        _relock_the_file(key, memory)  # the file just written is the one to guard now
        return
    if not os.path.exists(key):
        # never locked by anyone (a writer's lock file stays after it ends): no lock
        # file is made for a plain save
        yield
        return
    from filelock import FileLock, Timeout
    lock = FileLock(key, timeout=0, thread_local=False)
    try:
        lock.acquire()
    except Timeout:
        raise _locked_error(memory, Path(key)) from None
    except OSError:
        # a directory where no lock file can be made: the save itself reports it
        yield
        return
    try:
        yield
    finally:
        lock.release()


# -- progress of one long step ---------------------------------------------------------

#: Seconds a step runs before its progress is shown (a quick one shows nothing).
SHOW_AFTER = 1.0
#: Shortest time between two reports of one step (s).
_EVERY = 1.0
_SINKS: list[Callable[[str, float, float], None]] = []


@contextlib.contextmanager
def progress_sink(sink: Callable[[str, float, float], None]) -> Iterator[None]:
    """Tell ``sink(what, fraction, seconds)`` the progress of every :func:`long_step`
    run inside the block (the command line prints it to stderr).

    ``fraction`` is in [0, 1] (1: the step is done); ``seconds`` the time it
    has run. A step is reported once it has run :data:`SHOW_AFTER` seconds,
    then at most once a second, and when it ends.
    """
    _SINKS.append(sink)
    try:
        yield
    finally:
        _SINKS.remove(sink)


@contextlib.contextmanager
def long_step(what: str) -> Iterator[Callable[[float], None]]:
    """A step that may take seconds (reading a huge file, preprocessing a huge stroke).

    Yields ``report(fraction)``, to call as the work advances; it costs a
    clock reading when nobody listens (:func:`progress_sink`).

    Parameters
    ----------
    what : str
        What is being done, e.g. ``"reading stroke.csv (1,000,000 samples)"``.
    """
    start = time.monotonic()
    last = [start - _EVERY]
    shown = [False]

    def report(fraction: float) -> None:
        if not _SINKS:
            return
        now = time.monotonic()
        if now - start >= SHOW_AFTER and now - last[0] >= _EVERY:
            last[0] = now
            shown[0] = True
            for sink in list(_SINKS):
                sink(what, min(max(float(fraction), 0.0), 1.0), now - start)

    yield report
    if shown[0] or (_SINKS and time.monotonic() - start >= SHOW_AFTER):
        for sink in list(_SINKS):
            sink(what, 1.0, time.monotonic() - start)
