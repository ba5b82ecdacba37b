"""What the XML trajectory readers share: a safe parse with line numbers, strokes joined.

:func:`parse_xml` reads a file with :mod:`defusedxml` (an entity declaration,
the "billion laughs" attack's tool, and external references are refused
before anything is expanded or fetched) and keeps the line of each element,
so that an error names it. :func:`join_strokes` joins a drawing's strokes in
order into one pen path, as :meth:`iloci.data.unipen.UnipenSample.demonstration`
does. The formats themselves: :mod:`iloci.data.inkml` (W3C InkML) and
:mod:`iloci.data.gesturelog` (the $1/$N/$P gesture logs).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from xml.etree.ElementTree import Element, ParseError, TreeBuilder

import numpy as np

from iloci import validation
from iloci.data.csvfile import check_times
from iloci.errors import InvalidDemonstrationError, InvalidInputError

__all__ = ["XmlDocument", "parse_xml", "local_name", "number", "join_strokes"]

#: A number as the trajectory formats write one: decimal, optional exponent (no NaN, inf).
_NUMBER_RE = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")


@dataclass
class XmlDocument:
    """A parsed XML file.

    Attributes
    ----------
    root : Element
    name : str
        The file's name, for messages.
    lines : dict
        Element -> the line its start tag begins on (1-based).
    """

    root: Element
    name: str
    lines: dict[Element, int] = field(repr=False)

    def line(self, element: Element) -> int:
        """The line ``element``'s start tag begins on (0 when unknown)."""
        return self.lines.get(element, 0)


class _LineBuilder:
    """A tree builder that notes the line of every element's start tag."""

    def __init__(self) -> None:
        self.builder = TreeBuilder()
        self.lines: dict[Element, int] = {}
        self.expat: Any = None

    def start(self, tag: str, attrs: dict[str, str]) -> Element:
        element = self.builder.start(tag, attrs)
        self.lines[element] = int(self.expat.CurrentLineNumber) if self.expat else 0
        return element

    def end(self, tag: str) -> Element:
        return self.builder.end(tag)

    def data(self, text: str) -> None:
        self.builder.data(text)

    def close(self) -> Element:
        return self.builder.close()


def parse_xml(p: Path, what: str) -> XmlDocument:
    """Parse an XML file safely, keeping each element's line.

    Parameters
    ----------
    p : Path
    what : str
        What the file should be, for messages (``"an InkML file"``).

    Returns
    -------
    XmlDocument

    Raises
    ------
    InvalidInputError
        The file cannot be read, is not well-formed XML (the parser's line
        and column named), names an encoding Python does not know, nests
        elements too deeply, or declares an XML entity or refers to an
        external one (refused: an entity can expand into gigabytes, and an
        external one reads other files).
    """
    # imported here: `import iloci` (every fold worker) needs no XML parser
    try:
        from defusedxml import DefusedXmlException, EntitiesForbidden
        from defusedxml.ElementTree import DefusedXMLParser
    except ImportError:
        raise InvalidInputError(
            f"cannot read {p.name}: reading {what} needs defusedxml, a dependency of iloci "
            "that is not installed here. Install it with: pip install defusedxml") from None
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise InvalidInputError(f"cannot read {str(p)!r}: {exc.strerror or exc}.") from None
    target = _LineBuilder()
    parser = DefusedXMLParser(target=target)
    target.expat = parser.parser
    try:
        parser.feed(raw)
        root = parser.close()
    except ParseError as exc:
        line, col = getattr(exc, "position", (0, 0))
        reason = str(exc).split(":")[0]
        raise InvalidInputError(
            f"{p.name} is not {what}: it is not well-formed XML (line {line}, column "
            f"{col}: {reason}). Check that the file is the XML the recorder wrote, complete "
            "and not another format under its suffix.") from None
    except EntitiesForbidden as exc:
        raise InvalidInputError(
            f"{p.name}, line {parser.parser.CurrentLineNumber}: declares the XML entity "
            f"{exc.name!r} (<!ENTITY ...>), which is refused: an entity can expand into "
            "gigabytes of text (the 'billion laughs' attack). A trajectory file needs none: "
            "remove its <!DOCTYPE ...> declarations.") from None
    except LookupError as exc:  # an encoding Python has no codec for
        raise InvalidInputError(
            f"{p.name}: {exc} (named in its <?xml ... encoding=...?> declaration). Save it "
            "as UTF-8.") from None
    except RecursionError:
        raise InvalidInputError(f"{p.name}: its elements are nested too deeply to read (a "
                                "trajectory file nests a few levels).") from None
    except DefusedXmlException as exc:
        raise InvalidInputError(
            f"{p.name}, line {parser.parser.CurrentLineNumber}: refers to an external "
            f"resource ({exc}), which is refused: reading the file must not read other "
            "files or the network. Remove the reference.") from None
    return XmlDocument(root, p.name, target.lines)


def local_name(tag: str) -> str:
    """An element's name without its namespace: ``{http://...}trace`` -> ``trace``."""
    return tag.rpartition("}")[2]


def number(text: str) -> float | None:
    """``text`` as a float when it is a plain decimal number (``-1.5``, ``2e3``), else None."""
    t = text.strip()
    return float(t) if _NUMBER_RE.fullmatch(t) else None


class _PointNames(Sequence[str]):
    """How an error names point ``i`` of joined strokes, made only when an error asks."""

    def __init__(self, n: int, name_of: Callable[[int], str]) -> None:
        self._n = n
        self._name_of = name_of

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, slice):
            return [self._name_of(k) for k in range(self._n)[i]]
        return self._name_of(range(self._n)[i])


def join_strokes(strokes: Sequence[np.ndarray], times: Sequence[np.ndarray] | None,
                 where: Callable[[int], str], name: str) -> tuple[np.ndarray, np.ndarray | None]:
    """One pen path from a drawing's strokes, joined in order.

    As for a multi-stroke UNIPEN sample
    (:meth:`iloci.data.unipen.UnipenSample.demonstration`), a pen-up jump
    between strokes becomes a straight segment.

    Parameters
    ----------
    strokes : sequence of ndarray, each shape (n_k, 2)
        Pen positions ``x, y`` of each stroke, in the file's units.
    times : sequence of ndarray, each shape (n_k,), or None
        Time stamps (s) of each stroke's points; None when the file gives none.
    where : callable
        How an error names joined point ``i`` (``"trace 2 (line 14), point 5"``).
    name : str
        The file's name, for messages.

    Returns
    -------
    positions : ndarray, shape (N, 2)
    times : ndarray, shape (N,), or None
        Checked by :func:`iloci.data.csvfile.check_times` (repeated stamps
        spread; a time before the previous one is an error naming its point).

    Raises
    ------
    InvalidDemonstrationError
        More than :data:`iloci.validation.MAX_POINTS` points, or a time that
        goes back.
    """
    n = sum(len(s) for s in strokes)
    validation.check_size(n, name)
    positions = (np.concatenate(strokes, axis=0) if strokes
                 else np.empty((0, 2), dtype=np.float64))
    if times is None:
        return positions, None
    t = np.concatenate(times) if times else np.empty(0, dtype=np.float64)
    if len(t) < 2:
        return positions, t
    return positions, check_times(t, _PointNames(len(t), where), name)


def refuse(name: str, line: int, what: str) -> InvalidDemonstrationError:
    """An error about a file's content: ``"NAME, line L: WHAT"`` (no line when unknown)."""
    at = f", line {line}" if line else ""
    return InvalidDemonstrationError(f"{name}{at}: {what}")
