"""One entry of the paper's *Mem*: a consolidated exemplar or prototype.

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
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
import hashlib
from typing import Any

import numpy as np

__all__ = ["Entry", "demonstration_digest", "entries_equal"]


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

    @classmethod
    def learned_from(cls, sequence: np.ndarray, start: np.ndarray, dt: float, pb: np.ndarray,
                     concept: str, key: str, keep_pattern: bool) -> Entry:
        """A new exemplar of ``concept`` from one demonstration, before its rehearsal.

        ``sequence`` (T - 1, D) is the encoded demonstration, ``start`` its
        absolute first sample, ``pb`` its PB_obs (the rehearsal's start for
        the entry's PB; PB_rec and the generation error follow from it);
        ``keep_pattern``: keep ``sequence`` for later rehearsals.
        """
        return cls(pb=pb.copy(), pb_rec=pb.copy(), num_samples=1, num_steps=len(sequence),
                   initial_input=sequence[0].copy(), start=start.copy(), dt=dt,
                   concept=concept, generation_error=float("nan"), source=key,
                   sources=(key,), pattern=sequence.copy() if keep_pattern else None)

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


def demonstration_digest(demo: Any) -> str:
    """What makes two demonstrations "the same" for idempotent teaching (hex, 32 digits).

    SHA-256 of the demonstration's key (``"SHAPE/INDEX"``) and its pen
    positions rounded to float32 (about 7 significant digits), first 128
    bits. The same key with the same positions is the same demonstration
    when it comes again:

    - carried in float32 on the way (ROS's ``geometry_msgs/Point32``) or
      with float noise far below float32's precision (noise can still move
      a value across a float32 rounding step, rarely: then it is another
      demonstration);
    - with other time stamps: a replay is stamped anew (a ROS header, a
      logger's clock), and the default path reading (``resample =
      "arc_length"``) does not read them.

    Nothing else counts: not the true concept, not where the samples came
    from. The same key with any position changed beyond float32 precision
    is another demonstration; the same positions under another key are too.
    (Memories saved before this definition hold :func:`_digest_v1` digests:
    :meth:`Memory.learned_concept <iloci.concepts.memory.Memory.learned_concept>`
    knows both.)
    """
    h = hashlib.sha256(b"iloci-demonstration-v2\0" + demo.key.encode("utf-8", "surrogatepass")
                        + b"\0")
    h.update(np.ascontiguousarray(demo.positions, dtype=np.float64)
             .astype(np.float32).tobytes())
    return h.hexdigest()[:32]


def _digest_v1(demo: Any) -> str:
    """The digest of iloci before float32 positions: key, positions and times bit for bit."""
    h = hashlib.sha256(b"iloci-demonstration-v1\0" + demo.key.encode("utf-8", "surrogatepass")
                        + b"\0")
    h.update(np.ascontiguousarray(demo.positions, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(demo.times, dtype=np.float64).tobytes())
    return h.hexdigest()[:32]


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
