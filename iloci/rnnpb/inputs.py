"""The RNNPB's input checks and padding, shared by every back end (:mod:`iloci.rnnpb.common`).

Sequences, PBs and generation arguments are checked here once, so every
back end refuses the same inputs with the same :class:`~iloci.errors.InvalidInputError`,
and pads and buckets batches the same way.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from iloci.errors import InvalidInputError

__all__ = ["check_sequences", "pad_sequences", "bucket", "check_pbs", "check_generate_args"]

def check_sequences(sequences: Any, input_size: int, what: str = "sequences",
                    min_length: int = 2) -> list[np.ndarray]:
    """Validate a list of sequences and return them as float64 arrays.

    Parameters
    ----------
    sequences : sequence of array_like, each (T_i, D)
    input_size : int
        ``D``.
    min_length : int
        Fewest rows a sequence may have (2: one step to predict).

    Returns
    -------
    list of ndarray, each (T_i, D) float64

    Raises
    ------
    InvalidInputError
        Not a list, empty, a sequence not 2-D, of the wrong width, too short,
        or containing NaN or inf; the message names the sequence.
    """
    if isinstance(sequences, np.ndarray) and sequences.ndim == 2:
        raise InvalidInputError(
            f"{what} must be a list of (T, {input_size}) arrays, got one 2-D array of shape "
            f"{sequences.shape}; wrap a single sequence in a list: [sequence].")
    try:
        items = list(sequences)
    except TypeError:
        raise InvalidInputError(f"{what} must be a list of (T, {input_size}) arrays, got "
                                f"{type(sequences).__name__}.") from None
    if not items:
        raise InvalidInputError(f"{what} is empty; pass at least one (T, {input_size}) "
                                "sequence.")
    out = []
    for i, s in enumerate(items):
        try:
            a = np.asarray(s, dtype=np.float64)
        except (TypeError, ValueError):
            raise InvalidInputError(f"{what}[{i}] is not a numeric array.") from None
        if a.ndim != 2 or a.shape[1] != input_size:
            raise InvalidInputError(
                f"{what}[{i}] has shape {a.shape}; every sequence must have shape "
                f"(T, {input_size}): one row per step, {input_size} features (the model's "
                "input_size).")
        if len(a) < min_length:
            raise InvalidInputError(
                f"{what}[{i}] has {len(a)} step(s); at least {min_length} are needed (the "
                "network predicts each step from the previous one).")
        if not np.all(np.isfinite(a)):
            row = int(np.argwhere(~np.isfinite(a))[0, 0])
            raise InvalidInputError(f"{what}[{i}] contains NaN or inf (first at row {row}); "
                                    "remove or interpolate missing samples.")
        out.append(a)
    return out


def pad_sequences(sequences: Sequence[np.ndarray], rows: int | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Stack sequences of different lengths, time-major, with a mask.

    Parameters
    ----------
    sequences : list of ndarray, each (T_i, D)
        Checked sequences.
    rows : int, optional
        Batch size to pad to (``>= B``); extra rows are all-zero sequences
        with an all-zero mask, which contribute nothing to any loss.

    Returns
    -------
    X : ndarray, shape (T_max, rows, D)
        Zero after the end of each sequence.
    mask : ndarray, shape (T_max - 1, rows)
        1.0 where step ``t + 1`` of the sequence exists (a prediction to
        score), else 0.0.
    """
    b = len(sequences)
    rows = b if rows is None else rows
    t_max = max(len(s) for s in sequences)
    d = sequences[0].shape[1]
    X = np.zeros((t_max, rows, d))
    mask = np.zeros((t_max - 1, rows))
    for i, s in enumerate(sequences):
        X[:len(s), i] = s
        mask[:len(s) - 1, i] = 1.0
    return X, mask


def bucket(n: int, multiple: int = 4, geometric: bool = False) -> int:
    """Rows to pad ``n`` sequences to, so compiled back ends reuse their kernels.

    ``n`` rounded up to a multiple of ``multiple``; with ``geometric``, to
    ``multiple`` times a power of two (a memory growing one entry at a time
    then needs a new kernel only each time it doubles).
    """
    n = max(1, int(n))
    if geometric:
        rows = multiple
        while rows < n:
            rows *= 2
        return rows
    return -(-n // multiple) * multiple


def check_pbs(pbs: Any, rows: int | None, pb_size: int, what: str = "pbs") -> np.ndarray:
    """Validate PB vectors.

    Parameters
    ----------
    pbs : array_like, shape (B, P)
    rows : int or None
        Required ``B`` (None: any, including 0).

    Returns
    -------
    ndarray, shape (B, P) float64
    """
    try:
        a = np.asarray(pbs, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidInputError(f"{what} must be a numeric array of shape (B, {pb_size}).") \
            from None
    if a.ndim == 1 and a.shape == (pb_size,) and rows in (None, 1):
        a = a[None]
    if a.ndim != 2 or a.shape[1] != pb_size or (rows is not None and len(a) != rows):
        want = f"({rows if rows is not None else 'K'}, {pb_size})"
        raise InvalidInputError(f"{what} must have shape {want}, got {a.shape}: one PB "
                                "vector per sequence.")
    if not np.all(np.isfinite(a)):
        raise InvalidInputError(f"{what} contains NaN or inf.")
    return a


def check_generate_args(pbs: Any, initial_inputs: Any, lengths: Any, input_size: int,
                        pb_size: int) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Validate the arguments of ``generate``.

    Returns
    -------
    pbs : ndarray, shape (B, P)
    initial_inputs : ndarray, shape (B, D)
    lengths : list of int, length B, each >= 1
    """
    p = check_pbs(pbs, None, pb_size)
    if len(p) == 0:
        raise InvalidInputError("generate needs at least one PB vector.")
    try:
        x0 = np.asarray(initial_inputs, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidInputError("initial_inputs must be numeric, shape (B, D).") from None
    if x0.ndim == 1 and len(p) == 1:
        x0 = x0[None]
    if x0.shape != (len(p), input_size):
        raise InvalidInputError(f"initial_inputs must have shape ({len(p)}, {input_size}) "
                                f"(one first step per PB), got {x0.shape}.")
    if not np.all(np.isfinite(x0)):
        raise InvalidInputError("initial_inputs contains NaN or inf.")
    try:
        lens = [int(n) for n in np.atleast_1d(np.asarray(lengths))]
        if not np.all(np.asarray(lengths) == np.asarray(lens).reshape(np.shape(lengths))):
            raise ValueError
    except (TypeError, ValueError):
        raise InvalidInputError(f"lengths must be {len(p)} whole numbers.") from None
    if len(lens) != len(p) or min(lens) < 1:
        raise InvalidInputError(f"lengths must be {len(p)} integers >= 1 (steps to produce "
                                f"per PB, the first being the initial input), got {lens}.")
    return p, x0, lens
