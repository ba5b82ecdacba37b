"""The paper's *Mem*: consolidated exemplars and prototypes, and their persistence.

Mem holds, per consolidated entry (the paper's Table I), its PB (learned by
training), PB_rec (recognized from the entry's own pattern), numSamples,
numSteps, initialInfo, conceptLabel and generationError. The network itself
(the paper's TrajectoryNet) is the agent's perceptual model; its weights are
saved beside the memory.

Exemplars and prototypes: see :mod:`iloci.concepts.entry`.

The file format: :mod:`iloci.concepts.storage`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
import os
from pathlib import Path
from typing import Any

import numpy as np

from iloci._version import __version__, is_newer
from iloci.concepts.entry import (Entry, _digest_v1, _pattern, _stack, demonstration_digest,
                                  entries_equal)
from iloci.concepts.storage import FORMAT, FORMAT_VERSION, read_memory_file, write_memory_file
from iloci.errors import InvalidInputError, MemoryFileError
from iloci.sensorimotor.encoding import SensorimotorEncoder

__all__ = ["Entry", "Memory", "demonstration_digest", "FORMAT", "FORMAT_VERSION", "save_memory",
           "load_memory", "entries_equal"]



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
    labels : dict of str to str
        The data's label (``Demonstration.true_concept``) of each
        demonstration learned from that had one, by key: what a teacher that
        judges answers by the demonstrations they stand for (the oracle)
        needs in a later session (:func:`~iloci.concepts.learner.run_turn`
        gives it to the teacher). The robot never reads them. Saved with the
        memory; a file written before it was kept has none.
    learned : set of str
        :func:`demonstration_digest` of every demonstration learned from:
        one shown again (the same key and pen positions) is recognized
        and not learned twice (:meth:`learned_concept`). Saved with the
        memory; a file written before it was kept has none.
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
    learned: set[str] = field(default_factory=set, repr=False)
    labels: dict[str, str] = field(default_factory=dict, repr=False)

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
                  num_threshold: int,
                  stands_for: Callable[[int, int], bool] | None = None
                  ) -> tuple[list[Entry], int, float]:
        """The entries with ``concept``'s valid clusters replaced by their medoids.

        Works on copies (the memory is unchanged; :meth:`install` the
        entries once they are rehearsed). Each valid cluster
        (:func:`~iloci.concepts.clustering.plan_clusters`) keeps its medoid,
        now a prototype whose numSamples is the cluster's sum and whose
        sources are every member's; the other members are dropped.

        ``stands_for(member, medoid)`` (indices into :attr:`entries`), when
        given, picks the members the medoid replaces (``[learner] condense
        = "consistent"``); the others stay as they are, and a cluster whose
        medoid replaces none is not counted. ``None``: every member (the
        paper's rule).

        Returns
        -------
        entries : list of Entry
        clustered : int
            Valid clusters replaced.
        d_cutoff : float
            The cut the clusters were taken at (NaN below two entries).
        """
        # clustering imports scipy: loaded when a concept is first clustered, so
        # `import iloci` stays light
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
        replaced = 0
        for members, med in zip(plan.valid, plan.medoids):
            if stands_for is not None:
                members = tuple(j for j in members
                                if j == med or stands_for(idx[j], idx[med]))
                if len(members) < 2:
                    continue
            replaced += 1
            keep = own[med]
            others = [own[j] for j in members if j != med]
            keep.num_samples = sum(own[j].num_samples for j in members)
            keep.sources = tuple(dict.fromkeys(
                list(keep.sources) + [s for o in others for s in o.sources]))
            keep.prototype = True
            drop.update(idx[j] for j in members if j != med)
        return [e for i, e in enumerate(entries) if i not in drop], replaced, plan.d_cutoff

    def placed(self, digest: str | None = None, key: str | None = None,
               label: str | None = None) -> None:
        """One demonstration more was learned from (strengthened, exemplar or concept).

        ``digest``: its :func:`demonstration_digest`, kept in :attr:`learned`;
        ``key``, ``label``: its key and the data's label, kept in :attr:`labels`.
        """
        self.demonstrations_seen += 1
        if digest is not None:
            self.learned.add(digest)
        if key is not None and label is not None:
            self.labels[key] = label

    def learned_concept(self, demo: Any) -> str | None:
        """The concept ``demo`` was learned into, if this very demonstration was learned.

        "This very demonstration": the same key and the same pen positions
        to float32 precision (:func:`demonstration_digest`; time stamps do
        not count); one with the same key but other positions is another
        demonstration. ``None`` when it was not learned
        (or the entry that stood for it is gone).
        """
        if demonstration_digest(demo) not in self.learned \
                and _digest_v1(demo) not in self.learned:       # a memory saved before v2
            return None
        key = demo.key
        return next((e.concept for e in self.entries if key in e.sources), None)

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

    def checkpoint(self) -> tuple[Any, ...]:
        """What :meth:`rollback` puts back: copies of the entries, the counters and
        :attr:`learned`, and the revision (the encoder is not changed by learning)."""
        return ([e.copy() for e in self.entries], self.concept_count,
                self.demonstrations_seen, set(self.learned), dict(self.labels), self.revision)

    def rollback(self, point: tuple[Any, ...]) -> None:
        """Put the memory back as :meth:`checkpoint` found it (a learning step that failed
        half-way: a clusterer that raised after a rehearsal installed its new exemplar)."""
        (entries, self.concept_count, self.demonstrations_seen, learned, labels,
         self.revision) = point
        self.entries, self.learned, self.labels = entries, learned, labels

    def copy(self) -> Memory:
        enc = None
        if self.encoder is not None and self.encoder.scale_ is not None:
            enc = SensorimotorEncoder.from_state(self.encoder.state())
        elif self.encoder is not None:
            enc = SensorimotorEncoder(self.encoder.limit)
        return Memory([e.copy() for e in self.entries], enc, self.concept_count,
                      self.demonstrations_seen, learned=set(self.learned),
                      labels=dict(self.labels))

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
            "learned": sorted(self.learned),
            "labels": dict(sorted(self.labels.items())),
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
            learned = {str(d) for d in meta.get("learned", ())}
            labels = {str(k): str(v) for k, v in dict(meta.get("labels") or {}).items()}
            return cls(entries, encoder, int(meta["concept_count"]),
                       int(meta["demonstrations_seen"]), learned=learned, labels=labels)
        except (KeyError, TypeError, ValueError, IndexError, InvalidInputError) as exc:
            what = f"it lacks {exc}" if isinstance(exc, KeyError) else str(exc)
            raise MemoryFileError(f"memory file content is inconsistent ({what}); it was not "
                                  "written by this version of iloci or was edited.") from None


#: Longest concept name :meth:`Memory.rename` accepts (characters).
MAX_NAME = 40


# -- files -------------------------------------------------------------------------

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
        The written file (see :mod:`iloci.concepts.storage` for its format).
    """
    arrays, meta = memory.to_arrays()
    for k, v in network_state.items():
        a = np.asarray(v)
        if a.dtype == object:
            raise InvalidInputError(f"network state {k!r} is an object array; states must "
                                    "be numeric (no pickle).")
        arrays[f"net/{k}"] = a
    return write_memory_file(path, arrays, {"memory": meta, **dict(extra or {})})


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
    arrays, header = read_memory_file(path)
    try:
        memory = Memory.from_arrays(arrays, header.get("memory", {}))
    except MemoryFileError as exc:
        raise MemoryFileError(f"{path}: {exc} It says it was written by iloci "
                              f"{header.get('iloci', '(no version)')}; this is iloci "
                              f"{__version__}.") from None
    network_state = {k[4:]: v for k, v in arrays.items() if k.startswith("net/")}
    if is_newer(header.get("iloci")):
        import warnings
        warnings.warn(f"{path} was written by iloci {header.get('iloci')}, this is iloci "
                      f"{__version__}: what this version knows of it is loaded; anything "
                      "newer in it is not, and saving the memory from here drops that "
                      "(upgrade iloci to keep it).", UserWarning, stacklevel=2)
    return memory, network_state, header
