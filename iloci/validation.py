"""One array validator for every public entry point, after scikit-learn's ``check_array``.

Each function that takes an array from a user (a demonstration, a joint
path, PB vectors, encoded sequences, 3-D points) checks it with
:func:`check_array`, so bad input always gets the same three messages: not
numeric, wrong shape, NaN or inf (with the first bad row).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, TypeGuard

import numpy as np

from iloci.errors import InvalidDemonstrationError, InvalidInputError

__all__ = ["MAX_POINTS", "check_array", "check_size", "is_integer", "shape_text"]

#: Most samples one demonstration may have: 2,000,000 (a pen sampled at 1 kHz for
#: 33 minutes). Reading a drawing takes time linear in its samples, about 3 s per
#: million on one core (``benchmarks/results/preprocess.json``); more is refused by
#: :func:`iloci.sensorimotor.preprocess.preprocess` and
#: :func:`iloci.data.load_trajectory` with a clear error. Here, below both (the
#: data layer may not import the sensorimotor one); also importable from
#: :mod:`iloci.sensorimotor.preprocess`.
MAX_POINTS = 2_000_000


def is_integer(value: Any) -> TypeGuard[int | np.integer]:
    """Whether ``value`` is an integer: a Python or numpy int, not a bool (nor numpy's)."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def check_size(n: int, what: str) -> None:
    """Raise InvalidDemonstrationError when ``n`` samples exceed :data:`MAX_POINTS`."""
    if n > MAX_POINTS:
        raise InvalidDemonstrationError(
            f"{what} has {n:,} samples; iloci reads at most {MAX_POINTS:,} per demonstration "
            "(iloci.sensorimotor.preprocess.MAX_POINTS). Downsample it first (every k-th "
            "sample keeps the drawing: 50 points along its path are all the robot reads), "
            "or split a recording of several drawings into one file each.")


def shape_text(shape: Sequence[int | str | None]) -> str:
    """``(T, 2)``-style text of a shape spec (None: ``T``, str: itself, int: itself)."""
    parts = ["T" if s is None else str(s) for s in shape]
    return "(" + ", ".join(parts) + ("," if len(parts) == 1 else "") + ")"


def check_array(value: Any, name: str, shape: Sequence[int | str | None], *,
                finite: bool = True, error: type[InvalidInputError] = InvalidInputError,
                hint: str = "", finite_hint: str = "") -> np.ndarray:
    """``value`` as a float64 array of the given shape, finite unless told otherwise.

    Parameters
    ----------
    value : array_like
    name : str
        How messages name it (``"joint path"``, ``"positions of 'GShape/3'"``).
    shape : sequence of int, str or None
        One item per dimension: an int is the exact size, a str or None
        any size (named by the str, or ``T``, in messages).
    finite : bool
        Reject NaN and inf.
    error : subclass of InvalidInputError
        The error raised (e.g. :class:`~iloci.errors.InvalidDemonstrationError`).
    hint, finite_hint : str
        Appended to the shape and to the NaN messages (what to do).

    Returns
    -------
    ndarray
        float64; a new array only when a conversion was needed.

    Raises
    ------
    InvalidInputError (or ``error``)
        Not numeric; wrong number of dimensions or size; NaN or inf (the
        message gives the index of the first one).
    """
    want = shape_text(shape)
    if hasattr(value, "detach") and hasattr(value, "cpu"):  # a torch tensor (maybe on a GPU)
        value = value.detach().cpu().numpy()
    if isinstance(value, np.ma.MaskedArray):
        if np.ma.count_masked(value):
            raise error(f"{name} is a masked array with masked values: iloci would read the "
                        "values under the mask. Drop the masked rows (or fill them) first.")
        value = value.data
    try:
        kind = np.asarray(value).dtype.kind
    except (TypeError, ValueError):  # ragged nested lists: said below
        kind = "O"
    if kind in "bcmMV":  # numpy would read these as numbers, silently: not what was meant
        what = {"b": "true/false values", "c": "complex numbers",
                "m": "time spans (timedelta64)", "M": "dates (datetime64)",
                "V": "records"}[kind]
        extra = (" Convert time stamps to seconds first, e.g. (t - t[0]) / "
                 "np.timedelta64(1, 's').") if kind in "mM" else ""
        raise error(f"{name} must be a numeric array of shape {want}, got {what}.{extra}")
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise error(f"{name} must be a numeric array of shape {want}.") from None
    if arr.ndim != len(shape) or any(isinstance(s, int) and s != n
                                     for s, n in zip(shape, arr.shape)):
        raise error(f"{name} must have shape {want}, got {arr.shape}.{hint}")
    if finite and not np.all(np.isfinite(arr)):
        where = np.argwhere(~np.isfinite(arr))[0]
        at = f"row {int(where[0])}" if arr.ndim else "it"
        raise error(f"{name} contains NaN or inf (first at {at}).{finite_hint}")
    return arr
