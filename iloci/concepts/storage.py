"""The memory file: one ``.npz`` of numeric arrays and a JSON header, written atomically.

File format
-----------
One ``.npz`` file (``np.load(allow_pickle=False)``) holding numeric arrays
only:

* ``__header__`` - UTF-8 JSON as ``uint8``: format name, format version,
  iloci version, the agent's config, the per-entry strings (concept labels,
  source demonstration keys) and a SHA-256 checksum of everything else;
* ``mem/*`` - per-entry arrays (PB, PB_rec, numSamples, ...);
* ``enc/*`` - the sensorimotor encoder's state (its scales);
* ``net/*`` - the perceptual model's :meth:`state`.

It is written with :func:`iloci.data.files.write_atomic`: to a temporary
file in the target directory, flushed to disk and renamed over the target
(:func:`os.replace`), so a crash leaves either the old or the new memory,
never a mixture. Replacing a memory file keeps its permission bits.

:func:`~iloci.concepts.memory.save_memory` and
:func:`~iloci.concepts.memory.load_memory` turn a
:class:`~iloci.concepts.memory.Memory` into arrays and back; this module
writes and reads the file and checks it (format, version, checksum).
"""

from __future__ import annotations

from collections.abc import Mapping
import hashlib
import json
import os
from pathlib import Path
import struct
from typing import Any
import zipfile
import zlib

import numpy as np

from iloci._version import __version__
from iloci.data.files import write_atomic
from iloci.errors import InvalidInputError, MemoryFileError

__all__ = ["FORMAT", "FORMAT_VERSION", "RESERVED", "check_header_extra", "memory_path",
           "read_memory_file", "write_memory_file"]

#: Name written in every memory file's header.
FORMAT = "iloci-memory"
#: Version of the file layout this iloci writes and the newest it reads.
FORMAT_VERSION = 1
#: Largest memory file iloci unpacks, in bytes of arrays (the zip directory's sizes, read
#: before anything is unpacked): 2 GiB, about 10^4 times a LASA-taught memory of every
#: concept (~200 kB); a file claiming more is refused, as a zip bomb would be.
MAX_UNPACKED = 2 * 2**30
#: Above this many unpacked bytes (64 MiB), a file whose arrays unpack to more than
#: :data:`MAX_RATIO` times their packed size is refused before anything is unpacked: an
#: audit's 1.5 MB upload of zeros unpacked to 1.6 GB (3.3 GB of the server's memory, every
#: tab stalled 22 s). Memories iloci writes compress about 1.1 to 3 times (float arrays).
BOMB_ABOVE = 64 * 2**20
MAX_RATIO = 20


def _checksum(header: Mapping[str, Any], arrays: Mapping[str, np.ndarray]) -> str:
    h = hashlib.sha256()
    h.update(json.dumps({k: v for k, v in header.items() if k != "checksum"},
                        sort_keys=True).encode())
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(name.encode())
        h.update(str(a.dtype.str).encode())
        h.update(repr(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _check_members(path: Path) -> None:
    """Refuse, before anything is unpacked, a memory file that is a pickle, holds an
    object (pickled) array, or would unpack to more than :data:`MAX_UNPACKED` bytes."""
    try:
        with path.open("rb") as fh:
            head = fh.read(2)
    except OSError as exc:
        raise MemoryFileError(f"cannot read memory file {path}: {exc.strerror}.") from None
    if len(head) == 2 and head[0] == 0x80 and head[1] <= 5:  # pickle protocol 2-5
        raise MemoryFileError(_pickled(path, "the file is a Python pickle"))
    if not zipfile.is_zipfile(path):
        raise MemoryFileError(f"cannot read memory file {path}: it is truncated, corrupted "
                              "or not an iloci memory (not a complete .npz archive).")
    try:
        with zipfile.ZipFile(path) as zf:
            infos = zf.infolist()
            total = sum(i.file_size for i in infos)
            packed = sum(i.compress_size for i in infos)
            if total > BOMB_ABOVE and total > MAX_RATIO * max(packed, 1):
                raise MemoryFileError(
                    f"{path} would unpack {packed:,} bytes into {total:,} "
                    f"({total / max(packed, 1):,.0f} times as many); an iloci memory's arrays "
                    f"(weights, PB vectors, patterns) compress less than {MAX_RATIO} times. It "
                    "was not written by iloci or was made to exhaust memory (a zip bomb); "
                    "nothing was unpacked.")
            if total > MAX_UNPACKED:
                raise MemoryFileError(
                    f"{path} would unpack to {total / 2**30:.1f} GiB of arrays; iloci reads "
                    f"memory files up to {MAX_UNPACKED / 2**30:.0f} GiB unpacked (a memory "
                    "of every LASA concept is ~200 kB). It was not written by iloci or is "
                    "damaged; nothing was unpacked.")
            for info in infos:
                if not info.filename.endswith(".npy"):
                    continue
                with zf.open(info) as member:
                    version = np.lib.format.read_magic(member)
                    read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                            else np.lib.format.read_array_header_2_0)
                    shape, _, dtype = read(member, max_header_size=10_000)
                if dtype.hasobject:
                    raise MemoryFileError(_pickled(
                        path, f"its array {info.filename[:-4]!r} holds Python objects"))
                if int(np.prod(shape, dtype=np.float64)) * dtype.itemsize > info.file_size:
                    raise MemoryFileError(
                        f"cannot read memory file {path}: its array {info.filename[:-4]!r} "
                        f"claims shape {shape} ({dtype}), more than the "
                        f"{info.file_size} bytes stored: the file is corrupted.")
    except MemoryFileError:
        raise
    except (zipfile.BadZipFile, EOFError, ValueError, OSError, KeyError, zlib.error,
            struct.error, OverflowError, NotImplementedError, RuntimeError) as exc:
        raise MemoryFileError(f"cannot read memory file {path}: it is truncated, corrupted "
                              f"or not an iloci memory ({type(exc).__name__}: {exc}).") from None


def _pickled(path: Path, what: str) -> str:
    return (f"{path} is refused: {what}, and loading pickled data can run any code. iloci "
            "memories hold numeric arrays and a JSON header only; this file was not written "
            "by iloci (or was altered). Nothing was loaded.")


#: Header keys every memory file's header holds, written by :func:`write_memory_file`.
RESERVED = frozenset({"format", "version", "iloci", "checksum"})


def check_header_extra(extra: Any, reserved: frozenset[str] | set[str]) -> dict[str, Any]:
    """``extra`` as a dict of more header values, or InvalidInputError saying what is wrong.

    It must be a mapping with string keys, none of ``reserved`` (keys the file's
    own header holds: writing them would make the file unreadable), and
    values JSON can hold (str, int, float, bool, None, lists and dicts of them).
    """
    if extra is None:
        return {}
    if not isinstance(extra, Mapping):
        raise InvalidInputError(f"extra must be a mapping of more header values (a dict), got "
                                f"{type(extra).__name__}.")
    bad_keys = [k for k in extra if not isinstance(k, str)]
    if bad_keys:
        raise InvalidInputError(f"extra's keys must be strings, got {bad_keys[0]!r}.")
    taken = sorted(set(extra) & set(reserved))
    if taken:
        raise InvalidInputError(
            f"extra may not hold {', '.join(map(repr, taken))}: the memory file's own header "
            f"holds {'it' if len(taken) == 1 else 'them'} (reserved: "
            f"{', '.join(sorted(reserved))}). Choose other key names; nothing was written.")
    for key, value in extra.items():
        try:
            json.dumps(value)
        except (TypeError, ValueError) as exc:
            raise InvalidInputError(
                f"extra[{key!r}] cannot be written to the memory file's JSON header "
                f"({exc}): use str, int, float, bool, None, and lists and dicts of them "
                "(a numpy value: .item() or .tolist()). Nothing was written.") from None
    return dict(extra)


def memory_path(path: Any) -> str | os.PathLike[str]:
    """``path`` if it can name a memory file, else InvalidInputError (None, "", a number)."""
    if not isinstance(path, (str, os.PathLike)) or not os.fspath(path):
        raise InvalidInputError(f"a memory file needs a path (e.g. 'memory.npz'), got "
                                f"{path!r}.")
    return path


def write_memory_file(path: str | os.PathLike[str], arrays: dict[str, np.ndarray],
                      header: Mapping[str, Any]) -> Path:
    """Write ``arrays`` and ``header`` (with format, version and checksum) atomically.

    A symlinked memory is written through to its target (the link stays).
    Returns the path written.

    Raises
    ------
    InvalidInputError
        ``path`` is empty or not a path, or ``header`` holds a value JSON
        cannot hold; nothing is written. (A key of :data:`RESERVED` in
        ``header`` replaces the writer's own: a caller's choice, which
        :meth:`Agent.save <iloci.agent.Agent.save>` refuses for ``extra``.)
    MemoryFileError
        ``path`` is a directory.
    """
    if os.path.isdir(memory_path(path)):
        raise MemoryFileError(f"{path} is a directory; give a file name in it, e.g. "
                              f"{os.path.join(os.fspath(path), 'memory.npz')}.")
    header = check_header_extra(header, frozenset())  # format, version: the caller's own
    path = Path(os.path.realpath(os.fspath(path)))
    full: dict[str, Any] = {"format": FORMAT, "version": FORMAT_VERSION,
                            "iloci": __version__, **dict(header)}
    full["checksum"] = _checksum(full, arrays)
    arrays = {**arrays, "__header__": np.frombuffer(json.dumps(full, sort_keys=True).encode(),
                                                    np.uint8)}
    return write_atomic(path, lambda fh: np.savez(fh, allow_pickle=False, **arrays), mkdir=True)


def read_memory_file(path: str | os.PathLike[str]) -> tuple[dict[str, np.ndarray],
                                                            dict[str, Any]]:
    """The arrays (header removed) and the checked header of a memory file.

    Raises
    ------
    MemoryFileError
        Missing, truncated, tampered with (checksum mismatch), not an iloci
        memory, or written by a newer iloci.
    """
    path = Path(path)
    if path.is_dir():
        raise MemoryFileError(f"{path} is a directory, not a memory file; give the .npz "
                              "file `iloci teach --memory FILE` wrote.")
    if not path.is_file():
        raise MemoryFileError(f"memory file not found: {path}. Teach the robot first "
                              "(`iloci teach --memory FILE`), or check the path.")
    _check_members(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, EOFError, ValueError, OSError, KeyError, zlib.error,
            struct.error, OverflowError,
            # a damaged zip directory can claim a compression method zipfile lacks
            # (NotImplementedError) or an encrypted member (RuntimeError)
            NotImplementedError, RuntimeError) as exc:
        raise MemoryFileError(f"cannot read memory file {path}: it is truncated, corrupted "
                              f"or not an iloci memory ({type(exc).__name__}: {exc}).") from None
    raw = arrays.pop("__header__", None)
    if raw is None:
        raise MemoryFileError(f"{path} is not an iloci memory file (no header).")
    try:
        header = json.loads(raw.tobytes().decode("utf-8"))
        if not isinstance(header, dict):
            raise ValueError("header is not an object")
    except (ValueError, UnicodeDecodeError) as exc:
        # an iloci file (it has the header member) whose header was cut or edited
        raise MemoryFileError(f"{path}: its header (the memory's settings and checksum) is "
                              f"damaged and cannot be read ({exc}); the file was cut or "
                              "edited. Restore it from a copy, or teach afresh. The file is "
                              "unchanged.") from None
    if header.get("format") != FORMAT:
        raise MemoryFileError(f"{path} is not an iloci memory file (format "
                              f"{header.get('format')!r}).")
    version = header.get("version")
    if not isinstance(version, int) or version < 1:
        raise MemoryFileError(f"{path}: invalid memory format version {version!r}.")
    if version > FORMAT_VERSION:
        raise MemoryFileError(
            f"{path} was written by a newer iloci ({header.get('iloci')}, memory format "
            f"version {version}); this iloci reads format version {FORMAT_VERSION} and "
            "older. Upgrade iloci to load it.")
    if header.get("checksum") != _checksum(header, arrays):
        raise MemoryFileError(f"{path} is corrupted or was modified: its checksum does not "
                              "match its content. Restore it from a backup or teach again.")
    return arrays, header
