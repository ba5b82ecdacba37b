"""A user's own pen trajectory files (``.npy``, ``.csv``, ``.inkml``, ``.xml``); atomic writes.

Where each part lives: reading a trajectory file (:func:`load_trajectory`,
which picks the reader by suffix from :data:`TRAJECTORY_READERS`: ``.npy``
here, ``.csv`` in :mod:`iloci.data.csvfile`, ``.inkml`` in
:mod:`iloci.data.inkml`, ``.xml`` in :mod:`iloci.data.gesturelog`) and a
folder of them (:func:`trajectory_files`) here; atomic writes
(:func:`write_atomic`, :func:`writable_dir`...) in :mod:`iloci.data.writes`,
re-exported here.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
import os
from pathlib import Path
import re

import numpy as np

from iloci import validation
from iloci.data.csvfile import check_times, read_csv
from iloci.data.gesturelog import read_xml
from iloci.data.inkml import read_inkml
from iloci.data.writes import writable_dir, writable_file, write_atomic, write_text_atomic
from iloci.errors import InvalidDemonstrationError, InvalidInputError
from iloci.interfaces import Demonstration

__all__ = ["TrajectoryFile", "load_trajectory", "shape_name", "trajectory_files", "writable_dir",
           "writable_file", "write_atomic", "write_text_atomic", "TRAJECTORY_READERS",
           "TRAJECTORY_SUFFIXES", "TRAJECTORY_FORMATS"]

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
    """Read one pen trajectory from a file; its suffix (any case) says how.

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

    An ``.inkml`` file is W3C InkML (https://www.w3.org/TR/InkML/): its
    pen-down ``<trace>`` elements joined in order, channels ``X``, ``Y``
    and optionally ``T`` (see :func:`iloci.data.inkml.read_inkml`).

    An ``.xml`` file is a $1/$N/$P gesture log, ``<Gesture>`` of
    ``<Point X= Y= T=/>`` (T in ms), strokes joined in order (see
    :func:`iloci.data.gesturelog.read_gesture_log`), or InkML when its root
    is ``<ink>``. XML is parsed with :mod:`defusedxml`: entity declarations
    are refused.

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
        The file is missing, unreadable, not of a suffix in
        :data:`TRAJECTORY_SUFFIXES`, or (XML) not well-formed or declaring
        an entity.
    InvalidDemonstrationError
        No usable columns (the error names the header) or channels, a value
        that is not a number, NaN or inf, or a time not after the previous
        one (the error names the file's line), fewer than 3 points or zero
        extent.
    """
    p = Path(path)
    if not p.is_file():
        raise InvalidInputError(f"trajectory file {str(p)!r} does not exist.")
    reader = TRAJECTORY_READERS.get(p.suffix.lower())
    if reader is None:
        raise InvalidInputError(f"unsupported trajectory file {p.name!r}: use "
                                f"{TRAJECTORY_FORMATS}.")
    positions, times = reader(p)
    name = shape if shape is not None else shape_name(p)
    try:
        return Demonstration(positions=positions, times=times, shape=name, index=index,
                             true_concept=true_concept)
    except InvalidDemonstrationError as exc:  # too few points, zero extent: name the file
        raise InvalidDemonstrationError(f"{p.name}: {exc}") from None


def _read_npy(p: Path) -> tuple[np.ndarray, np.ndarray | None]:
    try:
        with open(p, "rb") as fh:
            magic = fh.read(6)
    except OSError as exc:
        raise InvalidInputError(f"cannot read {str(p)!r}: {exc.strerror or exc}.") from None
    if magic != b"\x93NUMPY":
        raise InvalidInputError(
            f"{str(p)!r} is not a .npy file (one written by numpy.save starts with "
            f"\\x93NUMPY; this one starts with {magic!r}). Save the array with "
            "numpy.save(path, array), or give a text file the .csv suffix.")
    try:  # mapped, not read: the header's shape is checked before any data is loaded
        arr = np.load(p, allow_pickle=False, mmap_mode="r")
    except (OSError, ValueError, EOFError) as exc:
        if "pickle" in str(exc) or "Python objects" in str(exc):
            raise InvalidInputError(
                f"{str(p)!r} is refused: it holds pickled Python objects, and loading "
                "pickled data can run any code. A trajectory is a plain numeric array: "
                "save it with numpy.save(path, array) of floats.") from None
        raise InvalidInputError(f"cannot read {str(p)!r} as a numpy array: {exc}. "
                                "Save it with numpy.save(path, array).") from None
    if isinstance(arr, np.ndarray) and arr.ndim >= 1:
        validation.check_size(len(arr), f"{p.name} (a {arr.shape} array)")
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
        times = check_times(arr[:, 0], [f"row {i}" for i in range(len(arr))], p.name)
        return arr[:, 1:], times
    return arr, None


#: Trajectory file suffix (lower case) -> its reader: positions (N, 2) and times (N,) in
#: s or None. The one place a suffix is mapped to a format: ``iloci teach``, data-set
#: folders and manifests read what is here.
TRAJECTORY_READERS: dict[str, Callable[[Path], tuple[np.ndarray, np.ndarray | None]]] = {
    ".npy": _read_npy, ".csv": read_csv, ".inkml": read_inkml, ".xml": read_xml}
#: File suffixes read as trajectories (lower case; matched without case).
TRAJECTORY_SUFFIXES = tuple(TRAJECTORY_READERS)
#: The formats, as messages name them.
TRAJECTORY_FORMATS = (".npy or .csv (N x 2 positions, or N x 3 with time first), .inkml "
                      "(InkML) or .xml ($1/$N gesture log)")


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


_UNIT_RE = re.compile(r"^\s*(?:pos_|pen_)?[xy](?:_pos)?\s*(?:[_ \[(]\s*([a-z]+)\s*[\])]?)?\s*$",
                      re.IGNORECASE)


def position_unit(path: str | os.PathLike[str]) -> str | None:
    """The unit a CSV file's header names for x and y (``x_mm``, ``x [px]``), else None.

    Only the first line is read; other formats, a header without a unit and
    an unreadable file give None (reading the file reports those).
    """
    path = Path(path)
    if path.suffix.lower() != ".csv":
        return None
    try:
        with open(path, encoding="utf-8-sig", errors="replace") as fh:
            first = fh.readline()
    except OSError:
        return None
    units = set()
    for cell in re.split(r"[,;\t|]", first):
        m = _UNIT_RE.match(cell.strip().strip('"'))
        if m and m.group(1):
            units.add(m.group(1).lower())
    return units.pop() if len(units) == 1 else None


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

