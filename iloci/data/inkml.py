"""A pen trajectory from a W3C InkML file (``.inkml``).

InkML is the W3C's Ink Markup Language (Recommendation of 20 September
2011, https://www.w3.org/TR/InkML/). One file is one drawing here: every
pen-down ``<trace>`` of the file, in document order, joined into one pen
path (:func:`read_inkml` says what is read and what is refused).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from xml.etree.ElementTree import Element

import numpy as np

from iloci.data.xmlfile import XmlDocument, join_strokes, local_name, parse_xml, refuse

__all__ = ["read_inkml", "read_inkml_document", "INKML_NAMESPACE"]

#: The InkML namespace (elements without one are read too).
INKML_NAMESPACE = "http://www.w3.org/2003/InkML"
_XML_ID = "{http://www.w3.org/XML/1998/namespace}id"
#: Units of a T channel -> seconds.
_TIME_UNITS = {"s": 1.0, "sec": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6}
#: One value of a trace (InkML 3.2.1): an optional difference prefix (``!`` explicit,
#: ``'`` first difference, ``"`` second difference), then a number (decimal, with an
#: exponent, or ``#`` hexadecimal; a ``-`` sign, ``+`` read too) or ``T``/``F``/``*``/``?``.
_TOKEN = re.compile(r"""\s*(?:(?P<comma>,)|(?P<prefix>[!'"])?\s*(?:
    (?P<num>[-+]?\s*(?:\#[0-9A-Fa-f]+|(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?))
    |(?P<sym>[TF*?])))""", re.VERBOSE)
_PLAIN = re.compile(r"[\s,0-9.eE+-]*")
_SYMBOLS = {"T": "'T' (true)", "F": "'F' (false)", "*": "'*' (the previous value)",
            "?": "'?' (a value not known)"}


@dataclass(frozen=True)
class _Channel:
    name: str
    units: str | None
    sign: float  # -1 for orientation="-ve"
    intermittent: bool


@dataclass(frozen=True)
class _Format:
    """A trace format: its channels (regular first, then intermittent), and where it is."""

    channels: tuple[_Channel, ...]
    where: str

    @property
    def regular(self) -> int:
        return sum(not c.intermittent for c in self.channels)

    def index(self, name: str) -> int | None:
        return next((i for i, c in enumerate(self.channels) if c.name == name), None)

    def names(self) -> str:
        return " ".join(c.name for c in self.channels)


_DEFAULT = _Format((_Channel("X", None, 1.0, False), _Channel("Y", None, 1.0, False)),
                   "the default trace format (X Y)")


def read_inkml(p: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """Positions (N, 2) and times (N,) in s, or None, from an InkML file.

    What is read (InkML, W3C Recommendation 2011-09-20,
    https://www.w3.org/TR/InkML/):

    * **Root** ``<ink>``, in the InkML namespace or none.
    * **Traces**: every ``<trace>`` outside ``<definitions>``, in document
      order, also inside ``<traceGroup>``; ``type="penUp"`` traces (the pen
      hovering) are left out. Their points are joined in order into one
      pen path, each pen-up jump a straight segment, as a multi-stroke
      UNIPEN sample is joined
      (:meth:`iloci.data.unipen.UnipenSample.demonstration`).
    * **Trace format**: the default is ``X Y``. A ``<traceFormat>`` (its
      ``<channel>`` elements, then those in ``<intermittentChannels>``) is
      taken from the trace's ``contextRef``, its ``<traceGroup>``'s, or the
      last ``<context>`` (or bare ``<traceFormat>``) before it in the
      document; a context gives its own ``<traceFormat>`` or
      ``traceFormatRef``, else its ``<inkSource>``'s (or ``inkSourceRef``'s),
      else its ``contextRef``'s. References are ``#id`` (``xml:id`` or
      ``id``) within the file. Channels ``X`` and ``Y`` (case-sensitive, as
      in the spec) are the position, in the file's units;
      ``orientation="-ve"`` negates a channel. ``T`` is the time: in the
      channel's ``units`` (``s``, ``ms``, ``us``), **seconds when it gives
      none** (as a ``.csv`` file's ``t``). Other channels (``F`` pressure,
      tilt, ...) are ignored. Without ``T`` the times are ``0, 1, ...,
      N-1`` (as for ``.npy``). An empty ``<trace/>`` adds nothing.
    * **Trace values**: points separated by ``,``, values by white space
      (or juxtaposed where unambiguous, ``3-5``); decimal numbers with an
      optional exponent, ``#`` hexadecimal integers; the prefixes ``!``
      (explicit value), ``'`` (first difference: the value minus the
      previous point's) and ``"`` (second difference: the first difference
      minus the previous one), each holding for its channel until the next
      prefix (InkML section 3.2.1). A trailing ``,`` is ignored.

    Positions are as recorded, in the channels' default orientation
    (``orientation="-ve"`` values negated). Ink recorded on a screen or a
    tablet has ``Y`` growing downwards: use ``[sensorimotor] y_axis =
    "down"`` for such files.

    Raises
    ------
    InvalidInputError
        Not readable, not XML (its line and column), an unknown encoding,
        or an XML entity declaration (refused).
    InvalidDemonstrationError
        A root other than ``<ink>``; no pen-down trace; a trace format
        without ``X`` and ``Y``, or with them (or ``T``) intermittent; a
        ``T`` channel of other units; a point with more or fewer values than
        its format has channels; a value that is not a number, or
        ``T``/``F``/``*``/``?`` in ``X``, ``Y`` or ``T``; a difference on a
        trace's first point (a second difference on its first two); a
        reference to another file or to no element; a ``timeOffset`` on a
        trace with ``T`` (its times would be relative to it: not read); some
        traces timed and some not; a time before the previous point's. Each
        names the file and the line.
    """
    doc = parse_xml(p, "an InkML file")
    return read_inkml_document(doc)


def read_inkml_document(doc: XmlDocument) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`read_inkml` of a parsed document (a ``.xml`` file whose root is ``<ink>``)."""
    root = doc.root
    if local_name(root.tag) != "ink":
        raise refuse(doc.name, doc.line(root),
                     f"the root element is <{local_name(root.tag)}>, not InkML's <ink>. "
                     "Give an InkML file (https://www.w3.org/TR/InkML/) the .inkml suffix, "
                     "and a $1/$N gesture log (<Gesture>) .xml.")
    ids = {el.get(_XML_ID) or el.get("id"): el for el in root.iter()
           if el.get(_XML_ID) or el.get("id")}
    reader = _Reader(doc, ids)
    try:
        traces = list(reader.traces(root, _DEFAULT))
    except RecursionError:
        raise refuse(doc.name, 0, "its <traceGroup>s are nested too deeply to read.") from None
    if not traces:
        inside = any(local_name(t.tag) == "trace" for d in root.iter()
                     if local_name(d.tag) == "definitions" for t in d.iter())
        hover = any(local_name(t.tag) == "trace" and t.get("type", "").strip() == "penUp"
                    for t in root.iter())
        why = ("its traces are all inside <definitions> (drawn through <traceView>, which "
               "is not read)" if inside else
               "its traces are all type=\"penUp\" (the pen hovering)" if hover else
               "it has no <trace> element")
        raise refuse(doc.name, 0, f"no pen-down trace to read: {why}. An InkML file holds "
                     "one drawing as <trace> elements of X Y points.")
    timed = [fmt.index("T") is not None for _, fmt in traces]
    if any(timed) and not all(timed):
        first = timed.index(not timed[0])
        raise refuse(doc.name, doc.line(traces[first][0]),
                     "some traces have a T (time) channel and some do not; give every trace "
                     "of the drawing one trace format.")
    strokes, times, names = [], [], []
    for k, (el, fmt) in enumerate(traces):
        xy, t, where = reader.values(el, fmt, k)
        strokes.append(xy)
        if t is not None:
            times.append(t)
        names.append(where)
    starts = np.cumsum([0] + [len(s) for s in strokes])

    def name_of(i: int) -> str:
        k = int(np.searchsorted(starts, i, side="right")) - 1
        return names[k](i - int(starts[k]))

    return join_strokes(strokes, times if all(timed) else None, name_of, doc.name)


class _Reader:
    """Resolves trace formats of one document and reads its traces' values."""

    def __init__(self, doc: XmlDocument, ids: dict[str | None, Element]) -> None:
        self.doc = doc
        self.ids = ids
        self._formats: dict[Element, _Format] = {}

    # ------------------------------------------------------------ trace formats
    def _ref(self, owner: Element, attr: str, kind: str) -> Element:
        ref = owner.get(attr, "")
        where, _, frag = ref.partition("#")
        target = self.ids.get(frag if _ else ref)
        if where and _:
            raise refuse(self.doc.name, self.doc.line(owner),
                         f"{attr}={ref!r} refers to another file, which is not read; put the "
                         f"<{kind}> in this file.")
        if target is None or local_name(target.tag) != kind:
            raise refuse(self.doc.name, self.doc.line(owner),
                         f"{attr}={ref!r} names no <{kind}> in the file (give the xml:id of "
                         f"one, as \"#id\").")
        return target

    def _trace_format(self, el: Element) -> _Format:
        hit = self._formats.get(el)
        if hit is not None:
            return hit
        line = self.doc.line(el)
        label = f"the traceFormat on line {line}" if line else "a traceFormat"
        channels = []
        for child in el:
            kind = local_name(child.tag)
            group = ([child] if kind == "channel" else
                     [c for c in child if local_name(c.tag) == "channel"]
                     if kind == "intermittentChannels" else [])
            for c in group:
                name = c.get("name")
                if not name:
                    raise refuse(self.doc.name, self.doc.line(c), "a <channel> without a name.")
                sign = -1.0 if c.get("orientation", "+ve").strip() == "-ve" else 1.0
                channels.append(_Channel(name, c.get("units"), sign,
                                         kind == "intermittentChannels"))
        if not channels:
            raise refuse(self.doc.name, line, "a <traceFormat> with no <channel>; declare "
                         "its channels (<channel name=\"X\"/> <channel name=\"Y\"/> ...).")
        fmt = _Format(tuple(channels), label)
        self._check(fmt, line)
        self._formats[el] = fmt
        return fmt

    def _check(self, fmt: _Format, line: int) -> None:
        for name in ("X", "Y"):
            i = fmt.index(name)
            if i is None:
                raise refuse(self.doc.name, line,
                             f"the trace format has no {name} channel (its channels: "
                             f"{fmt.names()}); the pen's position must be channels X and Y "
                             "(InkML channel names are case-sensitive).")
        for name in ("X", "Y", "T"):
            i = fmt.index(name)
            if i is not None and fmt.channels[i].intermittent:
                raise refuse(self.doc.name, line, f"channel {name} is intermittent (given "
                             "for some points only), which is not read: make it a regular "
                             "channel.")
        t = fmt.index("T")
        units = fmt.channels[t].units if t is not None else None
        if units is not None and units.strip() not in _TIME_UNITS:
            raise refuse(self.doc.name, line, f"the T channel's units {units!r} are not read "
                         f"(use {', '.join(_TIME_UNITS)}).")

    def _ink_source(self, el: Element) -> _Format | None:
        fmt = next((c for c in el if local_name(c.tag) == "traceFormat"), None)
        return self._trace_format(fmt) if fmt is not None else None

    def _context(self, el: Element, current: _Format, depth: int = 0) -> _Format:
        if depth > 16:
            raise refuse(self.doc.name, self.doc.line(el), "contextRef nested more than 16 "
                         "deep (a loop?).")
        for child in el:
            if local_name(child.tag) == "traceFormat":
                return self._trace_format(child)
        if el.get("traceFormatRef"):
            return self._trace_format(self._ref(el, "traceFormatRef", "traceFormat"))
        for child in el:
            if local_name(child.tag) == "inkSource":
                found = self._ink_source(child)
                if found is not None:
                    return found
        if el.get("inkSourceRef"):
            found = self._ink_source(self._ref(el, "inkSourceRef", "inkSource"))
            if found is not None:
                return found
        if el.get("contextRef"):
            return self._context(self._ref(el, "contextRef", "context"), current, depth + 1)
        return current

    def traces(self, parent: Element, current: _Format) -> Iterator[tuple[Element, _Format]]:
        """(trace, its format) of every pen-down trace under ``parent``, in document order."""
        for el in parent:
            kind = local_name(el.tag)
            if kind == "context":
                current = self._context(el, current)
            elif kind == "traceFormat":
                current = self._trace_format(el)
            elif kind == "traceGroup":
                group = (self._context(self._ref(el, "contextRef", "context"), current)
                         if el.get("contextRef") else current)
                yield from self.traces(el, group)
            elif kind == "trace":
                fmt = (self._context(self._ref(el, "contextRef", "context"), current)
                       if el.get("contextRef") else current)
                if el.get("type", "penDown").strip() != "penUp":
                    yield el, fmt

    # ------------------------------------------------------------ trace values
    def values(self, el: Element, fmt: _Format, k: int
               ) -> tuple[np.ndarray, np.ndarray | None, Callable[[int], str]]:
        """(positions (n, 2), times (n,) in s or None, point -> its name) of trace ``k``."""
        line = self.doc.line(el)
        text = el.text or ""
        label = f"trace {k + 1}"
        if not text.strip():  # an empty trace draws nothing
            return np.empty((0, 2)), np.empty(0), lambda j: f"{label}, point {j + 1}"
        t = fmt.index("T")
        if t is not None and el.get("timeOffset") is not None:
            raise refuse(self.doc.name, line,
                         f"{label} has a timeOffset, to which its T values are relative; "
                         "timeOffset is not read. Give absolute T values (add the offset) or "
                         "leave the T channel out.")
        x, y = fmt.index("X"), fmt.index("Y")
        assert x is not None and y is not None  # checked with the format
        used = [x, y] + ([t] if t is not None else [])
        table = _plain(text, fmt)
        starts: list[int] = []
        if table is None:
            table, starts = self._decode(text, fmt, label, line, used)

        def name_of(j: int) -> str:
            at = line + text.count("\n", 0, starts[j]) if starts and line else line
            return f"{label} (line {at}), point {j + 1}" if at else f"{label}, point {j + 1}"

        chans = fmt.channels
        xy = np.column_stack([table[:, x] * chans[x].sign, table[:, y] * chans[y].sign])
        times = None
        if t is not None:
            units = (chans[t].units or "s").strip()
            times = table[:, t] * chans[t].sign * _TIME_UNITS[units]
        return xy, times, name_of

    def _decode(self, text: str, fmt: _Format, label: str, line: int, used: list[int]
                ) -> tuple[np.ndarray, list[int]]:
        """The trace's values by the grammar of InkML 3.2.1, with differences resolved."""
        points: list[list[tuple[str | None, str, str]]] = [[]]
        starts = [0]
        pos = 0
        while True:
            m = _TOKEN.match(text, pos)
            if m is None:
                rest = text[pos:].strip()
                if not rest:
                    break
                bad = text[pos:].lstrip()[:12]
                at = line + text.count("\n", 0, pos + len(text[pos:]) - len(text[pos:].lstrip()))
                raise refuse(self.doc.name, at if line else 0,
                             f"{label}, point {len(points)}: {bad!r} is not a number (an "
                             "InkML trace holds points separated by ',', each of values "
                             "separated by spaces, such as '10 20, 11 22').")
            pos = m.end()
            if m.group("comma"):
                points.append([])
                starts.append(pos)
                continue
            if not points[-1]:  # a point is named by the line of its first value
                starts[-1] = m.start() + len(m.group(0)) - len(m.group(0).lstrip())
            points[-1].append((m.group("prefix"), m.group("num") or m.group("sym"),
                               "sym" if m.group("sym") else "num"))
        if points and not points[-1] and len(points) > 1:
            points.pop()  # a trailing comma
            starts.pop()
        width = len(fmt.channels)
        regular = fmt.regular
        for j, pt in enumerate(points):
            if not regular <= len(pt) <= width:
                at = line + text.count("\n", 0, starts[j]) if line else 0
                want = (f"{regular}" if regular == width
                        else f"{regular} to {width}")
                raise refuse(self.doc.name, at,
                             f"{label}, point {j + 1} has {len(pt)} value(s) where the trace "
                             f"format ({fmt.where}: {fmt.names()}) has {want} channel(s); "
                             "every point needs one value per channel.")
        table = np.full((len(points), width), np.nan)
        for c in used:
            mode, prev, speed = "!", None, None
            channel = fmt.channels[c].name
            for j, pt in enumerate(points):
                prefix, tok, kind = pt[c]
                at = line + text.count("\n", 0, starts[j]) if line else 0
                if kind == "sym":
                    raise refuse(self.doc.name, at,
                                 f"{label}, point {j + 1}: channel {channel} is "
                                 f"{_SYMBOLS[tok]}, which is not read in X, Y or T; give "
                                 "the number.")
                v = _value(tok)
                if not math.isfinite(v):
                    raise refuse(self.doc.name, at, f"{label}, point {j + 1}: channel "
                                 f"{channel} is {tok!r}, too large for a number; give a finite "
                                 "value.")
                if prefix:
                    mode = prefix
                if mode == "!":
                    new = v
                    speed = None if prev is None else new - prev
                elif prev is None or (mode == '"' and speed is None):
                    what = "first" if mode == "'" else "second"
                    raise refuse(self.doc.name, at,
                                 f"{label}, point {j + 1}: channel {channel} is given as a "
                                 f"{what} difference ({mode}{tok}) with no previous "
                                 f"{'value' if mode == chr(39) else 'difference'} in the "
                                 "trace; a trace starts with explicit values.")
                elif mode == "'":
                    speed = v
                    new = prev + v
                else:
                    speed = (speed or 0.0) + v
                    new = prev + speed
                prev = new
                table[j, c] = new
        return table, starts


def _value(tok: str) -> float:
    t = re.sub(r"\s+", "", tok)
    sign = -1.0 if t.startswith("-") else 1.0
    t = t.lstrip("+-")
    return sign * (float(int(t[1:], 16)) if t.startswith("#") else float(t))


def _plain(text: str, fmt: _Format) -> np.ndarray | None:
    """A trace of plain decimal points, every one of one value per channel, read at once.

    None when it is anything else (a prefix, hexadecimal, juxtaposed values,
    intermittent channels, a number out of range): :meth:`_Reader._decode`
    then reads it by the grammar and names the point at fault.
    """
    if len(fmt.channels) != fmt.regular or not _PLAIN.fullmatch(text):
        return None
    rows = [pt.split() for pt in text.split(",")]
    if len(rows) > 1 and not rows[-1]:
        rows.pop()  # a trailing comma
    if not rows or any(len(r) != len(fmt.channels) for r in rows):
        return None
    try:
        table = np.array(rows, dtype=np.float64)
    except ValueError:
        return None
    return table if np.isfinite(table).all() else None
