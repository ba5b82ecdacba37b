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
import hashlib
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from iloci.errors import IlociError

__all__ = [
    "PROGRESS_KEY",
    "MemoryLockedError",
    "SHOW_AFTER",
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


def item_digest(item: Any) -> str:
    """A digest (hex) of one stream item: a Demonstration, a trajectory file, or an array.

    Two items get one digest exactly when they would teach the same thing.
    """
    from iloci.interfaces import Demonstration
    h = hashlib.sha256()
    if isinstance(item, Demonstration):
        h.update(b"demo\0" + item.key.encode() + b"\0" + str(item.true_concept).encode())
        h.update(np.ascontiguousarray(item.positions, dtype=np.float64).tobytes())
        h.update(np.ascontiguousarray(item.times, dtype=np.float64).tobytes())
    elif isinstance(item, (str, os.PathLike)):
        key = getattr(item, "key", None) or Path(item).stem
        h.update(b"file\0" + str(key).encode() + b"\0")
        try:
            h.update(Path(os.fspath(item)).read_bytes())
        except OSError as exc:
            h.update(f"unreadable: {type(exc).__name__}".encode())
    else:
        try:
            arr = np.asarray(item, dtype=np.float64)
        except (TypeError, ValueError):
            h.update(b"other\0" + repr(item).encode())
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


@contextlib.contextmanager
def teaching_lock(memory: str | os.PathLike[str]) -> Iterator[Path]:
    """Hold ``MEMORY.lock`` while teaching ``memory``; never wait for it.

    The lock is an OS file lock (:mod:`filelock`), released by the kernel
    when its process dies, even by ``kill -9``: a crashed session never
    leaves the memory locked. The empty lock file itself may stay.

    Raises
    ------
    MemoryLockedError
        Another process holds the lock.
    """
    from filelock import FileLock, Timeout
    path = Path(os.fspath(memory))
    lock_path = path.with_name(path.name + ".lock")
    lock = FileLock(lock_path, timeout=0)
    try:
        lock.acquire()
    except Timeout:
        raise MemoryLockedError(
            f"the memory {path} is being taught by another process (it holds {lock_path}); "
            "wait for it to finish, or teach another --memory file. Nothing was changed."
        ) from None
    except OSError as exc:
        raise MemoryLockedError(f"cannot lock the memory {path} ({lock_path}: "
                                f"{exc.strerror or exc}).") from None
    try:
        yield lock_path
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
    import time
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
