"""A user's own pen trajectories from ``.npy`` or ``.csv`` files; atomic file writes."""

from __future__ import annotations

import csv
import errno
import os
import secrets
import stat
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

import numpy as np

from iloci.errors import InvalidDemonstrationError, InvalidInputError
from iloci.interfaces import Demonstration

__all__ = ["load_trajectory", "write_atomic", "write_text_atomic"]

_TIME_NAMES = ("t", "time", "times", "timestamp")


def load_trajectory(path: str | os.PathLike[str], *, shape: str | None = None,
                    true_concept: str | None = None, index: int = 0) -> Demonstration:
    """Read one pen trajectory from a file.

    Two layouts, in either format:

    * ``N x 2``: pen positions ``x, y`` (any unit); times default to
      ``0, 1, ..., N-1``.
    * ``N x 3``: ``t, x, y`` with the time stamps (s) in the first column.

    A ``.csv`` file is comma separated and may start with one header row;
    a header names the time column ``t`` or ``time`` (any position) and the
    other two columns are ``x, y`` in order. A ``.npy`` file holds a plain
    float array (loaded without pickle).

    Parameters
    ----------
    path : str or path-like
    shape : str, optional
        Name of the drawn shape; defaults to the file's stem.
    true_concept : str, optional
        The true concept, if known (see :class:`~iloci.interfaces.Demonstration`).
    index : int
        Demonstration index (the key is ``"SHAPE/INDEX"``).

    Returns
    -------
    Demonstration

    Raises
    ------
    InvalidInputError
        The file is missing, unreadable or not ``.npy`` / ``.csv``.
    InvalidDemonstrationError
        The array is not N x 2 or N x 3, has NaN or inf, fewer than 3
        points, zero extent, or non-increasing times.
    """
    p = Path(path)
    if not p.is_file():
        raise InvalidInputError(f"trajectory file {str(p)!r} does not exist.")
    suffix = p.suffix.lower()
    header: list[str] | None = None
    if suffix == ".npy":
        try:
            arr = np.load(p, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise InvalidInputError(f"cannot read {str(p)!r} as a numpy array: {exc}. "
                                    "Save it with numpy.save(path, array).") from None
    elif suffix == ".csv":
        arr, header = _read_csv(p)
    else:
        raise InvalidInputError(f"unsupported trajectory file {p.name!r}: use .npy or .csv "
                                "(N x 2 positions, or N x 3 with time first).")
    try:
        arr = np.asarray(arr, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidDemonstrationError(f"{p.name}: the array is not numeric.") from None
    name = shape if shape is not None else p.stem
    if arr.ndim != 2 or arr.shape[1] not in (2, 3):
        raise InvalidDemonstrationError(
            f"{p.name}: expected an N x 2 array of positions (x, y) or N x 3 (t, x, y), "
            f"got shape {arr.shape}.")
    times = None
    if arr.shape[1] == 3:
        tcol = 0
        if header is not None:
            lowered = [h.strip().lower() for h in header]
            hits = [i for i, h in enumerate(lowered) if h in _TIME_NAMES]
            tcol = hits[0] if hits else 0
        times = arr[:, tcol]
        arr = np.delete(arr, tcol, axis=1)
    return Demonstration(positions=arr, times=times, shape=name, index=index,
                         true_concept=true_concept)


def _read_csv(p: Path) -> tuple[np.ndarray, list[str] | None]:
    try:
        with p.open(newline="", encoding="utf-8") as fh:
            rows = [r for r in csv.reader(fh) if r and any(c.strip() for c in r)]
    except (OSError, UnicodeDecodeError) as exc:
        raise InvalidInputError(f"cannot read {str(p)!r}: {exc}.") from None
    header = None
    if rows and not _numeric(rows[0]):
        header, rows = rows[0], rows[1:]
    widths = {len(r) for r in rows}
    if len(widths) > 1:
        raise InvalidDemonstrationError(f"{p.name}: rows have different numbers of columns "
                                        f"{sorted(widths)}.")
    try:
        data = np.array([[float(c) for c in r] for r in rows], dtype=np.float64)
    except ValueError as exc:
        raise InvalidDemonstrationError(f"{p.name}: non-numeric value ({exc}).") from None
    if data.size == 0:
        data = data.reshape(0, len(header) if header else 2)
    return data, header


def _numeric(row: list[str]) -> bool:
    try:
        [float(c) for c in row]
    except ValueError:
        return False
    return True


def write_atomic(path: str | os.PathLike[str], writer: Callable[[IO[bytes]], Any], *,
                 mkdir: bool = False, overwrite: bool = True) -> Path:
    """Write a file atomically: readers see the old file or the new one, never a part.

    ``writer(fh)`` writes the content to a binary temporary file
    ``.NAME.<random>.tmp`` in the target's directory (the same file system,
    so the rename below is atomic). The file is flushed and fsync'ed, then
    renamed over the target with :func:`os.replace`, which is the commit
    point, and the directory is fsync'ed so the rename survives a power
    cut (best effort, where the platform allows it): if the writer raises (any exception, including
    :class:`KeyboardInterrupt`) or the rename fails, the temporary file is
    removed and the old target is left untouched.

    Permissions: a new file gets ``0o666`` minus the process umask, like
    ``open(path, "w")`` (the temporary file is created with :func:`os.open`
    and mode ``0o666`` so the kernel applies the umask; the umask is never
    read or changed, which would race with other threads). Replacing an
    existing file keeps its permission bits, so a file a user made private
    stays private.

    With ``overwrite=False`` an existing target is never replaced: the
    temporary file is committed with :func:`os.link`, which fails when the
    target exists (atomically, so two writers racing for one name cannot
    both win), and :class:`FileExistsError` is raised with the target left
    as it was. On a file system without hard links the existence check and
    the rename are two steps.

    Parameters
    ----------
    path : str or path-like
        The target file.
    writer : callable
        Called once with the open binary file object; its return value is
        ignored.
    mkdir : bool
        Create missing parent directories first (otherwise a missing
        directory raises :class:`FileNotFoundError`).
    overwrite : bool
        Replace an existing target (the default); ``False`` raises
        :class:`FileExistsError` instead.

    Returns
    -------
    pathlib.Path
        The written file.

    Raises
    ------
    FileExistsError
        ``overwrite=False`` and the target exists.
    OSError
        Unchanged from the file system (e.g. :class:`PermissionError` for an
        unwritable directory); whatever ``writer`` raises propagates too.
    """
    target = Path(path)
    directory = target.parent
    if mkdir:
        directory.mkdir(parents=True, exist_ok=True)
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    while True:
        tmp = directory / f".{target.name}.{secrets.token_hex(6)}.tmp"
        try:
            fd = os.open(tmp, flags, 0o666)
        except FileExistsError:
            continue
        break
    try:
        with os.fdopen(fd, "wb") as fh:
            writer(fh)
            fh.flush()
            os.fsync(fh.fileno())
        if not overwrite:
            _commit_new(tmp, target)
            _fsync_directory(directory)
            return target
        try:
            old_mode = stat.S_IMODE(os.stat(target).st_mode)
        except FileNotFoundError:
            pass
        else:
            os.chmod(tmp, old_mode)
        # the rename is the commit point: before it the old file is intact
        os.replace(tmp, target)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    _fsync_directory(directory)
    return target


def _fsync_directory(directory: Path) -> None:
    """Make a rename in ``directory`` durable: after a power cut, the new name is there.

    Best effort: where a directory cannot be opened or synced (Windows, some
    network file systems) the rename is still atomic, only maybe not yet on disk.
    """
    try:
        fd = os.open(directory, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _commit_new(tmp: Path, target: Path) -> None:
    """Give the finished temporary file ``tmp`` the name ``target``, which must not exist."""
    try:
        # the link is the commit point; it fails if the target exists
        os.link(tmp, target)
    except FileExistsError:
        raise FileExistsError(errno.EEXIST, "file exists; not replaced", str(target)) from None
    except OSError:  # no hard links here (some FAT, network or container file systems)
        if os.path.lexists(target):
            raise FileExistsError(errno.EEXIST, "file exists; not replaced",
                                  str(target)) from None
        os.replace(tmp, target)
        return
    try:
        os.unlink(tmp)  # the target is written: a leftover name is no failure
    except OSError:
        pass


def write_text_atomic(path: str | os.PathLike[str], text: str, *, encoding: str = "utf-8",
                      mkdir: bool = False) -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`write_atomic`).

    Parameters
    ----------
    path : str or path-like
    text : str
        Written as is (no newline translation).
    encoding : str
        Text encoding, UTF-8 by default (not the locale's).
    mkdir : bool
        Create missing parent directories first.

    Returns
    -------
    pathlib.Path
        The written file.
    """
    data = text.encode(encoding)
    return write_atomic(path, lambda fh: fh.write(data), mkdir=mkdir)
