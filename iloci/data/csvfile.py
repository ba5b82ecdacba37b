"""A pen trajectory from a ``.csv`` file: its encoding, dialect, header and columns.

What is read, and how, is described in :func:`iloci.data.files.load_trajectory`;
a value that is not a number and a time not after the previous one are
named by the file's line.
"""

from __future__ import annotations

import codecs
from collections.abc import Callable, Iterable, Sequence
import csv
import io
import math
import warnings
from pathlib import Path
import re
from typing import Any

import numpy as np

from iloci import validation
from iloci.errors import ColumnsWarning, InvalidDemonstrationError, InvalidInputError
from iloci.progress import long_step

__all__ = ["read_csv", "check_times", "decode_text"]


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


def decode_text(raw: bytes, name: str) -> tuple[str, str]:
    """The text of a text file people save (a trajectory CSV, a manifest) and its encoding.

    The encoding is found, not asked for: a byte-order mark says UTF-32,
    UTF-8 or UTF-16 (Excel's "Unicode text" is UTF-16 with one); zero
    bytes in the first 64 without a mark say UTF-16 of the byte order whose
    odd or even bytes hold more zeros; else UTF-8, and Latin-1 when the
    bytes are not valid UTF-8 (every byte is a Latin-1 character). The
    byte-order mark is not part of the text.

    Parameters
    ----------
    raw : bytes
        The file's content.
    name : str
        The file as the user knows it, for the error message.

    Returns
    -------
    text : str
    encoding : str
        The codec it was decoded with (``"utf-8"``, ``"utf-8-sig"``,
        ``"utf-16"``, ``"utf-16-le"``, ``"utf-16-be"``, ``"utf-32"`` or ``"latin-1"``).

    Raises
    ------
    InvalidInputError
        Not text: a workbook (.xlsx, .ods, .xls), a numpy array or other
        binary data (a control byte), named as such; or not valid text in
        the encoding its byte-order mark or zero bytes announce.
    """
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
        text = raw.decode(enc)
    except UnicodeDecodeError:
        if enc.startswith("utf-16-"):  # zero bytes and no byte-order mark: not text at all
            _check_text(raw, raw.decode("latin-1"), name)
        if enc != "utf-8":
            raise InvalidInputError(f"cannot read {name}: it is not valid {enc} text. Save "
                                    "it as UTF-8.") from None
        text, enc = raw.decode("latin-1"), "latin-1"
    _check_text(raw, text, name)
    return text, enc


#: Signatures of binary files people save under a text name (zip: .xlsx/.ods; OLE2: .xls).
_BINARY_KINDS = ((b"PK\x03\x04", "a zip archive (an Excel .xlsx or LibreOffice workbook?)"),
                 (b"\xd0\xcf\x11\xe0", "an old Excel .xls workbook"),
                 (b"\x93NUMPY", "a numpy .npy array (name it .npy)"))
_CONTROL_RE = re.compile(r"[\x00-\x08\x0e-\x1f\x7f]")


def _check_text(raw: bytes, text: str, name: str) -> None:
    """Refuse a file that is not text (a workbook, an array, binary data) with what it is."""
    kind = next((what for magic, what in _BINARY_KINDS if raw.startswith(magic)), None)
    bad = _CONTROL_RE.search(text, 0, 8192)
    if kind is None and bad is None:
        return
    what = kind or (f"binary data (a control byte 0x{ord(bad.group()):02x} at character "
                    f"{bad.start()})" if bad else "binary data")
    raise InvalidInputError(f"{name} is not a text CSV file: it holds {what}. Export it as "
                            "text, comma-separated values (UTF-8).")


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
    # plain comma-separated numbers first, without the sniffer (most of the time of
    # reading a small file): when every cell is then a number, in rows of one width of
    # 2 or more, no other separator is in the text, so the sniffer's answer is the same
    try:
        if _score(_rows(text, ","), False) == (1, 1.0):
            return ",", False
    except InvalidDemonstrationError:
        pass
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
            score = _score(rows, comma)
            if score > best[0]:
                best = (score, delim, comma)
            if score == (1, 1.0):
                return delim, comma
    return best[1], best[2]


def _score(rows: list[tuple[int, list[str]]], comma: bool) -> tuple[int, float]:
    """(1 if the data rows have one width of 2 or more, else 0; share of cells that are numbers)."""
    data = rows[1:] if rows and not _numeric_rows(rows[:1], comma) else rows
    cells = [c for _, r in data for c in r]
    widths = {len(r) for _, r in data}
    consistent = int(len(widths) == 1 and min(widths) >= 2)
    return consistent, sum(_number(c, comma) is not None for c in cells) / max(1, len(cells))


def _describe_dialect(delimiter: str | None, decimal_comma: bool, encoding: str) -> str:
    sep = {None: "white space", "\t": "tabs"}.get(delimiter, repr(delimiter))
    return (f"read as {encoding} text, fields separated by {sep}"
            + (", decimal commas" if decimal_comma else ""))


#: Bytes of a CSV file looked at before it is read whole (binary data is refused on them).
_HEAD = 65536
#: Largest CSV file read: :data:`~iloci.validation.MAX_POINTS` rows of 256 bytes (a row
#: of a few numbers is 20 to 80).
MAX_BYTES = validation.MAX_POINTS * 256


def read_csv(p: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """Positions (N, 2) and times (N,) or None from a CSV file (see :func:`load_trajectory`)."""
    try:
        size = p.stat().st_size
        with p.open("rb") as fh:
            head = fh.read(_HEAD)
        if size > _HEAD:  # binary data or a file no drawing fills: said before it is read
            decode_text(head, p.name)
            if size > MAX_BYTES:
                raise InvalidInputError(
                    f"{p.name} is {size / 2**20:,.0f} MiB: more than a drawing of at most "
                    f"{validation.MAX_POINTS:,} samples can be as text ({MAX_BYTES // 2**20} "
                    "MiB); is it the right file? Downsample a long recording, or split one "
                    "of several drawings into a file each.")
        raw = p.read_bytes()
    except OSError as exc:
        raise InvalidInputError(f"cannot read {str(p)!r}: {exc.strerror}.") from None
    lines = raw.count(b"\n")
    if lines > validation.MAX_POINTS + 1:  # before any parsing: the file is refused at once
        validation.check_size(lines - 1, f"{p.name} (about {lines:,} lines)")
    if len(raw) < 1_000_000:  # read in well under a second
        return _parse_csv(raw, p, lambda fraction: None)
    with long_step(f"reading {p.name} ({lines:,} lines)") as tell:
        return _parse_csv(raw, p, tell)


def _parse_csv(raw: bytes, p: Path, tell: Callable[[float], None]
               ) -> tuple[np.ndarray, np.ndarray | None]:
    text, encoding = decode_text(raw, p.name)
    # a big file's dialect is found on its first 64 kB (whole lines): the rest is
    # checked row by row below, with the line named
    sample = text if len(text) <= _SAMPLE else text[:text.rfind("\n", 0, _SAMPLE) + 1] or text
    delimiter, decimal_comma = _dialect(sample)
    how = _describe_dialect(delimiter, decimal_comma, encoding)
    tell(0.1)
    head = _rows(sample, delimiter) if sample is not text else None
    if head and not _numeric_rows(head[:1], decimal_comma):
        head_names = [c.strip() for c in head[0][1]]
        cols = _columns(head_names, len(head_names), p.name, how, _line_at(text, head[0][0]))
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
            if np.all(np.diff(times) >= 0):
                return positions, check_times(times, [], p.name)
            # a time out of order: read again below, to name its line
    try:
        rows = _rows(text, delimiter)
    except InvalidDemonstrationError as exc:
        raise InvalidDemonstrationError(f"{p.name}: {exc} ({how}).") from None
    tell(0.5)
    if not rows:
        raise InvalidDemonstrationError(f"{p.name}: the file holds no rows of numbers.")
    header: list[str] | None = None
    header_line = ""
    if not _numeric_rows(rows[:1], decimal_comma):
        header = [c.strip() for c in rows[0][1]]
        header_line = _line_at(text, rows[0][0])
        rows = rows[1:]
    width = len(header) if header is not None else len(rows[0][1])
    for line, fields in rows:
        if len(fields) != width:
            raise InvalidDemonstrationError(
                f"{p.name}: line {line} has {len(fields)} fields where "
                f"{'the header has' if header else 'line ' + str(rows[0][0]) + ' has'} "
                f"{width} ({how}).")
    cols = _columns(header, width, p.name, how, header_line)
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
        try:
            times = check_times(times, [f"line {line}" for line, _ in rows], p.name)
        except InvalidDemonstrationError as exc:
            if header is not None:
                raise
            # no header: the first column was taken for time by its place alone
            raise InvalidDemonstrationError(
                f"{exc} The file has no header, so its 3 columns were read as t, x, y; if "
                "they are x, y and another value (pressure, say), add a header line naming "
                "them (x,y,pressure).") from None
        levels = len(np.unique(positions[:, 1]))
        if header is None and len(rows) >= 20 and levels <= 3:
            # x happened to increase, so it passed as time: y is then the third column,
            # which a drawing's y is not (a few values over the whole stroke) but a pen's
            # pressure or button often is
            warnings.warn(
                f"{p.name}: no header, so its 3 columns were read as t, x, y, but its y "
                f"takes only {levels} value(s) over {len(rows)} rows: are they x, y and "
                "something else (pressure, a button)? Then add a header line naming them "
                "(x,y,pressure).", ColumnsWarning, stacklevel=2)
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


def _line_at(text: str, n: int) -> str:
    """Line ``n`` (1-based) of ``text`` as it is in the file, without its line end."""
    start = 0
    for _ in range(n - 1):
        start = text.find("\n", start) + 1
        if not start:
            return ""
    end = text.find("\n", start)
    return text[start:end if end >= 0 else len(text)].rstrip("\r")


def _columns(header: list[str] | None, width: int, name: str, how: str,
             shown: str = "") -> dict[str, Any]:
    """Indices of the t (or None), x and y columns and the time unit (s).

    ``shown`` is the header's line as the file has it (its separators), quoted in
    errors; by default the names joined with commas.
    """
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
    shown = shown or ",".join(header)

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


def check_times(times: np.ndarray, rows: Sequence[str], name: str) -> np.ndarray:
    """The time stamps, checked: ``times`` with repeated stamps spread, else an error.

    A clock coarser than the pen's sampling (15.6 ms on Windows, a browser's
    1 ms, a device that stamps a batch of samples at once) gives runs of equal
    time stamps. Each run is spread evenly from its stamp towards the next
    one (the last run by the median step between distinct stamps), so the
    times become strictly increasing and keep the file's pace; only the
    robot's drawing speed and ``resample = "time"`` read them.

    Parameters
    ----------
    times : ndarray, shape (N,)
        Time stamps (s), in file order.
    rows : sequence of str
        How each row is named in an error (``"line 4"``; only the row at fault is read).
    name : str
        The file's name, for the error.

    Returns
    -------
    ndarray, shape (N,)
        Strictly increasing times (``times`` itself when it already was).

    Raises
    ------
    InvalidDemonstrationError
        A time before the previous row's (naming its row), or every time
        stamp equal (they say nothing of the pace: drop the time column).
    """
    step = np.diff(times)
    if np.all(step > 0):
        return times
    back = np.flatnonzero(step < 0)
    if len(back):
        i = int(back[0]) + 1
        raise InvalidDemonstrationError(
            f"{name}: {rows[i]}: time {times[i]:g} is before the previous row's "
            f"{times[i - 1]:g}; times must not go back (is the file sorted by time?).")
    rise = step[step > 0]
    if not len(rise):
        raise InvalidDemonstrationError(
            f"{name}: every time stamp is {times[0]:g}; they say nothing of the pace. "
            "Leave the time column out (the robot then draws at a default pace).")
    start = np.flatnonzero(np.r_[True, step > 0])  # first row of each run of equal stamps
    stop = np.r_[start[1:], len(times)]
    nxt = np.r_[times[start[1:]], times[start[-1]] + float(np.median(rise))]
    out = times.astype(np.float64, copy=True)
    for a, b, t_next in zip(start, stop, nxt):
        if b - a > 1:
            out[a:b] = times[a] + (t_next - times[a]) * np.arange(b - a) / (b - a)
    return out
