"""UNIPEN ``train_r01_v07``: isolated online handwriting of many writers.

The data set (Guyon, Schomaker, Plamondon, Liberman and Janet 1994, "UNIPEN
project of on-line data exchange and recognizer benchmarks", ICPR,
doi:10.1109/ICPR.1994.576870; the December 1999 release, Unipen Consortium,
doi:10.5281/zenodo.1195803, Creative Commons Attribution 4.0) is not shipped
with iloci. Get it with git; the reader takes the folder that holds
``data/`` and ``include/``::

    git clone --depth 1 https://github.com/GreenCappuccino/train_r01_v07

(the parse-ready copy of the Zenodo release; its ``original`` branch has the
files as released). Categories: ``1a`` isolated digits, ``1b`` upper case,
``1c`` lower case letters (see its ``CDROM-README``).

The UNIPEN format, as far as this reader needs it: a file of ``data/<cat>/``
holds ``.INCLUDE`` lines (paths under ``include/``, followed recursively) and
``.SEGMENT CHARACTER <delineation> <quality> "<label>"`` lines. The included
files hold ``.PEN_DOWN`` blocks of ``x y ...`` rows (columns named by
``.COORD``), ``.PEN_UP`` markers, and header keywords (``.WRITER_ID``,
``.X_POINTS_PER_INCH``, ``.POINTS_PER_SECOND``). A delineation lists
components by number, ``3``, ``3-4``, ``3,5``, or with point ranges
``426:18-426:68``; components are the pen-down strokes numbered from 0 in
file order (the pen-up markers of this release carry no points; counting
them too makes half the digits point at empty pen-ups).

A *writer* is the person: ``"<contributor>/<WRITER_ID>"`` (e.g.
``aga/crlmtchl``), except for IBM's ``ibm0`` set, whose ``WRITER_ID`` is
``rNN-WW`` and whose person is ``WW``: ``ibm/r01-04``, ``ibm/r02-04``,
``ibm/r03-04`` and ``ibm/r04-04`` are one writer, ``ibm/writer-04``. So
writer-disjoint splits never put one person on both sides. The file's own id
stays in :attr:`UnipenSample.writer_id`. The evidence for the IBM rule, all in
the release:

- ``include/ibm/ibm0.doc`` says "Number of Writer(s): 12" and "Number of
  sessions: three per writer"; its 22 files ``r0007`` ... ``r0414`` hold
  exactly 12 distinct ``WW`` (04 05 06 07 08 09 11 12 13 14 15 16), in 1 to 4
  files each.
- Files of one ``WW`` share recorded ink: of the pen-down strokes of 8 or
  more points, 14-45 % of one file's recur bit for bit in another file of the
  same ``WW`` (e.g. 176 of ``r01-04``'s 405 in ``r02-04``), in all 15 such
  pairs; no stroke recurs between files of different ``WW``.
- The 170 digits stored under two or more writer ids in category ``1a``
  pair only ids of one ``WW`` (and ``gmd/alek`` with ``gmd/kast``, below).

Not grouped: ``gmd/kast``'s file repeats 268 of ``gmd/alek``'s 476 strokes,
but the release does not say whether one person wrote both (``gmd.doc``
names 8 writers and ships 3); :func:`read_unipen` drops the repeated
drawings, and neither id drew every digit in one stroke, so the benchmark's
subset (:func:`balanced_subset`) has neither.
"""

from __future__ import annotations

import hashlib
import os
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from iloci.data.datasets import drawing_key
from iloci.errors import InvalidInputError
from iloci.interfaces import Demonstration

__all__ = ["UnipenSample", "read_unipen", "person", "unipen_digits", "unipen_letters",
           "unipen_root", "balanced_subset", "samples_checksum", "UNIPEN_CITATION"]

#: How to cite the data set (reports and the benchmark print it).
UNIPEN_CITATION = ("UNIPEN train_r01_v07 (Guyon et al. 1994, doi:10.1109/ICPR.1994.576870; "
                   "data doi:10.5281/zenodo.1195803, CC BY 4.0)")

_SEGMENT = re.compile(r'^\.SEGMENT\s+(\S+)\s+(\S+)\s+(\S+)\s+"(.*)"\s*$')


@dataclass(frozen=True)
class UnipenSample:
    """One labelled segment of a UNIPEN file.

    Attributes
    ----------
    label : str
        The segment's text, e.g. ``"7"``.
    writer : str
        The person who wrote it: ``"<contributor>/<WRITER_ID>"``, or for
        IBM's session ids ``rNN-WW``, ``"ibm/writer-WW"`` (module docstring).
    path : str
        The ``data/`` file, relative to the data set's root.
    strokes : tuple of ndarray
        Each pen-down stroke of the segment, shape (n, 2), ``x, y`` as
        recorded (``y`` up: a 7's stroke ends below its start in every
        contributor's files), in mm when the file gives
        ``.X_POINTS_PER_INCH``, else in tablet units.
    points_per_second : float or None
        Sampling rate from ``.POINTS_PER_SECOND``, when given.
    quality : str
        The segment's quality field (``?`` unknown, ``OK``, ...).
    writer_id : str
        ``"<contributor>/<WRITER_ID>"`` as the file names it (e.g.
        ``"ibm/r02-04"``); empty means the same as ``writer``.
    """

    label: str
    writer: str
    path: str
    strokes: tuple[np.ndarray, ...]
    points_per_second: float | None = None
    quality: str = "?"
    writer_id: str = ""
    _key: tuple = field(default=(), repr=False, compare=False)

    @property
    def single_stroke(self) -> bool:
        """Drawn in one pen-down stroke."""
        return len(self.strokes) == 1

    def demonstration(self, index: int = 0) -> Demonstration:
        """The sample as a :class:`~iloci.interfaces.Demonstration`.

        Strokes are joined in order (a multi-stroke sample's pen-up jumps
        become straight segments). ``shape`` and ``true_concept`` are the
        label, ``index`` the given one; times from ``points_per_second``
        when known, else one step per point.

        Raises
        ------
        InvalidDemonstrationError
            Fewer than 3 points or zero extent (see ``Demonstration``).
        """
        pos = np.concatenate(self.strokes, axis=0)
        times = (np.arange(len(pos)) / self.points_per_second
                 if self.points_per_second else None)
        return Demonstration(positions=pos, times=times, shape=self.label, index=index,
                             true_concept=self.label)


def unipen_root(path: str | os.PathLike[str]) -> Path:
    """Check that ``path`` is a ``train_r01_v07`` folder (with ``data/`` and ``include/``).

    Raises
    ------
    InvalidInputError
        It is not, with how to get one.
    """
    root = Path(path).expanduser()
    if not (root / "data").is_dir() or not (root / "include").is_dir():
        raise InvalidInputError(
            f"{root} is not a UNIPEN train_r01_v07 folder (it needs data/ and include/). "
            "Get one with: git clone --depth 1 "
            "https://github.com/GreenCappuccino/train_r01_v07")
    return root


class _Parser:
    """Reads one data file with its includes: components, header state, segments."""

    def __init__(self, root: Path, rel: str) -> None:
        self.root = root
        self.rel = rel
        self.contributor = Path(rel).parts[2] if len(Path(rel).parts) > 2 else "?"
        self.strokes: list[np.ndarray] = []
        self.writers: list[str] = []
        self.rates: list[float | None] = []
        self.scales: list[float | None] = []
        self.segments: list[tuple[str, str, str]] = []
        self.writer = "?"
        self.rate: float | None = None
        self.ppi: float | None = None
        self._rows: list[list[float]] | None = None

    def _close(self) -> None:
        if self._rows is not None:
            rows = np.asarray(self._rows, dtype=np.float64).reshape(-1, 2)
            self.strokes.append(rows)
            self.writers.append(self.writer)
            self.rates.append(self.rate)
            self.scales.append(self.ppi)
        self._rows = None

    def read(self, path: Path, depth: int = 0) -> None:
        if depth > 8:
            raise InvalidInputError(f"{path}: .INCLUDE nested more than 8 deep (a loop?).")
        try:
            text = path.read_text(encoding="latin-1")
        except OSError as exc:
            raise InvalidInputError(
                f"cannot read UNIPEN file {path} ({exc.strerror or exc}); the data set "
                "folder is incomplete: clone it again.") from exc
        for raw in text.splitlines():
            line = raw.strip()
            if not line:
                continue
            if line[0] != ".":
                if self._rows is not None:
                    cols = line.split()
                    try:
                        self._rows.append([float(cols[0]), float(cols[1])])
                    except (ValueError, IndexError):
                        continue  # a stray comment line inside a block
                continue
            word, _, rest = line.partition(" ")
            word = word.split("\t")[0]
            rest = line[len(word):].strip()
            if word == ".PEN_DOWN":
                self._close()
                self._rows = []
            elif word in (".PEN_UP", ".DT"):
                self._close()
            elif word == ".INCLUDE":
                self._close()
                self.read(self.root / "include" / rest, depth + 1)
            elif word == ".SEGMENT":
                self._close()
                m = _SEGMENT.match(line)
                if m and m.group(1).upper() == "CHARACTER":
                    self.segments.append((m.group(2), m.group(3), m.group(4)))
            else:
                self._close()
                if word == ".WRITER_ID" and rest:
                    self.writer = rest.split()[0]
                elif word == ".POINTS_PER_SECOND":
                    self.rate = _positive(rest)
                elif word == ".X_POINTS_PER_INCH":
                    self.ppi = _positive(rest)
        if depth == 0:
            self._close()

    def samples(self) -> Iterator[UnipenSample]:
        for delineation, quality, label in self.segments:
            if quality.upper() == "BAD":
                continue
            parts = _delineation(delineation, len(self.strokes))
            if parts is None:
                continue
            strokes = []
            for comp, lo, hi in parts:
                s = self.strokes[comp][lo:hi]
                scale = self.scales[comp]
                s = s * (25.4 / scale) if scale else s.copy()
                if len(s):
                    strokes.append(s)
            if not strokes:
                continue
            first = parts[0][0]
            yield UnipenSample(label=label, writer=person(self.contributor, self.writers[first]),
                               path=self.rel, strokes=tuple(strokes),
                               points_per_second=self.rates[first], quality=quality,
                               writer_id=f"{self.contributor}/{self.writers[first]}")


_IBM_SESSION = re.compile(r"r\d\d-(\d\d)")


def person(contributor: str, writer_id: str) -> str:
    """The writer (the person) of a file: ``"<contributor>/<writer_id>"``, except IBM's
    session ids ``rNN-WW``, one person per ``WW``: ``person("ibm", "r02-04")`` is
    ``"ibm/writer-04"`` (evidence in the module docstring)."""
    m = _IBM_SESSION.fullmatch(writer_id)
    if contributor == "ibm" and m:
        return f"ibm/writer-{m.group(1)}"
    return f"{contributor}/{writer_id}"


def _positive(text: str) -> float | None:
    try:
        v = float(text.split()[0])
    except (ValueError, IndexError):
        return None
    return v if v > 0 else None


def _delineation(text: str, n: int) -> list[tuple[int, int, int | None]] | None:
    """``"3-4"``, ``"3,5"``, ``"426:18-426:68"`` -> [(component, first point, end point)]."""
    out: list[tuple[int, int, int | None]] = []
    try:
        for part in text.split(","):
            a, _, b = part.partition("-")
            ca, _, pa = a.partition(":")
            cb, _, pb = (b or a).partition(":")
            c0, c1 = int(ca), int(cb)
            if not 0 <= c0 <= c1 < n:
                return None
            for c in range(c0, c1 + 1):
                lo = int(pa) if (c == c0 and pa) else 0
                hi = int(pb) + 1 if (c == c1 and pb) else None
                out.append((c, lo, hi))
    except ValueError:
        return None
    return out


def read_unipen(root: str | os.PathLike[str], category: str = "1a", *,
                labels: Iterable[str] | None = None, single_stroke: bool = True,
                min_points: int = 8, drop_copies: bool = True) -> list[UnipenSample]:
    """Labelled samples of one UNIPEN category.

    Parameters
    ----------
    root : path
        The ``train_r01_v07`` folder (module docstring: how to get it).
    category : str
        ``"1a"`` digits, ``"1b"`` upper case, ``"1c"`` lower case, ...
    labels : iterable of str, optional
        Keep only these labels (e.g. ``"0123456789"``).
    single_stroke : bool
        Keep only samples drawn in one pen-down stroke (what a unistroke
        recognizer and iloci's one pen path take).
    min_points : int
        Drop samples with fewer points (taps, broken strokes).
    drop_copies : bool
        Keep a drawing stored more than once (the same points, bit for bit)
        only the first time it is met, in the order below, whatever its
        label or writer says elsewhere. train_r01_v07 stores such copies:
        of its 11321 single-stroke digits, 354 repeat an earlier one, some
        within one file (a segment listed twice), some under another writer
        id (IBM's ``r02-04`` repeats ``r01-04``, ...). The release does not
        say which writer drew a copied digit; keeping the first is
        deterministic and needs no seed. A copy kept would be taught in one
        fold and recognized in another (the check of
        :func:`iloci.data.datasets.load_dataset` refuses such a data set).

    Returns
    -------
    list of UnipenSample
        In file order (files sorted by path), then segment order. Segments
        marked ``BAD`` and those whose delineation points outside the file
        are skipped.

    Raises
    ------
    InvalidInputError
        ``root`` is not a train_r01_v07 folder, the category has no files,
        or an included file is missing.
    """
    base = unipen_root(root)
    folder = base / "data" / category
    files = sorted(folder.rglob("*.dat")) if folder.is_dir() else []
    if not files:
        raise InvalidInputError(f"no UNIPEN files under {folder}: category {category!r} "
                                "is not in this copy (1a digits, 1b upper case, 1c lower "
                                "case).")
    keep = None if labels is None else set(labels)
    out = []
    seen: set[bytes] = set()
    for f in files:
        parser = _Parser(base, f.relative_to(base).as_posix())
        parser.read(f)
        for s in parser.samples():
            if keep is not None and s.label not in keep:
                continue
            if single_stroke and not s.single_stroke:
                continue
            if sum(len(k) for k in s.strokes) < min_points:
                continue
            pos = np.concatenate(s.strokes)
            if not np.all(np.isfinite(pos)) or float(np.max(np.ptp(pos, axis=0))) <= 0:
                continue
            if drop_copies:
                key = drawing_key(pos)
                if key in seen:
                    continue
                seen.add(key)
            out.append(s)
    return out


def unipen_digits(root: str | os.PathLike[str], **kwargs) -> list[UnipenSample]:
    """Single-stroke isolated digits (``1a``, labels ``0``-``9``); see :func:`read_unipen`."""
    return read_unipen(root, "1a", labels="0123456789", **kwargs)


def unipen_letters(root: str | os.PathLike[str], category: str = "1c",
                   **kwargs) -> list[UnipenSample]:
    """Single-stroke isolated letters (``1c`` lower case by default, ``1b`` upper case)."""
    import string

    letters = string.ascii_lowercase if category == "1c" else string.ascii_uppercase
    return read_unipen(root, category, labels=letters, **kwargs)


def balanced_subset(samples: Iterable[UnipenSample], *, per: int = 1, seed: int = 0,
                    labels: Iterable[str] | None = None) -> list[UnipenSample]:
    """``per`` samples of every label from each writer who drew every label.

    The benchmark's UNIPEN digits (benchmarks/datasets.py): the writers
    (persons, ``UnipenSample.writer``: IBM's session ids of one person count
    as one) who drew each of the ten digits in one stroke at least ``per``
    times (15 in train_r01_v07 for ``per=1``, counted after
    :func:`read_unipen` dropped the 354 copies; 19 when IBM's session ids
    were counted as writers), ``per`` samples of each digit from each, drawn
    at random (seeded) from all of that person's samples. Every writer draws every
    concept, so writer-disjoint folds can learn every concept in each fold.
    A writer left short of a label (e.g. one whose digits were all copies of
    another writer's, kept under that one) is not picked. Identical samples
    in ``samples`` are not removed here; read with ``drop_copies=True``.

    Parameters
    ----------
    samples : iterable of UnipenSample
    per : int
        Samples per writer and label.
    seed : int
    labels : iterable of str, optional
        The labels every kept writer must have drawn (default: every label
        in ``samples``).

    Returns
    -------
    list of UnipenSample
        Sorted by label, then writer, then file order.
    """
    samples = list(samples)
    wanted = sorted(set(labels) if labels is not None else {s.label for s in samples})
    by: dict[tuple[str, str], list[int]] = {}
    for i, s in enumerate(samples):
        by.setdefault((s.writer, s.label), []).append(i)
    writers = sorted({w for w, _ in by
                      if all(len(by.get((w, lab), ())) >= per for lab in wanted)})
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 25]))
    keep = []
    for lab in wanted:
        for w in writers:
            idx = by[(w, lab)]
            keep += sorted(int(i) for i in rng.choice(idx, size=per, replace=False))
    return [samples[i] for i in keep]


def samples_checksum(samples: Iterable[UnipenSample]) -> str:
    """SHA-256 over labels, writers and points: names exactly which samples were used."""
    h = hashlib.sha256()
    for s in samples:
        h.update(f"{s.label}\0{s.writer}\0{s.path}\0".encode("utf-8", "surrogatepass"))
        for k in s.strokes:
            h.update(np.ascontiguousarray(k, dtype="<f8").tobytes())
    return h.hexdigest()
