"""The 22 relational concepts of the LASA experiment (docs/method.md, "The LASA concepts").

Four pairs of LASA shapes are the same concept drawn differently; every
other shape is its own concept.
"""

from __future__ import annotations

__all__ = ["LASA_SHAPES", "MULTI_MODEL_SHAPES", "LASA_CONCEPTS", "concept_of", "concept_of_key"]

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
