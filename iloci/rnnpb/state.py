"""The RNNPB's weights and saved state, shared by every back end (:mod:`iloci.rnnpb.common`).

The weight layout (:func:`weight_shapes`), the PB reparametrisation
``pb = bound tanh(u)`` (:func:`pb_to_u`, :func:`u_to_pb`) and the state
dict every back end saves and loads (:func:`make_state`, :func:`read_state`),
so a state saved by one back end loads into any other.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, fields
from typing import Any

import numpy as np

from iloci.errors import InvalidInputError
from iloci.params import RNNPBParams
from iloci.rnnpb.inputs import check_pbs

__all__ = ["FORMAT", "FORMAT_VERSION", "WEIGHT_NAMES", "weight_shapes", "pb_to_u", "u_to_pb",
           "make_state", "read_state"]

#: Value of ``state()["format"]``.
FORMAT = "iloci-rnnpb"
#: Version of the state layout; bumped when keys or their meaning change.
#: 2: ``recognition_method`` (Levenberg-Marquardt by default); a version-1
#: state recognized by Adam, so it loads with ``recognition_method="adam"``.
FORMAT_VERSION = 2
#: Weight arrays of a state, in this order.
WEIGHT_NAMES = ("w_in", "b_hidden", "w_out", "b_out")


def weight_shapes(input_size: int, hidden: int, context: int, pb: int) -> dict[str, tuple]:
    """Shapes of the weight arrays.

    Returns
    -------
    dict
        ``w_in`` (D + C + P, H) with rows ordered [input, context, PB];
        ``b_hidden`` (H,); ``w_out`` (H, D + C) with columns ordered
        [output, next context]; ``b_out`` (D + C,).
    """
    d, h, c, p = input_size, hidden, context, pb
    return {"w_in": (d + c + p, h), "b_hidden": (h,), "w_out": (h, d + c), "b_out": (d + c,)}


# -- PB reparametrisation ----------------------------------------------------

def pb_to_u(pbs: np.ndarray, bound: float) -> np.ndarray:
    """Unconstrained parameters of PB vectors (inverse of :func:`u_to_pb`).

    PBs at or beyond the bound are pulled just inside it, where ``atanh`` is
    finite.
    """
    r = np.clip(np.asarray(pbs, dtype=np.float64) / bound, -0.999, 0.999)
    return np.arctanh(r)


def u_to_pb(u: np.ndarray, bound: float) -> np.ndarray:
    """``pb = bound * tanh(u)``: every PB inside ``(-bound, bound)``."""
    return bound * np.tanh(np.asarray(u, dtype=np.float64))


# -- state ---------------------------------------------------------------------

def make_state(params: RNNPBParams, weights: Mapping[str, np.ndarray], pbs: np.ndarray,
               backend: str) -> dict[str, np.ndarray]:
    """The state dict of a model: weights, stored PBs, settings, format tag.

    Every value is a numpy array (strings as 0-d unicode arrays), so the
    dict saves with ``np.savez`` and loads with ``allow_pickle=False``.

    Returns
    -------
    dict of str to ndarray
        ``format``, ``version``, ``backend``; the weights (float64);
        ``pbs`` (K, P), the PBs learned by the last training (the default
        starts of recognition); ``param.NAME`` for every hyper-parameter.
    """
    out: dict[str, np.ndarray] = {
        "format": np.array(FORMAT),
        "version": np.array(FORMAT_VERSION),
        "backend": np.array(backend),
        "pbs": np.array(pbs, dtype=np.float64).reshape(-1, params.pb),
    }
    for name in WEIGHT_NAMES:
        out[name] = np.array(weights[name], dtype=np.float64)
    for key, value in asdict(params).items():
        out[f"param.{key}"] = np.array(value)
    return out


def read_state(state: Mapping[str, Any], params: RNNPBParams
               ) -> tuple[dict[str, np.ndarray], np.ndarray, RNNPBParams]:
    """Check a state dict and take it apart.

    The sizes (``input_size``, ``hidden``, ``context``, ``pb``) of the state
    replace those of ``params``; so do the other stored hyper-parameters,
    so a loaded model trains and recognizes as the saved one did. ``dtype``
    and ``kernel`` stay the loading model's (a float64 state runs in float32
    and back; a torch state loads into jax-rnnpb).

    Returns
    -------
    weights : dict of str to ndarray (float64)
    pbs : ndarray, shape (K, P)
    params : RNNPBParams

    Raises
    ------
    InvalidInputError
        Not a mapping, not an RNNPB state, a newer format version, missing
        keys, or arrays whose shapes do not match the stored sizes.
    """
    if not isinstance(state, Mapping):
        raise InvalidInputError(f"state must be a dict of arrays as returned by state(), got "
                                f"{type(state).__name__}.")
    fmt = str(np.asarray(state.get("format", "")))
    if fmt != FORMAT:
        raise InvalidInputError(f"not an RNNPB state (format {fmt!r}, expected {FORMAT!r}); "
                                "pass the dict returned by state() of torch-rnnpb or "
                                "jax-rnnpb.")
    try:
        version = int(np.asarray(state["version"]))
    except (KeyError, TypeError, ValueError):
        raise InvalidInputError("RNNPB state has no integer 'version'.") from None
    if version > FORMAT_VERSION:
        raise InvalidInputError(f"RNNPB state version {version} is newer than this iloci "
                                f"reads ({FORMAT_VERSION}); upgrade iloci.")
    values = asdict(params)
    if version < 2:
        values["recognition_method"] = "adam"
    for f in fields(RNNPBParams):
        key = f"param.{f.name}"
        if key in state and f.name not in ("dtype", "kernel"):
            v = np.asarray(state[key])
            values[f.name] = type(values[f.name])(v.item() if v.ndim == 0 else v)
    try:
        new = RNNPBParams(**values)
        new.validate()
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"RNNPB state holds invalid settings: {exc}.") from None
    shapes = weight_shapes(new.input_size, new.hidden, new.context, new.pb)
    weights = {}
    for name in WEIGHT_NAMES:
        if name not in state:
            raise InvalidInputError(f"RNNPB state lacks {name!r}.")
        a = np.array(state[name], dtype=np.float64)
        if a.shape != shapes[name]:
            raise InvalidInputError(f"RNNPB state {name!r} has shape {a.shape}, expected "
                                    f"{shapes[name]} for sizes input_size={new.input_size}, "
                                    f"hidden={new.hidden}, context={new.context}, pb={new.pb}.")
        if not np.all(np.isfinite(a)):
            raise InvalidInputError(f"RNNPB state {name!r} contains NaN or inf.")
        weights[name] = a
    pbs = check_pbs(state.get("pbs", np.zeros((0, new.pb))), None, new.pb, "state 'pbs'")
    return weights, pbs, new
