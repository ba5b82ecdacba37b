"""The paper's *Mem*: consolidated exemplars and prototypes, and their persistence.

Mem holds, per consolidated entry (the paper's Table I), its PB (learned by
training), PB_rec (recognized from the entry's own pattern), numSamples,
numSteps, initialInfo, conceptLabel and generationError. The network itself
(the paper's TrajectoryNet) is the agent's perceptual model; its weights are
saved beside the memory.

Exemplars and prototypes
------------------------
An *exemplar* is an entry learned from one demonstration; strengthening it
(a rewarded, highly similar demonstration) raises its numSamples but it
stays an exemplar, since its PB still encodes that one pattern. A
*prototype* is the medoid that replaced a valid cluster (numSamples summed);
:attr:`Entry.prototype` says which, and it is the only definition iloci
uses: :attr:`Memory.n_exemplars` and :attr:`Memory.n_prototypes` count by it,
and every output (``iloci teach``, ``iloci show MEMORY.npz``, ``metrics.json``)
reads those. The paper's nPrototypes counts every entry; iloci calls that
:attr:`Memory.n_entries` (docs/method.md, "Words").

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
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
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
from iloci.sensorimotor.encoding import SensorimotorEncoder

__all__ = ["Entry", "Memory", "FORMAT", "FORMAT_VERSION", "save_memory", "load_memory",
           "entries_equal"]

#: Name written in every memory file's header.
FORMAT = "iloci-memory"
#: Version of the file layout this iloci writes and the newest it reads.
FORMAT_VERSION = 1


@dataclass(eq=False)
class Entry:
    """One consolidated exemplar or prototype of Mem.

    Attributes
    ----------
    pb : ndarray, shape (P,)
        PB vector learned for the entry's pattern by the last rehearsal.
    pb_rec : ndarray, shape (P,)
        PB vector recognized from the entry's pattern with the weights
        frozen (what a new demonstration's PB_obs is compared with).
    num_samples : int
        Demonstrations this entry stands for (numSamples).
    num_steps : int
        Rows of the entry's encoded sequence (numSteps, ``T - 1``).
    initial_input : ndarray, shape (D,)
        First row of the encoded sequence: the network's initial input when
        the pattern is regenerated (initialInfo, part 1).
    start : ndarray, shape (D,)
        Absolute first sample ``[y, z, q1..qJ]`` (m, rad) that decoding a
        regenerated sequence starts from (initialInfo, part 2).
    dt : float
        Time step (s) of the motion when it is performed.
    concept : str
        The robot's concept label (conceptLabel), e.g. ``"c3"``.
    generation_error : float
        Mean squared closed-loop error of regenerating the pattern from
        ``pb`` and ``initial_input`` (generationError).
    source : str
        Key of the demonstration whose pattern the entry holds (a
        prototype's medoid).
    sources : tuple of str
        Keys of every demonstration the entry stands for.
    prototype : bool
        True for a medoid that replaced a cluster, False for an exemplar.
    pattern : ndarray, shape (num_steps, D), optional
        The encoded demonstration the entry was learned from, kept only with
        ``[learner] rehearse_from = "demonstrations"``: rehearsal then trains
        on it instead of regenerating it (see :mod:`iloci.concepts.rehearsal`).
        ``None`` (the paper): the robot keeps no demonstration.
    """

    pb: np.ndarray
    pb_rec: np.ndarray
    num_samples: int
    num_steps: int
    initial_input: np.ndarray
    start: np.ndarray
    dt: float
    concept: str
    generation_error: float
    source: str
    sources: tuple[str, ...] = ()
    prototype: bool = False
    pattern: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def exemplar(self) -> bool:
        """True for an entry learned from one demonstration (not a medoid)."""
        return not self.prototype

    def copy(self) -> Entry:
        return Entry(self.pb.copy(), self.pb_rec.copy(), self.num_samples, self.num_steps,
                     self.initial_input.copy(), self.start.copy(), self.dt, self.concept,
                     self.generation_error, self.source, tuple(self.sources), self.prototype,
                     None if self.pattern is None else self.pattern.copy())

    def __repr__(self) -> str:
        kind = "prototype" if self.prototype else "exemplar"
        return (f"Entry({kind} of {self.concept!r}, source={self.source!r}, "
                f"numSamples={self.num_samples}, generationError={self.generation_error:.3g})")


@dataclass(eq=False)
class Memory:
    """The robot's memory (Mem) of consolidated exemplars and prototypes.

    Attributes
    ----------
    entries : list of Entry
    encoder : SensorimotorEncoder or None
        The encoding scales, fitted on the first learning data.
    concept_count : int
        Concepts created so far; the next one is labelled
        ``f"c{concept_count + 1}"``.
    demonstrations_seen : int
        Demonstrations learned from so far (the index of the next one in the
        learning stream).
    revision : int
        Bumped by every change the learner or :meth:`rename` makes (not
        saved): a :class:`~iloci.concepts.learner.Turn` refuses feedback
        once the memory it was observed on has changed.
    """

    entries: list[Entry] = field(default_factory=list)
    encoder: SensorimotorEncoder | None = None
    concept_count: int = 0
    demonstrations_seen: int = 0
    revision: int = field(default=0, repr=False)

    # -- views ------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.entries)

    @property
    def n_entries(self) -> int:
        """Number of entries, exemplars and prototypes alike (the paper's nPrototypes)."""
        return len(self.entries)

    @property
    def n_exemplars(self) -> int:
        """Number of exemplars (entries that are not a cluster's medoid)."""
        return sum(not e.prototype for e in self.entries)

    @property
    def n_prototypes(self) -> int:
        """Number of prototypes (entries that replaced a valid cluster as its medoid)."""
        return sum(e.prototype for e in self.entries)

    @property
    def pbs(self) -> np.ndarray:
        """PB of every entry, shape (M, P)."""
        return _stack([e.pb for e in self.entries])

    @property
    def pbs_rec(self) -> np.ndarray:
        """PB_rec of every entry, shape (M, P)."""
        return _stack([e.pb_rec for e in self.entries])

    @property
    def concept_labels(self) -> list[str]:
        """conceptLabel of every entry, length M."""
        return [e.concept for e in self.entries]

    def concepts(self) -> list[str]:
        """Concept labels present in the memory, in order of first entry."""
        return list(dict.fromkeys(e.concept for e in self.entries))

    def indices_of(self, concept: str) -> list[int]:
        """Indices of the entries of ``concept``."""
        return [i for i, e in enumerate(self.entries) if e.concept == concept]

    def performer_of(self, concept: str) -> int:
        """Index of the entry that performs ``concept``: its lowest generation error.

        Raises
        ------
        InvalidInputError
            The memory holds no such concept.
        """
        idx = self.indices_of(concept)
        if not idx:
            raise InvalidInputError(f"the memory holds no concept {concept!r}; known: "
                                    f"{', '.join(self.concepts()) or '(none)'}.")
        return min(idx, key=lambda i: self.entries[i].generation_error)

    def num_samples_of(self, concept: str) -> int:
        """Total numSamples of the entries of ``concept``."""
        return sum(e.num_samples for e in self.entries if e.concept == concept)

    def new_concept_label(self) -> str:
        """Reserve and return the label of a new concept (``"c1"``, ``"c2"``, ...).

        A label a concept was renamed to is skipped.
        """
        used = set(self.concepts())
        self.concept_count += 1
        while f"c{self.concept_count}" in used:
            self.concept_count += 1
        return f"c{self.concept_count}"

    # -- transitions (the learning phase's changes, each with its invariant) -----
    def found_label(self) -> tuple[str, Callable[[], None]]:
        """The label of a concept about to be founded, and the undo of reserving it.

        :meth:`new_concept_label`, with a function that gives the label back
        (``concept_count`` as it was) when founding the concept fails.
        """
        before = self.concept_count
        label = self.new_concept_label()

        def undo() -> None:
            self.concept_count = before
        return label, undo

    def strengthen(self, index: int, source: str) -> None:
        """A rewarded demonstration within ``similarity_threshold`` of entry ``index``.

        The entry's numSamples rises by one and ``source`` (the
        demonstration's key) joins its sources; PBs, patterns and the
        network are untouched (no rehearsal). Bumps :attr:`revision`.
        """
        e = self.entries[index]
        e.num_samples += 1
        e.sources = tuple(e.sources) + (source,)
        self.revision += 1

    def install(self, entries: list[Entry]) -> None:
        """Replace every entry in one assignment (a rehearsal's result, once it succeeded).

        Other threads see the old entries or the new ones, never a mix; a
        rehearsal that fails installs nothing. Bumps :attr:`revision`.
        """
        self.entries = entries
        self.revision += 1

    def clustered(self, concept: str, clusterer: Any, *, k_cutoff: float,
                  num_threshold: int) -> tuple[list[Entry], int, float]:
        """The entries with ``concept``'s valid clusters replaced by their medoids.

        Works on copies (the memory is unchanged; :meth:`install` the
        entries once they are rehearsed). Each valid cluster
        (:func:`~iloci.concepts.clustering.plan_clusters`) keeps its medoid,
        now a prototype whose numSamples is the cluster's sum and whose
        sources are every member's; the other members are dropped.

        Returns
        -------
        entries : list of Entry
        clustered : int
            Valid clusters replaced.
        d_cutoff : float
            The cut the clusters were taken at (NaN below two entries).
        """
        from iloci.concepts import clustering
        entries = [e.copy() for e in self.entries]
        idx = [i for i, e in enumerate(entries) if e.concept == concept]
        own = [entries[i] for i in idx]
        plan = clustering.plan_clusters(
            np.array([e.pb for e in own]), [e.num_samples for e in own],
            [e.exemplar for e in own], clusterer=clusterer,
            k_cutoff=k_cutoff, num_threshold=num_threshold)
        if not plan.valid:
            return entries, 0, plan.d_cutoff
        drop: set[int] = set()
        for members, med in zip(plan.valid, plan.medoids):
            keep = own[med]
            others = [own[j] for j in members if j != med]
            keep.num_samples = sum(own[j].num_samples for j in members)
            keep.sources = tuple(dict.fromkeys(
                list(keep.sources) + [s for o in others for s in o.sources]))
            keep.prototype = True
            drop.update(idx[j] for j in members if j != med)
        return [e for i, e in enumerate(entries) if i not in drop], len(plan.valid), plan.d_cutoff

    def placed(self) -> None:
        """One demonstration more was learned from (strengthened, exemplar or concept)."""
        self.demonstrations_seen += 1

    def rename(self, concept: str, name: str) -> None:
        """Name a concept: every entry of ``concept`` is relabelled ``name``.

        The label is what the memory file stores, so the name is what every
        command, report and recognition shows from then on.

        Parameters
        ----------
        concept : str
            A concept of the memory (``"c3"``).
        name : str
            1 to :data:`MAX_NAME` printable characters, no ``/``, not used
            by another concept; surrounding white space is dropped.

        Raises
        ------
        InvalidInputError
            Unknown concept, or an unusable or taken name; nothing changed.
        """
        if concept not in self.concepts():
            raise InvalidInputError(f"the memory holds no concept {concept!r}; known: "
                                    f"{', '.join(self.concepts()) or '(none)'}.")
        if not isinstance(name, str):
            raise InvalidInputError(f"a concept name must be a string, got "
                                    f"{type(name).__name__}.")
        new = name.strip()
        if not new or len(new) > MAX_NAME or not new.isprintable() or "/" in new:
            raise InvalidInputError(f"a concept name needs 1 to {MAX_NAME} printable "
                                    f"characters without '/', got {name!r}.")
        if new != concept and new in self.concepts():
            raise InvalidInputError(f"another concept is already named {new!r}; choose "
                                    "another name.")
        for e in self.entries:
            if e.concept == concept:
                e.concept = new
        self.revision += 1

    def concept_members(self, concept_of_key: Any) -> dict[str, list[str | None]]:
        """The true concept of every demonstration each of the robot's concepts stands for.

        Parameters
        ----------
        concept_of_key : callable
            ``"SHAPE/INDEX" -> true concept or None`` (e.g. an oracle
            teacher's ``concept_of_key``).

        Returns
        -------
        dict
            Robot label -> one true concept (or ``None``) per source
            demonstration of its entries, in entry order.
        """
        return {label: [concept_of_key(key) for i in self.indices_of(label)
                        for key in self.entries[i].sources]
                for label in self.concepts()}

    def copy(self) -> Memory:
        enc = None
        if self.encoder is not None and self.encoder.scale_ is not None:
            enc = SensorimotorEncoder.from_state(self.encoder.state())
        elif self.encoder is not None:
            enc = SensorimotorEncoder(self.encoder.limit)
        return Memory([e.copy() for e in self.entries], enc, self.concept_count,
                      self.demonstrations_seen)

    def summary(self) -> str:
        """A header (entries, exemplars, prototypes, concepts) and one line per concept."""
        lines = [(f"{self.n_entries} entries ({self.n_exemplars} exemplars, "
                  f"{self.n_prototypes} prototypes), {len(self.concepts())} concepts, "
                  f"{self.demonstrations_seen} demonstrations seen")]
        for label in self.concepts():
            idx = self.indices_of(label)
            protos = sum(self.entries[i].prototype for i in idx)
            lines.append(f"  {label}: {len(idx)} entries ({protos} prototypes), "
                         f"numSamples {self.num_samples_of(label)}")
        return "\n".join(lines)

    # -- (de)serialisation -------------------------------------------------------
    def to_arrays(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Numeric arrays and JSON-able metadata describing the memory.

        Returns
        -------
        arrays : dict of str to ndarray
            ``mem/*`` per-entry arrays and ``enc/*`` encoder state.
        meta : dict
            Strings and counters (labels, sources, counts).
        """
        m = len(self.entries)
        p = self.entries[0].pb.shape[0] if m else 0
        d = self.entries[0].initial_input.shape[0] if m else 0
        arrays = {
            "mem/pb": _stack([e.pb for e in self.entries], p),
            "mem/pb_rec": _stack([e.pb_rec for e in self.entries], p),
            "mem/num_samples": np.array([e.num_samples for e in self.entries], np.int64),
            "mem/num_steps": np.array([e.num_steps for e in self.entries], np.int64),
            "mem/initial_input": _stack([e.initial_input for e in self.entries], d),
            "mem/start": _stack([e.start for e in self.entries],
                                self.encoder.width if self.encoder is not None
                                and self.encoder.width else 6),
            "mem/dt": np.array([e.dt for e in self.entries], np.float64),
            "mem/generation_error": np.array([e.generation_error for e in self.entries],
                                             np.float64),
            "mem/prototype": np.array([e.prototype for e in self.entries], np.bool_),
        }
        # [learner] rehearse_from = "demonstrations": each entry's kept pattern
        arrays.update({f"mem/pattern/{i}": np.asarray(e.pattern, dtype=np.float64)
                       for i, e in enumerate(self.entries) if e.pattern is not None})
        if self.encoder is not None and self.encoder.scale_ is not None:
            arrays.update({f"enc/{k}": np.asarray(v) for k, v in self.encoder.state().items()})
        meta = {
            "concepts": [e.concept for e in self.entries],
            "source": [e.source for e in self.entries],
            "sources": [list(e.sources) for e in self.entries],
            "concept_count": self.concept_count,
            "demonstrations_seen": self.demonstrations_seen,
        }
        return arrays, meta

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any]) -> Memory:
        """Inverse of :meth:`to_arrays`; :class:`MemoryFileError` if inconsistent."""
        try:
            m = len(meta["concepts"])
            cols = {k: np.asarray(arrays[f"mem/{k}"]) for k in (
                "pb", "pb_rec", "num_samples", "num_steps", "initial_input", "start", "dt",
                "generation_error", "prototype")}
            if any(len(v) != m for v in cols.values()) or len(meta["source"]) != m \
                    or len(meta["sources"]) != m:
                raise ValueError("per-entry arrays and labels differ in length")
            entries = [
                Entry(pb=cols["pb"][i].astype(np.float64), pb_rec=cols["pb_rec"][i].astype(
                          np.float64),
                      num_samples=int(cols["num_samples"][i]),
                      num_steps=int(cols["num_steps"][i]),
                      initial_input=cols["initial_input"][i].astype(np.float64),
                      start=cols["start"][i].astype(np.float64), dt=float(cols["dt"][i]),
                      concept=str(meta["concepts"][i]),
                      generation_error=float(cols["generation_error"][i]),
                      source=str(meta["source"][i]),
                      sources=tuple(str(s) for s in meta["sources"][i]),
                      prototype=bool(cols["prototype"][i]),
                      pattern=_pattern(arrays, i, int(cols["num_steps"][i]),
                                       cols["initial_input"].shape[-1]))
                for i in range(m)]
            enc_state = {k[4:]: v for k, v in arrays.items() if k.startswith("enc/")}
            encoder = SensorimotorEncoder.from_state(enc_state) if enc_state else None
            return cls(entries, encoder, int(meta["concept_count"]),
                       int(meta["demonstrations_seen"]))
        except (KeyError, TypeError, ValueError, IndexError, InvalidInputError) as exc:
            raise MemoryFileError(f"memory file content is inconsistent ({exc}); it was not "
                                  "written by this version of iloci or was edited.") from None


#: Longest concept name :meth:`Memory.rename` accepts (characters).
MAX_NAME = 40


def _pattern(arrays: Mapping[str, np.ndarray], i: int, steps: int,
             width: int) -> np.ndarray | None:
    """Entry ``i``'s kept pattern (``None`` when it has none), checked against its size."""
    a = arrays.get(f"mem/pattern/{i}")
    if a is None:
        return None
    a = np.asarray(a, dtype=np.float64)
    if a.shape != (steps, width) or not np.all(np.isfinite(a)):
        raise ValueError(f"entry {i}'s pattern has shape {a.shape}, expected "
                         f"({steps}, {width}) finite values")
    return a


def _stack(rows: list[np.ndarray], width: int | None = None) -> np.ndarray:
    if rows:
        return np.array(rows, dtype=np.float64)
    return np.zeros((0, width or 0), dtype=np.float64)


# -- files -------------------------------------------------------------------------

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


def save_memory(path: str | os.PathLike[str], memory: Memory,
                network_state: Mapping[str, np.ndarray],
                extra: Mapping[str, Any] | None = None) -> Path:
    """Write a memory and the network's state to one ``.npz`` file, atomically.

    Parameters
    ----------
    path : path-like
        Target file; ``.npz`` is conventional but not required.
    memory : Memory
    network_state : mapping of str to ndarray
        The perceptual model's :meth:`state`.
    extra : mapping, optional
        JSON-able values stored in the header (e.g. the agent's config).

    Returns
    -------
    pathlib.Path
        The written file.
    """
    # a symlinked memory is written through to its target (the link stays)
    path = Path(os.path.realpath(os.fspath(path)))
    arrays, meta = memory.to_arrays()
    for k, v in network_state.items():
        a = np.asarray(v)
        if a.dtype == object:
            raise InvalidInputError(f"network state {k!r} is an object array; states must "
                                    "be numeric (no pickle).")
        arrays[f"net/{k}"] = a
    header: dict[str, Any] = {"format": FORMAT, "version": FORMAT_VERSION,
                              "iloci": __version__, "memory": meta, **dict(extra or {})}
    header["checksum"] = _checksum(header, arrays)
    arrays["__header__"] = np.frombuffer(json.dumps(header, sort_keys=True).encode(), np.uint8)
    return write_atomic(path, lambda fh: np.savez(fh, allow_pickle=False, **arrays), mkdir=True)


def load_memory(path: str | os.PathLike[str]) -> tuple[Memory, dict[str, np.ndarray],
                                                      dict[str, Any]]:
    """Read what :func:`save_memory` wrote.

    Returns
    -------
    memory : Memory
    network_state : dict of str to ndarray
    header : dict
        The JSON header (format, version, config, ...).

    Raises
    ------
    MemoryFileError
        Missing, truncated, tampered with (checksum mismatch), not an iloci
        memory, or written by a newer iloci.
    """
    path = Path(path)
    if not path.is_file():
        raise MemoryFileError(f"memory file not found: {path}. Teach the robot first "
                              "(`iloci teach --memory FILE`), or check the path.")
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
    try:
        if raw is None:
            raise ValueError("no header")
        header = json.loads(raw.tobytes().decode("utf-8"))
        if not isinstance(header, dict):
            raise ValueError("header is not an object")
    except (ValueError, UnicodeDecodeError) as exc:
        raise MemoryFileError(f"{path} is not an iloci memory file ({exc}).") from None
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
    memory = Memory.from_arrays(arrays, header.get("memory", {}))
    network_state = {k[4:]: v for k, v in arrays.items() if k.startswith("net/")}
    return memory, network_state, header


def entries_equal(a: Iterable[Entry], b: Iterable[Entry]) -> bool:
    """True when two entry lists hold the same values (arrays compared exactly)."""
    a, b = list(a), list(b)
    if len(a) != len(b):
        return False
    for x, y in zip(a, b):
        for name in ("pb", "pb_rec", "initial_input", "start"):
            if not np.array_equal(getattr(x, name), getattr(y, name)):
                return False
        for name in ("num_samples", "num_steps", "dt", "concept", "generation_error",
                     "source", "sources", "prototype"):
            if getattr(x, name) != getattr(y, name):
                return False
        px, py = x.pattern, y.pattern
        if (px is None) != (py is None) or (
                px is not None and py is not None and not np.array_equal(px, py)):
            return False
    return True
