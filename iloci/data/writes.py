"""Atomic file writes: a file is the old one or the new one, never a part.

:func:`write_atomic` (and :func:`write_text_atomic`) for every file iloci
writes (memories, reports, figures, configs); :func:`writable_dir` and
:func:`writable_file` check a destination before any work that would end
there.
"""

from __future__ import annotations

import codecs
from collections.abc import Callable
import errno
import os
from pathlib import Path
import secrets
import stat
import tempfile
from typing import IO, Any

from iloci.errors import InvalidInputError

__all__ = ["bytes_escape", "writable_dir", "writable_file", "write_atomic",
           "write_text_atomic"]


def bytes_escape(exc: UnicodeError) -> tuple[str, int]:
    """Codec error handler ``"iloci-bytes"``: a byte the OS gave undecoded (a lone
    surrogate U+DC80-U+DCFF) as ``\\xNN``, like :func:`iloci.data.files.shape_name`;
    anything else as a backslash escape."""
    if not isinstance(exc, UnicodeEncodeError):
        raise exc
    text = exc.object[exc.start:exc.end]
    return "".join(f"\\x{ord(c) - 0xDC00:02x}" if 0xDC80 <= ord(c) <= 0xDCFF
                   else c.encode("ascii", "backslashreplace").decode() for c in text), exc.end


codecs.register_error("iloci-bytes", bytes_escape)


def writable_dir(path: str | os.PathLike[str], what: str) -> Path:
    """``path`` as a directory files can be written to, created if missing; checked by
    writing (and removing) a temporary file in it, before any work that would end there.

    Parameters
    ----------
    path : path-like
    what : str
        How the error names it, e.g. ``"--memories"``.

    Raises
    ------
    InvalidInputError
        It is a file, cannot be created, or nothing can be written in it (read-only,
        no permission, no space): naming the reason, and that nothing was done.
    """
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InvalidInputError(f"{what} {str(p)!r} is a file, not a directory; give a "
                                "directory. Nothing was done.")
    try:
        p.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=p):
            pass
    except OSError as exc:
        raise InvalidInputError(
            f"{what} {str(p)!r}: nothing can be written there ({exc.strerror or exc}); choose "
            "another directory or make it writable. Nothing was done.") from None
    return p


def writable_file(path: str | os.PathLike[str], what: str) -> Path:
    """``path`` as a file that can be (re)written atomically (:func:`write_atomic`): its
    directory (created if missing) takes new files, and it is not a directory.

    Raises
    ------
    InvalidInputError
        As :func:`writable_dir`, naming ``what`` (e.g. ``"--memory"``).
    """
    p = Path(path)
    if p.is_dir():
        raise InvalidInputError(f"{what} {str(p)!r} is a directory; give a file name. "
                                "Nothing was done.")
    writable_dir(p.parent, f"{what} {str(p)!r}: its folder")
    return p


def check_memory_path(memory: str | os.PathLike[str], what: str = "--memory") -> Path:
    """``memory`` as a memory file a writer can use, checked before anything is learned.

    A symbolic link is followed (the file it points to is the memory; its
    folder must take new files); a link that leads back to itself, or a
    path that is a directory, is refused; so is a new file whose name does
    not end in ``.npz`` (``--memory GShape/0 Sine/0``: the memory's name left
    out); the folder is created if missing and must be writable
    (:func:`writable_file`).

    Returns
    -------
    Path
        ``memory`` as given.

    Raises
    ------
    InvalidInputError
        Naming the path, what is wrong and that nothing was done.
    """
    path = Path(memory)
    try:
        os.stat(path)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise InvalidInputError(
                f"{what} {str(path)!r} is a symbolic link that leads back to itself (a loop); "
                "give the memory file's own path. Nothing was done.") from None
        if path.suffix.lower() != ".npz":  # a new memory: named as one, or a slip
            looks = ("a demonstration (a LASA shape or a trajectory file)"
                     if path.suffix.lower() in (".csv", ".npy", ".inkml", ".xml", ".txt", "")
                     else f"a {path.suffix} file")
            raise InvalidInputError(
                f"{what} {str(path)!r} would be a new memory file, and a memory file's name "
                f"ends in .npz; {str(path)!r} looks like {looks}. Did you leave out the "
                f"memory's name? e.g. {what} memory.npz {path}. Nothing was done.") from None
    if os.path.islink(path):
        writable_file(os.path.realpath(path), f"{what} {str(path)!r} (a link to)")
    else:
        writable_file(path, what)
    return path


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
        From the file system (e.g. :class:`PermissionError` for an unwritable
        directory), with ``filename`` the target when the system named none
        (a write refused for a full disk); whatever ``writer`` raises
        propagates too.
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
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(exc, OSError) and exc.errno is not None and exc.filename is None:
            exc.filename = str(target)  # a full disk says which file it refused
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
        Written as is (no newline translation); a byte of a file name the OS gave
        undecoded (a lone surrogate) as ``\\xNN`` (:func:`bytes_escape`).
    encoding : str
        Text encoding, UTF-8 by default (not the locale's).
    mkdir : bool
        Create missing parent directories first.

    Returns
    -------
    pathlib.Path
        The written file.
    """
    data = text.encode(encoding, "iloci-bytes")
    return write_atomic(path, lambda fh: fh.write(data), mkdir=mkdir)
