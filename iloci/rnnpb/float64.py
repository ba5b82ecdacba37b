"""The float64 arithmetic of closed-loop generation, in numpy: the specification.

:meth:`iloci.rnnpb.RNNPBBase.generate` (an entry's regenerated pattern: what
the robot performs, what the regeneration decision compares a drawing
with, what a rehearsal trains on) runs the network closed-loop in float64.
Written with numpy's ``@`` and ``tanh`` (:func:`iloci.rnnpb.reference.reference_outputs`)
its last bits depend on the CPU: OpenBLAS picks its matrix kernels by CPU
model (on one machine ``OPENBLAS_CORETYPE=Haswell`` and ``SkylakeX`` give
different bits) and numpy's ``tanh`` has its own SIMD code on AVX-512.
The same seed then learned memories that differ in their last bits from
machine to machine (found on 2026-12-02: the golden session of
``tests/test_golden.py`` recorded on one x86-64 machine did not hold on
another). This module defines one order of float64 operations instead;
native-rnnpb's C kernel (``iloci_rnnpb_generate64`` in ``_native.c``)
computes exactly it, on every CPU, and the tests compare the two bit for
bit (``tests/plugins/test_native_rnnpb.py``).

The order (``S = D + C`` state units, ``H`` hidden units, ``P`` PB units;
``w_in`` (S + P, H), ``w_out`` (H, S), as :func:`iloci.rnnpb.reference.init_weights`):

* a product's element ``z[j] = (sum_k a[k] w[k, j]) + b[j]``: ``acc = +0``,
  then for ``k`` ascending ``acc = acc + a[k] * w[k, j]`` (the product
  rounded, then the sum: no fused multiply-add), then ``acc + b[j]``. The
  PB's part of the hidden pre-activation, ``pre = (sum_k pb[k] w_in[S + k]) +
  b_hidden``, is computed once per row; each step's hidden pre-activation is
  ``(sum_k s[k] w_in[k]) + pre`` over the whole state ``s = [x, c]``;
* ``tanh(x) = sign(x) e / (e + 2)`` with ``e = expm1(2 |x|)``; ``1`` (with
  ``x``'s sign) for ``|x| > 22``, where tanh rounds to 1;
* ``expm1(y)`` for ``y >= 0``: ``k = floor(y / ln 2 + 1/2)`` (``y`` times
  :data:`INV_LN2`), ``r = (y - k ln2_hi) - k ln2_lo`` (Cody and Waite's
  split of ln 2, as fdlibm's), ``p = r + r^2/2! + ... + r^14/14!`` by
  Horner's rule (``|r| <= 0.35``: the first term left out is below
  ``2^-60 |r|``), then ``2^k p + (2^k - 1)``. Within 4 units in the last
  place of :func:`math.tanh` on 1.2 million ``x`` evenly spread over
  [-30, 30] (1 in 630 beyond 1 unit, 47 beyond 2): not correctly rounded,
  and the same everywhere.

Every operation is a correctly rounded IEEE float64 operation (``ldexp``
and ``floor`` are exact), so any IEEE machine computes these bits.
"""

from __future__ import annotations

from collections.abc import Mapping
import math

import numpy as np

__all__ = ["tanh64", "expm1_64", "generate64", "INV_LN2", "LN2_HI", "LN2_LO",
           "EXPM1_COEFFICIENTS", "TANH_ONE"]

#: ``1 / ln 2`` rounded to float64.
INV_LN2 = 1.4426950408889634
#: ln 2 split in two (fdlibm's ``ln2_hi``, ``ln2_lo``): ``k * LN2_HI`` is exact for ``|k| < 2^20``.
LN2_HI = 6.93147180369123816490e-01
LN2_LO = 1.90821492927058770002e-10
#: ``1 / n!`` for ``n = 1 .. 14``, each rounded to float64 (Horner from the last).
EXPM1_COEFFICIENTS = tuple(1.0 / math.factorial(n) for n in range(1, 15))
#: Beyond this ``|x|``, tanh is 1 in float64 (``1 - tanh(x) < 2^-54`` from ``x > 19.1``).
TANH_ONE = 22.0


def expm1_64(y: np.ndarray) -> np.ndarray:
    """``exp(y) - 1`` for ``0 <= y <= 2 * TANH_ONE``, in the order of the module docstring.

    Parameters
    ----------
    y : ndarray of float64, any shape, each in ``[0, 44]`` (NaN passes through)

    Returns
    -------
    ndarray of float64, the shape of ``y``
    """
    y = np.asarray(y, dtype=np.float64)
    k = np.floor(y * INV_LN2 + 0.5)
    r = (y - k * LN2_HI) - k * LN2_LO
    p = np.full_like(r, EXPM1_COEFFICIENTS[-1])
    for c in EXPM1_COEFFICIENTS[-2::-1]:
        p = c + r * p
    p = r * p
    ki = np.nan_to_num(k).astype(np.int64)
    return np.ldexp(p, ki) + (np.ldexp(1.0, ki) - 1.0)


def tanh64(x: np.ndarray) -> np.ndarray:
    """tanh in the module docstring's order (the C kernel's ``tanh64``, bit for bit).

    Parameters
    ----------
    x : ndarray of float64, any shape

    Returns
    -------
    ndarray of float64, the shape of ``x``
    """
    x = np.asarray(x, dtype=np.float64)
    a = np.abs(x)
    e = expm1_64(np.minimum(a, TANH_ONE) * 2.0)
    t = np.where(a > TANH_ONE, 1.0, e / (e + 2.0))
    return np.copysign(t, x)


def _product(a: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``sum_k a[:, k] w[k]`` from +0, ``k`` ascending, each product rounded, then added."""
    acc = np.zeros((a.shape[0], w.shape[1]))
    for k in range(a.shape[1]):
        acc = acc + a[:, k:k + 1] * w[k][None, :]
    return acc


def generate64(weights: Mapping[str, np.ndarray], pbs: np.ndarray, x0: np.ndarray,
               steps: int) -> np.ndarray:
    """Closed-loop outputs of the network in the module docstring's order: the spec.

    Slow (a loop over every sum's terms); what it computes is what the C
    kernel's ``iloci_rnnpb_generate64`` computes.

    Parameters
    ----------
    weights : dict of ndarray
        ``w_in`` (D + C + P, H), ``b_hidden`` (H,), ``w_out`` (H, D + C),
        ``b_out`` (D + C,), as :func:`iloci.rnnpb.reference.init_weights`.
    pbs : ndarray, shape (R, P)
    x0 : ndarray, shape (R, D)
        The first input of each row (the paper's initialInfo).
    steps : int
        Outputs to produce.

    Returns
    -------
    ndarray, shape (steps, R, D)
        Output ``t`` predicts step ``t + 1``, and is the input of the next step.
    """
    w_in = np.asarray(weights["w_in"], dtype=np.float64)
    w_out = np.asarray(weights["w_out"], dtype=np.float64)
    b_hidden = np.asarray(weights["b_hidden"], dtype=np.float64)
    b_out = np.asarray(weights["b_out"], dtype=np.float64)
    x0 = np.asarray(x0, dtype=np.float64)
    d, s = x0.shape[1], w_out.shape[1]
    pre = _product(np.asarray(pbs, dtype=np.float64), w_in[s:]) + b_hidden
    state = np.zeros((len(x0), s))
    state[:, :d] = x0
    out = np.empty((steps, len(x0), d))
    for t in range(steps):
        h = tanh64(_product(state, w_in[:s]) + pre)
        state = tanh64(_product(h, w_out) + b_out)
        out[t] = state[:, :d]
    return out
