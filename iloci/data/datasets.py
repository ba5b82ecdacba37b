"""A user's own data set of labelled trajectories, for ``iloci evaluate --data PATH``.

Two layouts (docs/guide.md, "Your own shapes"):

**A folder per concept**::

    shapes/
        circle/    a.csv  b.csv  ...          files of one concept
        square/    alice/1.csv  bob/1.csv     or one sub-folder per writer

Each sub-folder of ``PATH`` is a concept (its name); the trajectory files
in it (every format ``iloci teach`` reads: ``.npy``, ``.csv``, ``.inkml``,
``.xml``, the suffix in any case; see
:func:`iloci.data.files.load_trajectory`) are its samples. Files directly
in a concept folder have no writer; a sub-folder of a concept folder names
the writer of the files in it (deeper folders are read too, the first level
naming the writer).

**A manifest**, ``PATH`` a ``.csv`` or ``.json`` file (or a folder holding
``manifest.csv`` / ``manifest.json``): one row per sample with ``file``
(relative to the manifest's folder) and ``concept``, optionally ``writer``
and ``session``. Column names are matched without case; ``path`` for
``file``, ``label``/``class`` for ``concept``, ``user``/``subject``/
``person`` for ``writer`` are accepted. A JSON manifest is a list of such
objects, or ``{"samples": [...]}``.

Everything is checked before any learning starts: every problem is listed
in one :class:`~iloci.errors.InvalidInputError` naming the paths (empty
folders, unreadable files, files missing from the manifest's folder, mixed
units, concepts with fewer samples than folds).
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import os
import re
import warnings
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from iloci.data.csvfile import decode_text
from iloci.data.files import (TRAJECTORY_FORMATS, TRAJECTORY_SUFFIXES, load_trajectory,
                              position_unit)
from iloci.errors import DataSetWarning, InvalidInputError, TimeUnitWarning
from iloci.interfaces import Demonstration
from iloci.progress import long_step

__all__ = ["Sample", "DataSet", "load_dataset", "load_dataset_once", "check_protocol",
           "writer_folds", "demos_checksum", "drawing_key", "TRAJECTORY_SUFFIXES"]

_MANIFESTS = ("manifest.csv", "manifest.json")
_FILE_COLS = ("file", "path", "filename", "file_name", "trajectory")
_CONCEPT_COLS = ("concept", "label", "class", "gesture", "shape", "category")
_WRITER_COLS = ("writer", "user", "subject", "person", "participant", "author")
_SESSION_COLS = ("session", "trial", "run")
#: Lists of problems are cut at this many lines in an error message.
_MAX_LISTED = 12


@dataclass(frozen=True)
class Sample:
    """One labelled trajectory of a data set.

    Attributes
    ----------
    path : str
        The file, relative to the data set's folder (``/`` separated).
    concept : str
    writer, session : str or None
    """

    path: str
    concept: str
    writer: str | None = None
    session: str | None = None


@dataclass
class DataSet:
    """A loaded, checked data set.

    Attributes
    ----------
    name : str
        The folder's name; a manifest's file name without its suffix, or its folder's
        name when the manifest is ``manifest.csv`` / ``manifest.json``.
    root : str
        Absolute path of the folder the sample paths are relative to.
    source : str
        What ``PATH`` was (the folder or the manifest file).
    layout : str
        ``"folders"`` or ``"manifest"``.
    samples : list of Sample
    demos : list of Demonstration
        One per sample, in the same order: ``shape`` and ``true_concept``
        the concept, ``index`` its number within the concept (keys
        ``"circle/0"``, ``"circle/1"``, ...).
    checksum : str
        SHA-256 over every sample's path, labels and file bytes.
    """

    name: str
    root: str
    source: str
    layout: str
    samples: list[Sample]
    demos: list[Demonstration] = field(repr=False)
    checksum: str = ""

    @property
    def concepts(self) -> dict[str, int]:
        """Concept -> number of samples, sorted by concept."""
        return dict(sorted(Counter(s.concept for s in self.samples).items()))

    @property
    def writers(self) -> list[str]:
        """The writers named, sorted (empty when none are)."""
        return sorted({s.writer for s in self.samples if s.writer is not None})

    def sample_files(self) -> dict[str, dict[str, str | None]]:
        """Each sample's key (``folds.json``'s ``"circle/0"``) -> its ``file`` (relative to
        :attr:`root`, ``/`` separated, as a manifest names it), ``concept``, ``writer`` and
        ``session`` (None when not named): ``metrics.json``'s ``samples``. A file name
        whose bytes are not UTF-8 is written with them as ``\\xNN`` (as concept names
        are, :func:`_text`): JSON and CSV hold text, not the file system's bytes."""
        return {d.key: {"file": _text(s.path), "concept": s.concept, "writer": s.writer,
                        "session": s.session} for s, d in zip(self.samples, self.demos)}

    def writers_of(self, indices: Sequence[int]) -> list[str]:
        """The writers (sorted, each once) of the samples at ``indices``."""
        return sorted({str(w) for i in indices if (w := self.samples[i].writer) is not None})

    def summary(self) -> dict[str, Any]:
        """What ``metrics.json``'s ``dataset`` records: name, path, size, checksum, ..."""
        return {"name": self.name, "path": self.source, "layout": self.layout,
                "samples": len(self.samples), "concepts": self.concepts,
                "writers": len(self.writers), "checksum": self.checksum}


def _fail(title: str, problems: Sequence[str], hint: str) -> InvalidInputError:
    shown = list(problems[:_MAX_LISTED])
    if len(problems) > _MAX_LISTED:
        shown.append(f"... and {len(problems) - _MAX_LISTED} more")
    return InvalidInputError(title + "\n  " + "\n  ".join(shown) + "\n" + hint)


def _visible(p: Path) -> bool:
    return not p.name.startswith((".", "_"))


#: Files that file managers and archivers leave in folders: never drawings, passed over
#: without a note (as are hidden files and a zip's ``__MACOSX`` folder).
_JUNK = frozenset({"thumbs.db", "desktop.ini", "icon\r", "ehthumbs.db"})


def _hidden(rel: Path) -> bool:
    """A path (relative to the data set) that no one means as data: hidden or archive junk."""
    return (any(part.startswith(".") or part == "__MACOSX" for part in rel.parts)
            or rel.name.lower() in _JUNK)


def _listed(paths: Sequence[str], n: int = 3) -> str:
    return ", ".join(paths[:n]) + (", ..." if len(paths) > n else "")


def _scan_folders(root: Path) -> tuple[list[Sample], list[str]]:
    """The samples of a data set of concept folders, and its problems.

    Files and folders whose names start with ``.`` or ``_`` are left out
    (a note names the trajectory files that were, :class:`DataSetWarning`),
    as are files of other formats (a note too, unless they are a file
    manager's junk: ``Thumbs.db``, ``__MACOSX/``); a link whose file is
    missing is a problem, not a file passed over.
    """
    problems: list[str] = []
    entries = sorted(root.iterdir())
    concept_dirs = [d for d in entries if d.is_dir() and _visible(d)]
    loose = sorted(f.name for f in entries
                   if f.is_file() and f.suffix.lower() in TRAJECTORY_SUFFIXES and _visible(f))
    if not concept_dirs:
        hint = (f" (it holds {len(loose)} trajectory files but no concept folders)"
                if loose else "")
        raise InvalidInputError(
            f"data set {root} has no concept folders{hint}: put each concept's trajectory "
            "files in a folder named after it (shapes/circle/*.csv, shapes/square/*.csv), "
            "or give a manifest (.csv or .json: file, concept[, writer, session]).")
    if loose:
        problems.append(f"{root}: trajectory files outside any concept folder "
                        f"({_listed(loose)})")
    samples: list[Sample] = []
    left_out: list[str] = []     # trajectory files under a name starting with "_"
    other: list[str] = []        # files of formats the data set is not read from
    mixed: list[str] = []        # concept folders with files both in and under them
    for d in [e for e in entries if e.is_dir() and not _hidden(e.relative_to(root))]:
        if d not in concept_dirs:  # "_old/": its trajectory files are noted below
            left_out += [f.relative_to(root).as_posix() for f in sorted(d.rglob("*"))
                         if f.is_file() and f.suffix.lower() in TRAJECTORY_SUFFIXES
                         and not _hidden(f.relative_to(root))]
            continue
        files, seen = [], []
        for f in sorted(d.rglob("*")):
            rel = f.relative_to(root)
            if _hidden(rel):
                continue
            if f.is_symlink() and not f.exists():
                problems.append(f"{f}: a link to {os.readlink(f)}, which does not exist; "
                                "restore the file or remove the link")
                continue
            if not f.is_file():
                continue
            seen.append(f.name)
            if any(part.startswith("_") for part in rel.parts):
                if f.suffix.lower() in TRAJECTORY_SUFFIXES:
                    left_out.append(rel.as_posix())
            elif f.suffix.lower() in TRAJECTORY_SUFFIXES:
                files.append(f)
            else:
                other.append(rel.as_posix())
        if not files:
            what = (f"holds no trajectory files ({', '.join(TRAJECTORY_SUFFIXES)}); it holds "
                    f"{_listed(seen)}" if seen else "is empty")
            problems.append(f"{d}: concept folder {what}")
            continue
        for f in files:
            rel = f.relative_to(d)
            writer = _text(rel.parts[0]) if len(rel.parts) > 1 else None
            samples.append(Sample(f.relative_to(root).as_posix(), _text(d.name), writer))
        inside = {len(f.relative_to(d).parts) > 1 for f in files}
        if len(inside) > 1:
            mixed.append(d.name)
    if samples and left_out:
        warnings.warn(
            f"data set {root}: {len(left_out)} trajectory file(s) left out because a name "
            f"on their path starts with '_' ({_listed(left_out)}); iloci leaves such "
            "files and folders out of a data set. Rename them to include them.",
            DataSetWarning, stacklevel=3)
    if mixed:
        warnings.warn(
            f"data set {root}: concept folder(s) {_listed(mixed)} hold trajectory files both "
            "directly and in sub-folders; a sub-folder is read as the writer of its files "
            "(circle/alice/1.csv: writer alice), so the files directly in the concept folder "
            "have no writer (and --split writers refuses them). Move them into a writer's "
            "folder, or move the sub-folder's files up if it is not a writer.",
            DataSetWarning, stacklevel=3)
    if samples and other:
        kinds = Counter(Path(o).suffix.lower() or "no suffix" for o in other)
        warnings.warn(
            f"data set {root}: {len(other)} file(s) left out that are not trajectory files "
            f"a data set is read from ({', '.join(f'{k}: {n}' for k, n in kinds.items())}; "
            f"e.g. {_listed(other)}). A data set reads {TRAJECTORY_FORMATS}; convert "
            "drawings of other formats, or ignore this if those files are not drawings.",
            DataSetWarning, stacklevel=3)
    return samples, problems


#: A gesture log's ``Name`` attribute in the first bytes of its file ($1, $N, $P logs).
_GESTURE_NAME = re.compile(rb"<Gesture\b[^>]*?\bName\s*=\s*[\"']([^\"']*)[\"']")


def _gesture_label(path: Path) -> str | None:
    """The gesture a $1/$N/$P log names itself (``Name="arrow01"`` -> ``"arrow"``), or None.

    Read from the file's first 4 KiB only (no parse: an unreadable file is
    reported when it is read); the number the logs append is dropped.
    """
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError:
        return None
    m = _GESTURE_NAME.search(head)
    if m is None:
        return None
    label = re.sub(r"[\W_]*\d+$", "", m.group(1).decode("utf-8", "replace")).strip()
    return label.casefold() or None


def _check_gesture_names(root: Path, samples: Sequence[Sample]) -> None:
    """Refuse a folder data set whose gesture logs name other gestures than their folders.

    The $1 recognizer's logs are filed as ``writer/speed/gestureNN.xml``; read
    as a data set of folders, each writer would be a concept and every
    gesture of a writer one concept's drawings: a run would learn and score
    nonsense without an error. Such a tree shows itself by the logs' own
    ``Name`` attributes: folders holding several gestures each, and the same
    gesture in several folders (a folder that groups gestures on purpose,
    ``pointy/`` for ``arrow`` and ``caret``, shares none with another).

    Raises
    ------
    InvalidInputError
        Naming a folder, the gestures in it and a gesture found in several
        folders; pointing to a manifest (docs/guide.md, "Your own shapes").
    """
    named: dict[str, set[str]] = {}
    for s in samples:
        if s.path.lower().endswith(".xml"):
            label = _gesture_label(root / s.path)
            # a log named after its writer's folder (s01/..., Name="s01_3") names no gesture
            if label is not None and label != (s.writer or "").casefold():
                named.setdefault(s.concept, set()).add(label)
    mixed = sorted(c for c, labels in named.items() if len(labels) > 1)
    folders: dict[str, list[str]] = {}
    for c, labels in named.items():
        for label in labels:
            folders.setdefault(label, []).append(c)
    shared = sorted((g for g, cs in folders.items() if len(cs) > 1),
                    key=lambda g: (-len(folders[g]), g))
    if len(mixed) < 2 or not shared:
        return
    c, g = mixed[0], shared[0]
    held = sorted(named[c])
    raise InvalidInputError(
        f"data set {root}: its gesture logs name other gestures than the folders they are "
        f"in: folder {c!r} holds {len(held)} gestures ({', '.join(held[:6])}"
        f"{', ...' if len(held) > 6 else ''}; {len(mixed)} folders hold several), and "
        f"{g!r} is in {len(folders[g])} folders ({', '.join(sorted(folders[g])[:4])}"
        f"{', ...' if len(folders[g]) > 4 else ''}). A data set of folders takes each folder "
        f"under {root} as a concept (and a folder inside it as the writer), so this would "
        "teach the writers' folders as concepts; nothing was learned. For logs filed by "
        "writer (the $1 logs' s01/fast/arrow01.xml), write a manifest with each file's "
        "concept and writer: docs/guide.md, \"Your own shapes\", has the few lines of "
        "Python that do it. (If the folders are the concepts and the logs' names are not "
        "gesture names, a manifest is read as it says too.)")


def manifests_in(folder: Path) -> list[Path]:
    """``manifest.csv`` / ``manifest.json`` in ``folder``, their names in any case."""
    return sorted(f for f in folder.iterdir() if f.name.lower() in _MANIFESTS and f.is_file())


def _text(name: str) -> str:
    """A folder name as a concept or writer name: bytes that are not UTF-8 (held by Python
    as lone surrogates, which cannot be printed, drawn or saved) written ``\\xNN``, as
    :func:`iloci.data.files.shape_name` writes them in a file's name."""
    return os.fsencode(name).decode("utf-8", "backslashreplace")


def _pick(header: Sequence[str], names: Sequence[str]) -> str | None:
    low = {h.strip().lower(): h for h in header}
    for n in names:
        if n in low:
            return low[n]
    return None


def _read_manifest(path: Path) -> tuple[list[Sample], list[str]]:
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise InvalidInputError(f"cannot read manifest {path}: {exc.strerror or exc}.") from None
    try:  # UTF-8 with or without a byte-order mark, UTF-16/32 (Excel's "Unicode text"), Latin-1
        text = decode_text(raw, str(path))[0].lstrip("\ufeff")
    except InvalidInputError as exc:
        raise InvalidInputError(f"manifest {exc}") from None
    rows: list[dict[str, Any]]
    if path.suffix.lower() == ".json":
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InvalidInputError(f"manifest {path} is not valid JSON: {exc.msg} at line "
                                    f"{exc.lineno}, column {exc.colno}.") from None
        except RecursionError:
            raise InvalidInputError(
                f"manifest {path}: its JSON is nested too deeply to read (a manifest is a "
                'list of objects [{"file": "a.csv", "concept": "circle"}, ...], two '
                "levels).") from None
        if isinstance(data, dict) and isinstance(data.get("samples"), list):
            data = data["samples"]
        if not isinstance(data, list) or not all(isinstance(r, dict) for r in data):
            raise InvalidInputError(
                f"manifest {path}: expected a list of objects "
                '[{"file": "a.csv", "concept": "circle", "writer": "w1"}, ...] '
                '(or {"samples": [...]}).')
        rows = data
        header = sorted({k for r in rows for k in r})
        where = [f"entry {i}" for i in range(len(rows))]
    else:
        try:
            dialect = csv.Sniffer().sniff(text[:4096], delimiters=",;\t|")
        except csv.Error:
            dialect = csv.excel
        reader = csv.DictReader(io.StringIO(text, newline=""), dialect=dialect)
        try:
            header = list(reader.fieldnames or [])
            rows = [dict(r) for r in reader]
        except csv.Error as exc:
            raise InvalidInputError(f"manifest {path}, line {reader.line_num}: {exc}. Save it "
                                    "as comma-separated text, one sample a line.") from None
        where = [f"line {i + 2}" for i in range(len(rows))]
    fcol, ccol = _pick(header, _FILE_COLS), _pick(header, _CONCEPT_COLS)
    if not rows and not header:  # [] or an empty file: nothing to name columns by
        raise InvalidInputError(f"manifest {path} lists no samples: give one row (or JSON "
                                "object) per file, with its file and concept.")
    if fcol is None or ccol is None:
        raise InvalidInputError(
            f"manifest {path} needs a 'file' and a 'concept' column (optional: writer, "
            f"session); its columns are {', '.join(map(str, header)) or 'none'}.")
    wcol, scol = _pick(header, _WRITER_COLS), _pick(header, _SESSION_COLS)
    samples, problems = [], []
    for w, r in zip(where, rows):
        f, c = r.get(fcol), r.get(ccol)
        wrong = [(col, v) for col, v, types in ((fcol, f, (str,)), (ccol, c, (str, int)))
                 if v is not None and (isinstance(v, bool) or not isinstance(v, types))]
        if wrong:
            col, v = wrong[0]
            problems.append(f"{path}, {w}: {col} is {json.dumps(v)[:60]}, not "
                            f"{'a path (a string)' if col == fcol else 'a name'}")
            continue
        if f is None or str(f).strip() == "" or c is None or str(c).strip() == "":
            problems.append(f"{path}, {w}: empty {'file' if not f else 'concept'}")
            continue

        def opt(col: str | None, row: dict[str, Any] = r) -> str | None:
            v = row.get(col) if col else None
            return None if v is None or str(v).strip() == "" else str(v).strip()

        # a manifest written on Windows names files with backslashes
        samples.append(Sample(Path(str(f).strip().replace("\\", "/")).as_posix(),
                              str(c).strip(), opt(wcol), opt(scol)))
    if not samples and not problems:
        problems.append(f"{path}: the manifest lists no samples")
    return samples, problems


def _note_unlisted(root: Path, manifest: Path, samples: Sequence[Sample]) -> None:
    """Warn (:class:`DataSetWarning`) of trajectory files in folders beside ``manifest``
    that it does not list: a folder holding a manifest is read as the manifest says, not
    by its folders."""
    listed = {os.path.normpath(root / s.path) for s in samples}
    listed.add(os.path.normpath(manifest))
    # files in folders only: a .csv beside the manifest is as often another table
    unlisted = sorted(
        f.relative_to(root).as_posix() for f in root.rglob("*")
        if f.suffix.lower() in TRAJECTORY_SUFFIXES and len(f.relative_to(root).parts) > 1
        and not _hidden(f.relative_to(root)) and f.is_file()
        and os.path.normpath(f) not in listed)
    if unlisted:
        warnings.warn(
            f"data set {root}: {manifest.name} is read, and it does not list "
            f"{len(unlisted)} trajectory file(s) beside it ({_listed(unlisted)}): they are "
            f"left out. List them in {manifest.name} to include them (or give the folder "
            "without the manifest to read it by its concept folders).",
            DataSetWarning, stacklevel=3)


def drawing_key(positions: np.ndarray) -> bytes:
    """What makes two drawings "the same": SHA-256 of the positions as little-endian float64.

    Used by :func:`load_dataset` (a data set holding one drawing twice is
    refused) and :func:`iloci.data.unipen.read_unipen` (copies dropped).

    Parameters
    ----------
    positions : ndarray, shape (N, 2)
    """
    return hashlib.sha256(np.ascontiguousarray(positions, dtype="<f8").tobytes()).digest()


def _naming(f: Path, message: str) -> str:
    """``message`` about file ``f`` led by its full path, once (a reader's message may
    already start with the file's name or path)."""
    for said in (f"{f}: ", f"{f.name}: "):
        if message.startswith(said):
            message = message[len(said):]
            break
    return f"{f}: {message}"


def _read_samples(samples: Sequence[Sample], root: Path, demos: list[Demonstration],
                  counter: Counter[str], timed: dict[bool, list[str]],
                  units: dict[str, list[str]], problems: list[str], h: Any,
                  report: Any) -> None:
    """Read every sample's file (the loop of :func:`load_dataset`), reporting progress.

    Also adds to ``problems`` the files that hold the same drawing as an earlier
    one (a copy would be taught in one fold and recognized in another), and
    gives one :class:`~iloci.errors.TimeUnitWarning` for all the files whose
    time stamps look like milliseconds, not one per file.
    """
    drawings: dict[bytes, Sample] = {}
    ms: list[tuple[Sample, str]] = []
    for i, s in enumerate(samples):
        report(i / max(len(samples), 1))
        f = root / s.path
        # every file takes its number, read or not: two broken files never share a key
        index = counter[s.concept]
        counter[s.concept] += 1
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", TimeUnitWarning)
                d = load_trajectory(f, shape=s.concept, true_concept=s.concept, index=index)
        except InvalidInputError as exc:
            problems.append(_naming(f, str(exc)))
            continue
        for w in caught:
            if issubclass(w.category, TimeUnitWarning):
                ms.append((s, str(w.message)))
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        first = drawings.setdefault(drawing_key(d.positions), s)
        if first is not s:
            same = ("" if first.concept == s.concept
                    else f" (labelled {first.concept!r} there, {s.concept!r} here)")
            problems.append(f"{f}: the same drawing as {root / first.path}{same}; a copy would "
                            "be taught in one fold and recognized in another: remove one")
            continue
        demos.append(d)
        timed[_has_times(d)].append(s.path)
        unit = position_unit(f)
        if unit:
            units.setdefault(unit, []).append(s.path)
        h.update(f"{s.path}\0{s.concept}\0{s.writer or ''}\0{s.session or ''}\0".encode(
            "utf-8", "surrogatepass"))
        h.update(hashlib.sha256(f.read_bytes()).digest())
    if ms:
        span = re.search(r"span [^;]*", ms[0][1])
        warnings.warn(
            f"{len(ms)} of {len(samples)} files have time stamps that look like milliseconds, "
            f"not seconds, e.g. {root / ms[0][0].path} ({span.group() if span else ms[0][1]}). "
            "Name the column "
            "t_ms (CSV), give the T channel units=\"ms\" (InkML), or divide the times by "
            "1000; only the robot's drawing speed reads them, "
            "so the evaluation goes on.", TimeUnitWarning, stacklevel=3)


def load_dataset(path: str | os.PathLike[str]) -> DataSet:
    """Read and check a data set (module docstring: the layouts).

    Parameters
    ----------
    path : path
        A folder of concept folders, a manifest (``.csv``/``.json``), or a
        folder holding ``manifest.csv`` / ``manifest.json``.

    Returns
    -------
    DataSet
        Samples sorted by concept then path (manifest: in its order).

    Raises
    ------
    InvalidInputError
        One error listing every problem found, with paths: a missing path,
        no concept folders, an empty concept folder, a manifest without
        ``file``/``concept`` columns or naming missing files, an unreadable
        or invalid trajectory file, mixed units (some files with time
        stamps and some without, or CSV headers naming different position
        units), fewer than 2 concepts.
    """
    p = Path(path).expanduser()
    if not p.exists():
        raise InvalidInputError(f"data set {str(p)!r} does not exist: give a folder with a "
                                "sub-folder of trajectory files per concept, or a manifest "
                                "(.csv or .json: file, concept[, writer, session]).")
    manifest = None
    if p.is_file():
        if p.suffix.lower() not in (".csv", ".json"):
            raise InvalidInputError(f"data set {p} is a file but not a .csv or .json "
                                    "manifest.")
        manifest = p
    else:
        found = manifests_in(p)
        if len(found) > 1:
            raise InvalidInputError(
                f"data set {p} holds both {' and '.join(f.name for f in found)}: give the one "
                f"to read (--data {found[0]}) or remove the other.")
        manifest = found[0] if found else None
    if manifest is not None:
        root = manifest.parent
        samples, problems = _read_manifest(manifest)
        # a manifest called manifest.csv names its folder's data set, not "manifest"
        layout, name = "manifest", (p.resolve().name if p.is_dir()
                                    else manifest.parent.resolve().name
                                    if manifest.name.lower() in _MANIFESTS else manifest.stem)
        for s in samples:
            if (root / s.path).is_dir():
                problems.append(f"{root / s.path}: listed in {manifest.name} but it is a "
                                "folder; list its trajectory files, one a row")
            elif not (root / s.path).is_file():
                problems.append(f"{root / s.path}: listed in {manifest.name} but not found")
            elif Path(s.path).suffix.lower() not in TRAJECTORY_SUFFIXES:
                problems.append(f"{root / s.path}: not a trajectory file ({TRAJECTORY_FORMATS})")
        if p.is_dir() and not problems:
            _note_unlisted(root, manifest, samples)
    else:
        root = p
        samples, problems = _scan_folders(p)
        layout, name = "folders", p.resolve().name
        _check_gesture_names(root, samples)
    dup = [k for k, n in Counter(s.path for s in samples).items() if n > 1]
    problems += [f"{root / k}: listed more than once" for k in dup[:_MAX_LISTED]]
    if problems:
        raise _fail(f"data set {p} has problems; nothing was learned:", problems,
                    "Fix them (or leave the files out) and run again.")

    demos: list[Demonstration] = []
    counter: Counter[str] = Counter()
    timed: dict[bool, list[str]] = {True: [], False: []}
    units: dict[str, list[str]] = {}
    h = hashlib.sha256()
    with long_step(f"reading data set {p} ({len(samples):,} files)") as report:
        _read_samples(samples, root, demos, counter, timed, units, problems, h, report)
    if problems:
        raise _fail(f"data set {p}: {len(problems)} file(s) cannot be used; nothing was "
                    "learned:", problems,
                    "Fix or remove them and run again. Each file must be what `iloci teach` "
                    f"reads, one drawing: {TRAJECTORY_FORMATS}.")
    if timed[True] and timed[False]:
        raise _fail(f"data set {p} mixes units of time: {len(timed[True])} file(s) have time "
                    f"stamps and {len(timed[False])} have none, e.g.:",
                    [f"with times: {root / timed[True][0]}",
                     f"without: {root / timed[False][0]}"],
                    "Give every file time stamps (a CSV time column, InkML's T channel, a "
                    "gesture log's T attribute), or none.")
    if len(units) > 1:
        raise _fail(f"data set {p} mixes position units:",
                    [f"{u}: {len(fs)} file(s), e.g. {root / fs[0]}" for u, fs in units.items()],
                    "Convert the files to one unit.")
    alike: dict[str, list[str]] = {}
    for c in counter:
        alike.setdefault(" ".join(c.split()).casefold(), []).append(c)
    for names in alike.values():
        if len(names) > 1:
            warnings.warn(f"data set {p}: the concepts {', '.join(map(repr, sorted(names)))} "
                          "differ only in case or spaces; they are scored as different "
                          "concepts. If they are one, name them alike.", DataSetWarning,
                          stacklevel=2)
    people: dict[str, set[str]] = {}
    for s in samples:
        if s.writer is not None:
            people.setdefault(" ".join(s.writer.split()).casefold(), set()).add(s.writer)
    for spelt in people.values():
        if len(spelt) > 1:
            warnings.warn(f"data set {p}: the writers {', '.join(map(repr, sorted(spelt)))} "
                          "differ only in case or spaces; they are counted as different "
                          "writers, and --split writers could teach one and recognize the "
                          "other. If they are one person, name them alike.", DataSetWarning,
                          stacklevel=2)
    if len(counter) < 2:
        hint = ""
        if layout == "folders" and len(counter) == 1:
            inner = root / next(iter(counter))
            if any(d.is_dir() for d in inner.iterdir()):
                hint = (f" If {inner} holds the concept folders, give that path "
                        f"(--data {inner}).")
        raise InvalidInputError(f"data set {p} has {len(counter)} concept(s) "
                                f"({', '.join(counter) or 'none'}); recognition needs at "
                                f"least 2.{hint}")
    return DataSet(name=name, root=str(root.resolve()), source=str(p.resolve()), layout=layout,
                   samples=samples, demos=demos, checksum=h.hexdigest())


#: Data sets read in this process: resolved path -> (fingerprint, DataSet).
_READ: dict[str, tuple[tuple, DataSet]] = {}


def _fingerprint(p: Path) -> tuple:
    """Name, size and modification time of every file a data set at ``p`` reads.

    Cheap (one ``stat`` per file, nothing read but a manifest): a changed,
    added or removed trajectory file or manifest changes it.
    """
    def stat(f: str) -> tuple[str, int, int]:
        try:
            st = os.stat(f)
        except OSError:
            return (f, -1, -1)
        return (f, st.st_size, st.st_mtime_ns)

    found = manifests_in(p) if p.is_dir() else [p]
    if found:  # the manifest and the files it lists (which may lie anywhere)
        files = [str(m) for m in found]
        try:
            files += [str(found[0].parent / s.path) for s in _read_manifest(found[0])[0]]
        except InvalidInputError:
            pass
        return (str(p.resolve()), tuple(stat(f) for f in files))
    out = [stat(os.path.join(dirpath, name)) for dirpath, _dirs, names in os.walk(p)
           for name in names if name.lower().endswith(TRAJECTORY_SUFFIXES)]
    return (str(p.resolve()), tuple(sorted(out)))


def load_dataset_once(path: str | os.PathLike[str], *, warn: bool = False) -> DataSet:
    """:func:`load_dataset`, read again only when a file of the data set changed.

    ``iloci evaluate`` needs the data set in its own process (to check it,
    then to plan the folds) and in every task of its workers (a fold's
    learning, its baselines, its recognition); this reads it once per
    process. The data set read last is kept, with the size and modification
    time of each of its files (see :func:`_fingerprint`).

    Parameters
    ----------
    path : path
        As for :func:`load_dataset`.
    warn : bool
        Give the data set's :class:`~iloci.errors.TimeUnitWarning` and
        :class:`~iloci.errors.DataSetWarning` when it is read (workers do
        not: the evaluation's own process gave them).
    """
    p = Path(path).expanduser()
    key = str(p.resolve())
    fp = _fingerprint(p)
    hit = _READ.get(key)
    if hit is not None and hit[0] == fp:
        return hit[1]
    with warnings.catch_warnings():
        if not warn:
            warnings.simplefilter("ignore", TimeUnitWarning)
            warnings.simplefilter("ignore", DataSetWarning)
        dataset = load_dataset(p)
    _READ.clear()  # one data set kept: a worker serves one evaluation at a time
    _READ[key] = (fp, dataset)
    return dataset


def demos_checksum(demos: Sequence[Demonstration]) -> str:
    """SHA-256 over the demonstrations' keys, true concepts, times and positions."""
    h = hashlib.sha256()
    for d in demos:
        h.update(f"{d.key}\0{d.true_concept or ''}\0".encode("utf-8", "surrogatepass"))
        h.update(np.ascontiguousarray(d.times, dtype="<f8").tobytes())
        h.update(np.ascontiguousarray(d.positions, dtype="<f8").tobytes())
    return h.hexdigest()


def _has_times(demo: Demonstration) -> bool:
    """Whether the file gave time stamps (without, the loader numbers the samples 0, 1, ...)."""
    t = demo.times
    return t is not None and not np.array_equal(t, np.arange(len(t), dtype=np.float64))


def writer_folds(samples: Sequence[Sample], folds: int, seed: int
                 ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Writer-disjoint folds: fold ``k`` learns from writer group ``k``, tests on the others.

    The writers are shuffled (seeded) and dealt into ``folds`` groups, so
    each fold is taught by about ``1/folds`` of the writers (the paper's
    taught share) and recognizes drawings of writers it never saw.

    Parameters
    ----------
    samples : sequence of Sample
        Each with a writer.
    folds : int
        ``>= 2`` and at most the number of writers.
    seed : int

    Returns
    -------
    list of (learn_idx, test_idx)
        Sorted int arrays of indices into ``samples``.

    Raises
    ------
    InvalidInputError
        A sample without writer, fewer writers than folds, or a writer group
        that lacks a concept (that fold could not learn it; the error names
        the concept and the group's writers).
    """
    missing = [s.path for s in samples if s.writer is None]
    if missing:
        raise _fail(f"--split writers needs a writer for every sample; {len(missing)} have "
                    "none, e.g.:", missing[:3],
                    "Put each writer's files in a sub-folder of its concept folder "
                    "(circle/alice/1.csv) or give a manifest with a writer column.")
    writers = sorted({str(s.writer) for s in samples})
    if len(writers) < 2:
        raise InvalidInputError(
            f"--split writers teaches some writers and recognizes the others, so it needs "
            f"at least 2 writers; the data set has {len(writers)} ({', '.join(writers)}). "
            "Split per concept instead (--split concepts, the default).")
    if len(writers) < folds:
        raise InvalidInputError(f"--split writers with {folds} folds needs at least {folds} "
                                f"writers; the data set has {len(writers)}. Set [evaluation] folds "
                                f"to at most {len(writers)}.")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 3]))
    order = [writers[i] for i in rng.permutation(len(writers))]
    group = {w: i % folds for i, w in enumerate(order)}
    of = np.array([group[str(s.writer)] for s in samples])
    concepts = sorted({s.concept for s in samples})
    problems = []
    for k in range(folds):
        have = {s.concept for s, g in zip(samples, of) if g == k}
        lack = [c for c in concepts if c not in have]
        if lack:
            ws = sorted(w for w, g in group.items() if g == k)
            problems.append(f"fold {k} (writers {', '.join(ws)}) has no sample of "
                            f"{', '.join(lack)}")
    if problems:
        drew: dict[str, set[str]] = {}
        for s in samples:
            drew.setdefault(str(s.writer), set()).add(s.concept)
        partial = []
        for w in writers:
            lacks = [c for c in concepts if c not in drew[w]]
            if lacks:
                partial.append(f"writer {w} drew {len(concepts) - len(lacks)} of the "
                               f"{len(concepts)} concepts, not {', '.join(lacks[:8])}"
                               + (", ..." if len(lacks) > 8 else ""))
        raise _fail("--split writers: some writer groups do not draw every concept, so "
                    "their fold could not learn it:", problems + partial,
                    "Leave out the writers who did not draw every concept (or give them "
                    "the missing drawings), use fewer folds, or split per concept "
                    "(--split concepts).")
    return [(np.flatnonzero(of == k), np.flatnonzero(of != k)) for k in range(folds)]


def check_protocol(dataset: DataSet, folds: int, split: str = "concepts", seed: int = 0
                   ) -> None:
    """Check that the paper's protocol can run on ``dataset`` before anything is learned.

    Raises
    ------
    InvalidInputError
        ``split="concepts"``: a concept with fewer samples than folds (all
        such concepts named with their counts); ``split="writers"``: see
        :func:`writer_folds`; an unknown split.
    """
    if split == "concepts":
        few = [f"{c}: {n} sample(s) in {Path(dataset.root) / c}"
               if dataset.layout == "folders" else f"{c}: {n} sample(s)"
               for c, n in dataset.concepts.items() if n < folds]
        if few:
            raise _fail(f"data set {dataset.source}: {len(few)} concept(s) have fewer "
                        f"samples than the {folds} folds (each fold learns from one part "
                        "of every concept):", few,
                        "Add samples, leave those concepts out, or use fewer folds "
                        "([evaluation] folds).")
    elif split == "writers":
        writer_folds(dataset.samples, folds, seed)
    else:
        raise InvalidInputError(f"unknown split {split!r}: use 'concepts' (k folds per "
                                "concept) or 'writers' (teach some writers, recognize the "
                                "others).")
