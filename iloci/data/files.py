"""A user's own pen trajectories from ``.npy`` or ``.csv`` files; atomic file writes."""

from __future__ import annotations

import codecs
import csv
import errno
import io
import math
import os
import re
import secrets
import stat
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np

from iloci.errors import InvalidDemonstrationError, InvalidInputError
from iloci.interfaces import Demonstration

__all__ = ["TrajectoryFile", "bytes_escape", "load_trajectory", "shape_name", "trajectory_files",
           "writable_dir", "writable_file", "write_atomic", "write_text_atomic"]

def bytes_escape(exc: UnicodeError) -> tuple[str, int]:
    """Codec error handler ``"iloci-bytes"``: a byte the OS gave undecoded (a lone
    surrogate U+DC80-U+DCFF) as ``\\xNN``, like :func:`shape_name`; anything else as a
    backslash escape."""
    if not isinstance(exc, UnicodeEncodeError):
        raise exc
    text = exc.object[exc.start:exc.end]
    return "".join(f"\\x{ord(c) - 0xDC00:02x}" if 0xDC80 <= ord(c) <= 0xDCFF
                   else c.encode("ascii", "backslashreplace").decode() for c in text), exc.end


codecs.register_error("iloci-bytes", bytes_escape)


def shape_name(path: str | os.PathLike[str]) -> str:
    """The shape name a trajectory file gives its demonstration: the file's stem, as text.

    A file name the OS gives as bytes that are not UTF-8 (a Latin-1 name on a
    UTF-8 system, say: Python holds such bytes as lone surrogates, which cannot
    be printed, drawn, hashed or saved as text) is accepted: each such byte is
    written ``\\xNN`` in the name (``caf\\xe9`` for ``café`` in Latin-1); the
    file itself is read by its own name.
    """
    return os.fsencode(Path(path).stem).decode("utf-8", "backslashreplace")


def load_trajectory(path: str | os.PathLike[str], *, shape: str | None = None,
                    true_concept: str | None = None, index: int = 0) -> Demonstration:
    """Read one pen trajectory from a file.

    A ``.npy`` file holds a plain float array (loaded without pickle),
    ``N x 2`` pen positions ``x, y`` (any unit; times default to ``0, 1,
    ..., N-1``) or ``N x 3`` ``t, x, y`` with the time stamps (s) first.

    A ``.csv`` file is read with :mod:`csv`:

    * **Encoding**: UTF-8 (with or without a byte-order mark), UTF-16 and
      UTF-32 with a byte-order mark, UTF-16 without one (recognised by its
      zero bytes); other bytes are read as Latin-1.
    * **Dialect**: fields separated by ``,``, ``;``, tab or ``|`` (found by
      :class:`csv.Sniffer`, checked against the data) or by spaces; with a
      separator other than ``,`` a decimal comma (``0,5``) is read as
      ``0.5``.
    * **Header**: optional. Columns are taken by name: time ``t``,
      ``time``, ``timestamp`` (s), ``t_ms``, ``time_ms`` (ms, converted to
      s), unit suffixes such as ``x_mm`` or ``t [s]`` allowed; positions
      ``x`` and ``y`` (or ``pos_x``, ``pen_x``, ...). Other columns
      (pressure, tilt, ...) are ignored. A header that names no ``x`` and
      ``y`` is accepted only when it is unambiguous: two columns (x, y) or
      a named time column plus two others (x, y in order); otherwise the
      error names the header.
    * Without a header: 2 columns are ``x, y``, 3 are ``t, x, y``.

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
        No usable columns (the error names the header), a value that is not
        a number, NaN or inf, or a time not after the previous one (the
        error names the file's line), fewer than 3 points or zero extent.
    """
    p = Path(path)
    if not p.is_file():
        raise InvalidInputError(f"trajectory file {str(p)!r} does not exist.")
    suffix = p.suffix.lower()
    name = shape if shape is not None else shape_name(p)
    if suffix == ".npy":
        positions, times = _read_npy(p)
    elif suffix == ".csv":
        positions, times = _read_csv(p)
    else:
        raise InvalidInputError(f"unsupported trajectory file {p.name!r}: use .npy or .csv "
                                "(N x 2 positions, or N x 3 with time first).")
    return Demonstration(positions=positions, times=times, shape=name, index=index,
                         true_concept=true_concept)


def _read_npy(p: Path) -> tuple[np.ndarray, np.ndarray | None]:
    try:
        arr = np.load(p, allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        raise InvalidInputError(f"cannot read {str(p)!r} as a numpy array: {exc}. "
                                "Save it with numpy.save(path, array).") from None
    if not isinstance(arr, np.ndarray) or arr.dtype.kind not in "biuf":
        raise InvalidDemonstrationError(
            f"{p.name}: the array is not numeric (dtype "
            f"{getattr(arr, 'dtype', type(arr).__name__)}).")
    arr = arr.astype(np.float64)
    if arr.ndim != 2 or arr.shape[1] not in (2, 3):
        raise InvalidDemonstrationError(
            f"{p.name}: expected an N x 2 array of positions (x, y) or N x 3 (t, x, y), "
            f"got shape {arr.shape}.")
    bad = np.argwhere(~np.isfinite(arr))
    if len(bad):
        raise InvalidDemonstrationError(f"{p.name}: row {int(bad[0, 0])} contains NaN or inf; "
                                        "remove or interpolate missing samples.")
    if arr.shape[1] == 3:
        _check_times(arr[:, 0], [f"row {i}" for i in range(len(arr))], p.name)
        return arr[:, 1:], arr[:, 0]
    return arr, None


@dataclass(frozen=True)
class TrajectoryFile:
    """A trajectory file in a learning stream, read when its turn comes.

    Attributes
    ----------
    path : str
    shape : str
        Shape name of its demonstration (the file's stem).
    index : int
        Its index among the stream's files of that stem, so that files of
        the same name in different folders get different keys
        (``circle/0``, ``circle/1``).
    """

    path: str
    shape: str
    index: int = 0

    def __fspath__(self) -> str:
        return self.path

    @property
    def key(self) -> str:
        return f"{self.shape}/{self.index}"

    def load(self) -> Demonstration:
        """The demonstration (see :func:`load_trajectory` for the errors)."""
        return load_trajectory(self.path, shape=self.shape, index=self.index)


def trajectory_files(paths: Iterable[str | os.PathLike[str]],
                     seen: dict[str, dict[str, int]] | None = None) -> list[TrajectoryFile]:
    """Stream items for trajectory files, with a distinct key per distinct file.

    Files whose names share a stem (``s01/circle.csv``, ``s02/circle.csv``:
    one folder per person) are numbered in order, ``circle/0``,
    ``circle/1``; the same file named twice keeps one key (it is the same
    demonstration, shown again).

    Parameters
    ----------
    paths : iterable of path-like
    seen : dict, optional
        Numbering state (stem -> file -> index) to continue from, for a
        stream whose files arrive one at a time; updated in place.

    Returns
    -------
    list of TrajectoryFile
        One per path, in order.
    """
    seen = {} if seen is None else seen
    out = []
    for path in paths:
        p = Path(path)
        same_stem = seen.setdefault(shape_name(p), {})
        ident = os.path.normcase(os.path.abspath(p))
        index = same_stem.setdefault(ident, len(same_stem))
        out.append(TrajectoryFile(str(path), shape_name(p), index))
    return out


def shared_stems(files: Iterable[TrajectoryFile]) -> list[list[TrajectoryFile]]:
    """Groups of distinct files that share a stem (each group in stream order)."""
    groups: dict[str, dict[int, TrajectoryFile]] = {}
    for f in files:
        groups.setdefault(f.shape, {}).setdefault(f.index, f)
    return [list(g.values()) for g in groups.values() if len(g) > 1]


#: Header names of a time column (lower case, unit suffix removed) -> unit in s.
_TIME_NAMES = {"t": 1.0, "time": 1.0, "times": 1.0, "timestamp": 1.0, "ts": 1.0,
               "t_ms": 1e-3, "time_ms": 1e-3, "timestamp_ms": 1e-3, "ms": 1e-3}
#: Units a header may append to a name (``t_ms``, ``t [ms]``, ``x (mm)``) -> factor to s.
_UNITS = {"s": 1.0, "sec": 1.0, "secs": 1.0, "seconds": 1.0, "ms": 1e-3, "msec": 1e-3,
          "us": 1e-6, "mm": None, "cm": None, "m": None, "px": None, "pixels": None,
          "in": None}
_X_NAMES = ("x", "pos_x", "x_pos", "pen_x", "posx", "xpos")
_Y_NAMES = ("y", "pos_y", "y_pos", "pen_y", "posy", "ypos")
_DELIMITERS = (",", ";", "\t", "|")
_NUMBER_RE = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|[+-]?(nan|inf|infinity)",
                        re.IGNORECASE)
_DECIMAL_COMMA_RE = re.compile(r"[+-]?\d+,\d+([eE][+-]?\d+)?")


def _decode(raw: bytes, name: str) -> tuple[str, str]:
    """The text of a CSV file and the encoding it was read with."""
    for bom, enc in ((codecs.BOM_UTF32_LE, "utf-32"), (codecs.BOM_UTF32_BE, "utf-32"),  # noqa: B007 (enc: the one found, used after the loop)
                     (codecs.BOM_UTF8, "utf-8-sig"), (codecs.BOM_UTF16_LE, "utf-16"),
                     (codecs.BOM_UTF16_BE, "utf-16")):
        if raw.startswith(bom):
            break
    else:
        enc = "utf-8"
        if raw[:2] and b"\x00" in raw[:64]:  # UTF-16 without a byte-order mark
            enc = "utf-16-le" if raw[1:64:2].count(0) > raw[0:64:2].count(0) else "utf-16-be"
    try:
        return raw.decode(enc), enc
    except UnicodeDecodeError:
        if enc != "utf-8":
            raise InvalidInputError(f"cannot read {name}: it is not valid {enc} text. Save "
                                    "it as UTF-8.") from None
        return raw.decode("latin-1"), "latin-1"


def _split_name(cell: str) -> tuple[str, float | None]:
    """A header cell as (base name, time unit in s or None): 't [ms]' -> ('t', 0.001)."""
    name = cell.strip().strip('"').strip().lower()
    m = re.fullmatch(r"(.*?)\s*[\[(]\s*([a-z]+)\s*[\])]", name)
    if m and m.group(2) in _UNITS:
        return m.group(1).strip(), _UNITS[m.group(2)]
    name = re.sub(r"\s+", "_", name)
    if name in _TIME_NAMES:
        return name, _TIME_NAMES[name]
    base, sep, unit = name.rpartition("_")
    if sep and unit in _UNITS and base:
        return base, _UNITS[unit]
    return name, None


def _number(cell: str, decimal_comma: bool) -> float | None:
    c = cell.strip()
    if decimal_comma and _DECIMAL_COMMA_RE.fullmatch(c):
        c = c.replace(",", ".")
    if not _NUMBER_RE.fullmatch(c):
        return None
    return float(c)


def _rows(text: str, delimiter: str | None) -> list[tuple[int, list[str]]]:
    """(line number, fields) of every non-blank row; ``None`` splits on white space."""
    if delimiter is None:
        return [(i, line.split()) for i, line in enumerate(text.splitlines(), 1)
                if line.strip()]
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=delimiter,
                        skipinitialspace=True)
    out = []
    try:
        for fields in reader:
            if fields and "".join(fields).strip():
                out.append((reader.line_num, fields))
    except csv.Error as exc:
        raise InvalidDemonstrationError(f"line {reader.line_num}: {exc}") from None
    return out


def _numeric_rows(rows: list[tuple[int, list[str]]], decimal_comma: bool) -> bool:
    return all(_number(c, decimal_comma) is not None for _, r in rows for c in r)


def _dialect(text: str) -> tuple[str | None, bool]:
    """(delimiter, decimal comma) under which the most data cells are numbers.

    :class:`csv.Sniffer`'s guess is tried first, then ``,``, ``;``, tab,
    ``|`` and white space; a candidate must give every data row one width
    of at least 2 columns to win over one that does not. A decimal comma is
    only considered with a separator other than ``,``.
    """
    candidates: list[str | None] = []
    try:
        sniffed = csv.Sniffer().sniff(text[:8192], delimiters="".join(_DELIMITERS)).delimiter
        candidates.append(sniffed)
    except csv.Error:
        pass
    candidates += [d for d in _DELIMITERS if d not in candidates] + [None]
    best: tuple[tuple[int, float], str | None, bool] = ((-1, -1.0), ",", False)
    for delim in candidates:
        try:
            rows = _rows(text, delim)
        except InvalidDemonstrationError:
            continue
        for comma in ((False, True) if delim != "," else (False,)):
            data = rows[1:] if rows and not _numeric_rows(rows[:1], comma) else rows
            cells = [c for _, r in data for c in r]
            widths = {len(r) for _, r in data}
            consistent = int(len(widths) == 1 and min(widths) >= 2)
            parsed = sum(_number(c, comma) is not None for c in cells) / max(1, len(cells))
            if (consistent, parsed) > best[0]:
                best = ((consistent, parsed), delim, comma)
            if consistent and parsed == 1.0:
                return delim, comma
    return best[1], best[2]


def _describe_dialect(delimiter: str | None, decimal_comma: bool, encoding: str) -> str:
    sep = {None: "white space", "\t": "tabs"}.get(delimiter, repr(delimiter))
    return (f"read as {encoding} text, fields separated by {sep}"
            + (", decimal commas" if decimal_comma else ""))


def _read_csv(p: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """Positions (N, 2) and times (N,) or None from a CSV file (see :func:`load_trajectory`)."""
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise InvalidInputError(f"cannot read {str(p)!r}: {exc.strerror}.") from None
    from iloci.progress import long_step
    from iloci.validation import MAX_POINTS, check_size
    lines = raw.count(b"\n")
    if lines > MAX_POINTS + 1:  # before any parsing: the file is refused at once
        check_size(lines - 1, f"{p.name} (about {lines:,} lines)")
    if len(raw) < 1_000_000:  # read in well under a second
        return _parse_csv(raw, p, lambda fraction: None)
    with long_step(f"reading {p.name} ({lines:,} lines)") as tell:
        return _parse_csv(raw, p, tell)


def _parse_csv(raw: bytes, p: Path, tell: Callable[[float], None]
               ) -> tuple[np.ndarray, np.ndarray | None]:
    text, encoding = _decode(raw, p.name)
    # a big file's dialect is found on its first 64 kB (whole lines): the rest is
    # checked row by row below, with the line named
    sample = text if len(text) <= _SAMPLE else text[:text.rfind("\n", 0, _SAMPLE) + 1] or text
    delimiter, decimal_comma = _dialect(sample)
    how = _describe_dialect(delimiter, decimal_comma, encoding)
    tell(0.1)
    head = _rows(sample, delimiter) if sample is not text else None
    if head and not _numeric_rows(head[:1], decimal_comma):
        head_names = [c.strip() for c in head[0][1]]
        cols = _columns(head_names, len(head_names), p.name, how)
        body = text
        for _ in range(head[0][0]):  # the body starts after the header's line
            body = body[body.find("\n") + 1:]
        values = _loadtxt(body, delimiter, decimal_comma, len(head_names))
        if values is not None:
            tell(0.9)
            positions = values[:, [cols["x"], cols["y"]]]
            if cols["t"] is None:
                return positions, None
            times = values[:, cols["t"]] * cols["unit"]
            if np.all(np.diff(times) > 0):
                return positions, times
            # a time out of order: read again below, to name its line
    try:
        rows = _rows(text, delimiter)
    except InvalidDemonstrationError as exc:
        raise InvalidDemonstrationError(f"{p.name}: {exc} ({how}).") from None
    tell(0.5)
    if not rows:
        raise InvalidDemonstrationError(f"{p.name}: the file holds no rows of numbers.")
    header: list[str] | None = None
    if not _numeric_rows(rows[:1], decimal_comma):
        header = [c.strip() for c in rows[0][1]]
        rows = rows[1:]
    width = len(header) if header is not None else len(rows[0][1])
    for line, fields in rows:
        if len(fields) != width:
            raise InvalidDemonstrationError(
                f"{p.name}: line {line} has {len(fields)} fields where "
                f"{'the header has' if header else 'line ' + str(rows[0][0]) + ' has'} "
                f"{width} ({how}).")
    cols = _columns(header, width, p.name, how)
    names = header or [("t", "x", "y")[i] if width == 3 else ("x", "y")[i]
                       for i in range(width)]
    used = [c for c in (cols["t"], cols["x"], cols["y"]) if c is not None]
    values = np.empty((len(rows), width), dtype=np.float64)
    tell(0.7)
    for r, (line, fields) in enumerate(rows):
        for c in used:
            v = _number(fields[c], decimal_comma)
            if v is None:
                raise InvalidDemonstrationError(
                    f"{p.name}: line {line}, column {names[c]!r}: {fields[c]!r} is not a "
                    f"number ({how}).")
            if not math.isfinite(v):
                raise InvalidDemonstrationError(
                    f"{p.name}: line {line}, column {names[c]!r} is {fields[c].strip()}: "
                    "NaN or inf; remove or interpolate missing samples.")
            values[r, c] = v
    positions = values[:, [cols["x"], cols["y"]]]
    times = None
    if cols["t"] is not None:
        times = values[:, cols["t"]] * cols["unit"]
        _check_times(times, [f"line {line}" for line, _ in rows], p.name)
    return positions, times


#: Characters of a CSV file its dialect is found on (all of a smaller file).
_SAMPLE = 65_536


def _loadtxt(body: str, delimiter: str | None, decimal_comma: bool, width: int
             ) -> np.ndarray | None:
    """A big file's rows of numbers after its header, read by numpy's C parser: (N, width).

    None whenever the rows are not plainly ``width`` finite numbers each (a quote, a
    decimal comma, a blank cell, a word, NaN, a row of another width, ``1_000``
    which Python reads and :func:`_number` does not): the row-by-row reading then
    takes over and names the line at fault.
    """
    if delimiter is None or decimal_comma or '"' in body or "_" in body:
        return None
    import warnings
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # numpy's "empty input" warning
            values = np.loadtxt(io.StringIO(body), delimiter=delimiter, comments=None,
                                ndmin=2, dtype=np.float64)
    except ValueError:
        return None
    if values.shape[1] != width or len(values) < 3 or not np.isfinite(values).all():
        return None
    return values


def _columns(header: list[str] | None, width: int, name: str, how: str) -> dict[str, Any]:
    """Indices of the t (or None), x and y columns and the time unit (s)."""
    if header is None:
        if width == 2:
            return {"t": None, "x": 0, "y": 1, "unit": 1.0}
        if width == 3:
            return {"t": 0, "x": 1, "y": 2, "unit": 1.0}
        raise InvalidDemonstrationError(
            f"{name}: {width} columns and no header; without a header a file holds "
            "x, y or t, x, y. Add a header naming the columns t, x, y (others are "
            f"ignored) ({how}).")
    split = [_split_name(h) for h in header]
    bases = [b for b, _ in split]
    shown = ",".join(header)

    def find(names: Iterable[str]) -> list[int]:
        return [i for i, b in enumerate(bases) if b in names]

    t_hits = [i for i, (b, _) in enumerate(split) if b in _TIME_NAMES or
              (b in ("t", "time", "timestamp") and split[i][1] is not None)]
    x_hits, y_hits = find(_X_NAMES), find(_Y_NAMES)
    for what, hits in (("time", t_hits), ("x", x_hits), ("y", y_hits)):
        if len(hits) > 1:
            raise InvalidDemonstrationError(
                f"{name}: the header {shown!r} names more than one {what} column "
                f"({', '.join(header[i] for i in hits)}); keep one.")
    t = t_hits[0] if t_hits else None
    unit = 1.0
    if t is not None:
        base, u = split[t]
        unit = u if u is not None else _TIME_NAMES.get(base, 1.0)
    if x_hits and y_hits:
        return {"t": t, "x": x_hits[0], "y": y_hits[0], "unit": unit}
    rest = [i for i in range(width) if i != t]
    if not x_hits and not y_hits and len(rest) == 2 and (t is not None or width == 2):
        return {"t": t, "x": rest[0], "y": rest[1], "unit": unit}
    raise InvalidDemonstrationError(
        f"{name}: cannot tell the pen positions from the header {shown!r}: name them x "
        "and y (time t, time or t_ms; other columns such as pressure are ignored).")


def _check_times(times: np.ndarray, rows: list[str], name: str) -> None:
    """Raise naming the first row whose time is not after the previous one."""
    bad = np.flatnonzero(np.diff(times) <= 0)
    if len(bad):
        i = int(bad[0]) + 1
        raise InvalidDemonstrationError(
            f"{name}: {rows[i]}: time {times[i]:g} is not after the previous row's "
            f"{times[i - 1]:g}; times must be strictly increasing.")


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
    import tempfile
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
