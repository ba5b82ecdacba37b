"""A user's own pen trajectories from ``.npy`` or ``.csv`` files."""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np

from iloci.errors import InvalidDemonstrationError, InvalidInputError
from iloci.interfaces import Demonstration

__all__ = ["load_trajectory"]

_TIME_NAMES = ("t", "time", "times", "timestamp")


def load_trajectory(path: str | os.PathLike[str], *, shape: str | None = None,
                    concept: str | None = None, index: int = 0) -> Demonstration:
    """Read one pen trajectory from a file.

    Two layouts, in either format:

    * ``N x 2``: pen positions ``x, y`` (any unit); times default to
      ``0, 1, ..., N-1``.
    * ``N x 3``: ``t, x, y`` with the time stamps (s) in the first column.

    A ``.csv`` file is comma separated and may start with one header row;
    a header names the time column ``t`` or ``time`` (any position) and the
    other two columns are ``x, y`` in order. A ``.npy`` file holds a plain
    float array (loaded without pickle).

    Parameters
    ----------
    path : str or path-like
    shape : str, optional
        Name of the drawn shape; defaults to the file's stem.
    concept : str, optional
        The true concept, if known.
    index : int
        Demonstration index (the key is ``"SHAPE/INDEX"``).

    Returns
    -------
    Demonstration

    Raises
    ------
    InvalidInputError
        The file is missing, unreadable or not ``.npy`` / ``.csv``.
    InvalidDemonstrationError
        The array is not N x 2 or N x 3, has NaN or inf, fewer than 3
        points, zero extent, or non-increasing times.
    """
    p = Path(path)
    if not p.is_file():
        raise InvalidInputError(f"trajectory file {str(p)!r} does not exist.")
    suffix = p.suffix.lower()
    header: list[str] | None = None
    if suffix == ".npy":
        try:
            arr = np.load(p, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise InvalidInputError(f"cannot read {str(p)!r} as a numpy array: {exc}. "
                                    "Save it with numpy.save(path, array).") from None
    elif suffix == ".csv":
        arr, header = _read_csv(p)
    else:
        raise InvalidInputError(f"unsupported trajectory file {p.name!r}: use .npy or .csv "
                                "(N x 2 positions, or N x 3 with time first).")
    try:
        arr = np.asarray(arr, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidDemonstrationError(f"{p.name}: the array is not numeric.") from None
    name = shape if shape is not None else p.stem
    if arr.ndim != 2 or arr.shape[1] not in (2, 3):
        raise InvalidDemonstrationError(
            f"{p.name}: expected an N x 2 array of positions (x, y) or N x 3 (t, x, y), "
            f"got shape {arr.shape}.")
    times = None
    if arr.shape[1] == 3:
        tcol = 0
        if header is not None:
            lowered = [h.strip().lower() for h in header]
            hits = [i for i, h in enumerate(lowered) if h in _TIME_NAMES]
            tcol = hits[0] if hits else 0
        times = arr[:, tcol]
        arr = np.delete(arr, tcol, axis=1)
    return Demonstration(positions=arr, times=times, shape=name, index=index,
                         concept=concept)


def _read_csv(p: Path) -> tuple[np.ndarray, list[str] | None]:
    try:
        with p.open(newline="", encoding="utf-8") as fh:
            rows = [r for r in csv.reader(fh) if r and any(c.strip() for c in r)]
    except (OSError, UnicodeDecodeError) as exc:
        raise InvalidInputError(f"cannot read {str(p)!r}: {exc}.") from None
    header = None
    if rows and not _numeric(rows[0]):
        header, rows = rows[0], rows[1:]
    widths = {len(r) for r in rows}
    if len(widths) > 1:
        raise InvalidDemonstrationError(f"{p.name}: rows have different numbers of columns "
                                        f"{sorted(widths)}.")
    try:
        data = np.array([[float(c) for c in r] for r in rows], dtype=np.float64)
    except ValueError as exc:
        raise InvalidDemonstrationError(f"{p.name}: non-numeric value ({exc}).") from None
    if data.size == 0:
        data = data.reshape(0, len(header) if header else 2)
    return data, header


def _numeric(row: list[str]) -> bool:
    try:
        [float(c) for c in row]
    except ValueError:
        return False
    return True
