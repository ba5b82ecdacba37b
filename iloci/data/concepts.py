"""Ground truth: the 22 relational concepts of LASA (docs/method.md, "The LASA concepts").

Four pairs of LASA shapes are the same concept drawn differently; every
other shape is its own concept.

This module is the one place a demonstration's true concept is looked up
(:class:`GroundTruth`) and a robot concept is named by the true concepts of
the demonstrations it stands for (:func:`majority_names`). The robot's
memory never sees true concepts: the evaluation, the oracle teacher and
``iloci draw`` ask here.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

__all__ = ["LASA_SHAPES", "MULTI_MODEL_SHAPES", "LASA_CONCEPTS", "GroundTruth", "concept_of",
           "concept_of_key", "majority_names"]

#: The 26 single-pattern LASA shapes (file names without ``.mat``).
LASA_SHAPES: tuple[str, ...] = (
    "Angle", "BendedLine", "CShape", "DoubleBendedLine", "GShape", "heee",
    "JShape", "JShape_2", "Khamesh", "Leaf_1", "Leaf_2", "Line", "LShape",
    "NShape", "PShape", "RShape", "Saeghe", "Sharpc", "Sine", "Snake", "Spoon",
    "Sshape", "Trapezoid", "Worm", "WShape", "Zshape",
)

#: Multi-pattern files, available on request, not part of the benchmark.
MULTI_MODEL_SHAPES: tuple[str, ...] = (
    "Multi_Models_1", "Multi_Models_2", "Multi_Models_3", "Multi_Models_4",
)

_MERGED = {
    "JShape_2": "JShape",
    "Leaf_1": "Leaf",
    "Leaf_2": "Leaf",
    "DoubleBendedLine": "BendedLine",
    "Sharpc": "CShape",
}

#: LASA shape -> concept (22 distinct concepts).
LASA_CONCEPTS: dict[str, str] = {s: _MERGED.get(s, s) for s in LASA_SHAPES}


def concept_of(shape: str) -> str | None:
    """The LASA concept of ``shape``, or ``None`` for a shape outside LASA."""
    return LASA_CONCEPTS.get(shape)


def concept_of_key(key: str) -> str | None:
    """The LASA concept of the demonstration ``"SHAPE/INDEX"``, or ``None`` outside LASA."""
    return concept_of(key.rsplit("/", 1)[0])


class GroundTruth:
    """A demonstration's true concept, the one lookup every evaluation uses.

    In order: the demonstration's own ``true_concept``; the one given for
    its key (``"SHAPE/INDEX"``) by a demonstration passed here; the LASA
    concept of its shape (:func:`concept_of`); the shape itself.

    Parameters
    ----------
    demos : iterable of Demonstration, optional
        Demonstrations whose ``true_concept`` names their key (e.g. a
        fold's learning and test sets).
    """

    def __init__(self, demos: Iterable[Any] = ()) -> None:
        self.known: dict[str, str] = {d.key: d.true_concept for d in demos if d.true_concept}

    def __call__(self, key: str) -> str:
        """The true concept of the demonstration with key ``key``."""
        if key in self.known:
            return self.known[key]
        shape = key.rsplit("/", 1)[0]
        c = concept_of(shape)
        return c if c is not None else shape

    def of(self, demo: Any) -> str:
        """The true concept of ``demo`` (a Demonstration)."""
        return str(demo.true_concept or self(demo.key))


def _counts(members: Mapping[str, Sequence[str | None]]) -> dict[str, dict[str, int]]:
    out: dict[str, dict[str, int]] = {}
    for robot, truths in members.items():
        c: dict[str, int] = {}
        for t in truths:
            if t is not None:
                c[t] = c.get(t, 0) + 1
        out[robot] = c
    return out


def majority_names(members: Mapping[str, Sequence[str | None]]) -> dict[str, str | None]:
    """Name each of the robot's concepts by the true concept of most of its demonstrations.

    Parameters
    ----------
    members : mapping of str to sequence of str
        Robot concept label -> the true concept of each demonstration its
        memory entries stand for (``None`` for an unknown one), e.g.
        ``memory.concept_members(GroundTruth())``.

    Returns
    -------
    dict
        Robot label -> most frequent true concept (ties: the first seen);
        ``None`` when none is known. Two robot concepts may get the same
        name (a concept the robot split in two).
    """
    return {robot: (max(c, key=c.__getitem__) if c else None)
            for robot, c in _counts(members).items()}
