"""A pen trajectory from a $1/$N/$P gesture log (``.xml``).

The format of the logs published with the $1 unistroke recognizer (Wobbrock,
Wilson and Li 2007, "Gestures without libraries, toolkits or training: a $1
recognizer for user interface prototypes", UIST, doi:10.1145/1294211.1294238)
and the $N and $P multistroke recognizers (Anthony and Wobbrock 2010, GI;
Vatavu, Anthony and Wobbrock 2012, ICMI, doi:10.1145/2388676.2388732)::

    <Gesture Name="arrow01" Subject="1" Speed="fast" Number="1" NumPts="62" ...>
      <Point X="65" Y="139" T="9250250" />
      ...
    </Gesture>

and for multistroke gestures ``<Stroke>`` elements, each wrapping its
``<Point>`` elements. A ``.xml`` file whose root is InkML's ``<ink>`` is read
as InkML (:mod:`iloci.data.inkml`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from xml.etree.ElementTree import Element

import numpy as np

from iloci.data.inkml import read_inkml_document
from iloci.data.xmlfile import join_strokes, local_name, number, parse_xml, refuse

__all__ = ["read_gesture_log", "read_xml"]


def read_xml(p: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """Positions (N, 2) and times (N,) in s, or None, from a ``.xml`` trajectory file.

    A root ``<Gesture>`` is a $1/$N/$P gesture log (:func:`read_gesture_log`
    says what is read); a root ``<ink>`` is InkML
    (:func:`iloci.data.inkml.read_inkml`). Errors: those of the two readers;
    another root element is an :class:`~iloci.errors.InvalidDemonstrationError`
    naming it.
    """
    doc = parse_xml(p, "a gesture log (<Gesture>) or InkML (<ink>)")
    if local_name(doc.root.tag) == "ink":
        return read_inkml_document(doc)
    return _gesture(doc.root, doc.name, doc.line)


def read_gesture_log(p: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """Positions (N, 2) and times (N,) in s, or None, from a $1/$N/$P gesture log.

    What is read:

    * The root ``<Gesture>`` (its attributes, ``Name``, ``Subject``,
      ``Speed``, ``Number``..., are not read: a data set's concepts and
      writers come from its folders or manifest).
    * Its ``<Point X="..." Y="..." T="..."/>`` children, or the points of
      its ``<Stroke>`` children ($N and $P logs), strokes joined in order
      into one pen path, each pen-up jump a straight segment, as a
      multi-stroke UNIPEN sample is joined
      (:meth:`iloci.data.unipen.UnipenSample.demonstration`). An empty
      ``<Stroke>`` adds nothing.
    * ``X`` and ``Y`` are the position in the logger's units (screen
      pixels, y down: use ``[sensorimotor] y_axis = "down"``). ``T`` is in
      milliseconds (the loggers' tick count) and read as seconds
      (``T / 1000``); repeated stamps are spread as for a CSV file
      (:func:`iloci.data.csvfile.check_times`). Without ``T`` on every point
      the times are ``0, 1, ..., N-1``. Attribute names are matched
      without case (``x``, ``X``); other attributes (``Pressure``) are
      ignored.

    Raises
    ------
    InvalidInputError
        Not readable, not XML (its line and column), or an XML entity
        declaration (refused).
    InvalidDemonstrationError
        A root other than ``<Gesture>``; no point; points directly in
        ``<Gesture>`` beside ``<Stroke>`` elements; a point without ``X``
        or ``Y``, or one whose ``X``, ``Y`` or ``T`` is not a number; ``T``
        on some points only; a time before the previous point's. Each names
        the file and the line.
    """
    doc = parse_xml(p, "a gesture log")
    return _gesture(doc.root, doc.name, doc.line)


def _gesture(root: Element, name: str, line_of: Callable[[Element], int]
             ) -> tuple[np.ndarray, np.ndarray | None]:
    if local_name(root.tag) != "Gesture":
        raise refuse(name, line_of(root),
                     f"the root element is <{local_name(root.tag)}>; a $1/$N gesture log's is "
                     "<Gesture> (one gesture a file, its <Point X= Y= T=/> elements inside), "
                     "and InkML's <ink>.")
    children = [el for el in root if local_name(el.tag) in ("Point", "Stroke")]
    kinds = {local_name(el.tag) for el in children}
    if len(kinds) > 1:
        raise refuse(name, line_of(root), "the <Gesture> holds both <Point> and <Stroke> "
                     "elements; a gesture's points are all in its <Stroke>s or all directly "
                     "in it.")
    groups = ([[p for p in el if local_name(p.tag) == "Point"] for el in children]
              if kinds == {"Stroke"} else [children])
    points = [p for g in groups for p in g]
    if not points:
        raise refuse(name, line_of(root), "the <Gesture> has no <Point> (an empty "
                     "recording); leave the file out.")
    values = np.empty((len(points), 3), dtype=np.float64)
    timed = []
    for i, p in enumerate(points):
        attrs = {k.lower(): v for k, v in p.attrib.items()}
        timed.append("t" in attrs)
        for c, key in enumerate(("x", "y", "t")):
            if key not in attrs:
                if key == "t":
                    values[i, c] = np.nan
                    continue
                raise refuse(name, line_of(p), f"<Point> {i + 1} has no {key.upper()} "
                             "attribute; each point is <Point X=\"..\" Y=\"..\" T=\"..\"/>.")
            v = number(attrs[key])
            if v is None:
                raise refuse(name, line_of(p), f"<Point> {i + 1}: {key.upper()}="
                             f"{attrs[key]!r} is not a number; write positions and times as "
                             "numbers such as 87, -3.5 or 1.2e3 (a decimal point, not a "
                             "comma).")
            values[i, c] = v
    if any(timed) and not all(timed):
        i = timed.index(not timed[0])
        raise refuse(name, line_of(points[i]), f"<Point> {i + 1} {'has' if timed[i] else 'has no'}"
                     f" T where <Point> 1 {'has' if timed[0] else 'has none'}; give every point "
                     "a time (T, ms) or none.")
    sizes = np.cumsum([0] + [len(g) for g in groups])
    strokes = [values[a:b, :2] for a, b in zip(sizes[:-1], sizes[1:]) if b > a]
    times = ([values[a:b, 2] / 1000.0 for a, b in zip(sizes[:-1], sizes[1:]) if b > a]
             if all(timed) else None)

    def where(i: int) -> str:
        return f"line {line_of(points[i])} (<Point> {i + 1})"

    return join_strokes(strokes, times, where, name)
