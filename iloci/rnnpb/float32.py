"""The float32 arithmetic of the RNNPB's training, in numpy: the specification.

:func:`train` is :func:`iloci.rnnpb.reference.train` (the recipe: forward
pass, closed-loop loss, back-propagation through time, clipping, schedule,
Adam) computed in float32 in one stated order of operations, the order of
``native-rnnpb``'s C kernel (``plugins/iloci-native``, "The float32
arithmetic" in ``_native.c``). Every instruction set of that kernel
(AVX-512, AVX2, portable C, NEON) computes exactly this, and so does this
module, bit for bit (``tests/plugins/test_rnnpb_reference_parity.py``).
It is slow (a loop over every sum's terms); it is the definition, not a
back end.

The order (``S = D + C`` state units, ``H`` hidden units; the arrays are
padded to ``S_p``, ``H_p``, the next multiples of 16, with zeros that stay
zero, as in the kernel's layout):

* a matrix product's element ``C[i, j] = init + sum_k A[i, k] B[k, j]`` is
  ``acc = init`` (a bias row, the row being added to, or +0), then for
  ``k`` ascending ``acc = fma(A[i, k], B[k, j], acc)``: one rounding per
  term (:func:`fma`). The forward pass sums over the ``S`` state and ``H``
  hidden units; the weight gradients over all steps and rows, time-major
  (step by step, rows in order within a step), from +0; the PB gradient's
  dot products over the ``H_p`` padded hidden units, from +0;
* column sums (``b_out``'s and ``b_hidden``'s gradients, the sum of the
  hidden deltas over steps) add in ascending order from +0, no products;
* ``tanh(x)``: clamp to ``+-7.90531110763549805``, ``x2 = x x``, the [13/6]
  rational function of Eigen and XLA with fused Horner steps for the
  numerator ``p(x2)`` and denominator ``q(x2)``, then ``(x p) / q``
  correctly rounded (:func:`tanh`);
* the derivative ``y (1 - e^2)`` inside a product's epilogue as
  ``y * fma(-e, e, 1)``; at the last step, before any product, as
  ``g * (1 - o o)`` separately rounded;
* everything else (the loss, the mixing of inputs, Adam) separately
  rounded float32 operations in the order written below;
* the closed-loop prediction error of a row scoring candidate PBs
  (:func:`prediction_errors`): the forward pass above, each step's
  ``sum_D d^2`` in float32, its sum over steps weighted by the mask in
  float64, over ``D`` and the row's step count;
* in float64: the loss's sum over rows (each row's float32
  ``sum_D d^2`` times its weight, added in time-major order), the
  clipping norm (8 partial sums of the squares, interleaved over the flat
  padded gradient, then ``((s0 + s1) + (s2 + s3)) + ((s4 + s5) + (s6 + s7))``),
  Adam's step size (bias corrections as running products ``0.9^t``,
  ``0.999^t``) and the decay ``decay ** ((t - 1) / epochs)`` (libm's
  ``pow``, as the kernel).

numpy has no fused multiply-add; :func:`fma` computes one exactly: the
product of two float32 is exact in float64, their sum with the addend is
rounded to float64 *to odd* (the error of the float64 sum, found exactly by
Knuth's TwoSum, decides the last bit), and a value rounded to odd with at
least 2 more bits than float32 rounds to float32 as the exact value does
(Boldo & Melquiond 2008, "Emulation of FMA and correctly rounded sums:
proved algorithms using rounding to odd", IEEE Trans. Computers 57(4),
doi:10.1109/TC.2007.70819, Theorem 1).
"""

from __future__ import annotations

from collections.abc import Mapping
import math
from typing import Any

import numpy as np

from iloci.params import RNNPBParams

__all__ = ["fma", "tanh", "train", "prediction_errors"]

F32 = np.float32
#: tanh's clamp and its rational function's coefficients, as the kernel's float literals
TANH_CLAMP = F32(7.90531110763549805)
TANH_P = tuple(F32(c) for c in (-2.76076847742355e-16, 2.00018790482477e-13,
                                -8.60467152213735e-11, 5.12229709037114e-08,
                                1.48572235717979e-05, 6.37261928875436e-04,
                                4.89352455891786e-03))
TANH_Q = tuple(F32(c) for c in (1.19825839466702e-06, 1.18534705686654e-04,
                                2.26843463243900e-03, 4.89352518554385e-03))


def fma(a: Any, b: Any, c: Any) -> np.ndarray:
    """``a b + c`` rounded once to float32 (arrays broadcast; float32 in and out)."""
    x = np.asarray(a, np.float32).astype(np.float64) * np.asarray(b, np.float32)  # exact
    y = np.asarray(c, np.float32).astype(np.float64)
    s = x + y
    bv = s - x
    err = (x - (s - bv)) + (y - bv)          # TwoSum: s + err == x + y exactly
    odd = (s.view(np.int64) & 1) == 1
    with np.errstate(invalid="ignore"):
        toward = np.where(err > 0, np.inf, -np.inf)
    s = np.where((err != 0) & ~odd, np.nextafter(s, toward), s)  # round to odd
    return s.astype(np.float32)


def tanh(x: Any) -> np.ndarray:
    """The kernel's float32 tanh (module docstring), element-wise."""
    x = np.minimum(np.maximum(np.asarray(x, np.float32), -TANH_CLAMP), TANH_CLAMP)
    x2 = x * x
    p = fma(x2, TANH_P[0], TANH_P[1])
    for c in TANH_P[2:]:
        p = fma(x2, p, c)
    q = fma(x2, TANH_Q[0], TANH_Q[1])
    for c in TANH_Q[2:]:
        q = fma(x2, q, c)
    return (x * p) / q


def _product(a: np.ndarray, b: np.ndarray, k: int, init: Any) -> np.ndarray:
    """``init + a[:, :k] @ b[:k]``, one fma per term, k ascending."""
    acc = np.broadcast_to(np.asarray(init, np.float32), (a.shape[0], b.shape[1])).copy()
    for i in range(k):
        acc = fma(a[:, i:i + 1], b[i][None, :], acc)
    return acc


def _product_tn(a: np.ndarray, b: np.ndarray, init: np.ndarray | None = None) -> np.ndarray:
    """``init + a.T @ b`` (a sum over rows, in order), one fma per term, from +0."""
    acc = (np.zeros((a.shape[1], b.shape[1]), np.float32) if init is None
           else init.copy())
    for r in range(a.shape[0]):
        acc = fma(a[r][:, None], b[r][None, :], acc)
    return acc


def _colsum(a: np.ndarray) -> np.ndarray:
    """Sum over the first axis in order, from +0."""
    acc = np.zeros(a.shape[1:], np.float32)
    for row in a:
        acc = acc + row
    return acc


def _dtanh(y: np.ndarray, e: Any) -> np.ndarray:
    return y * fma(-e, e, F32(1.0))


def _round16(n: int) -> int:
    return (n + 15) // 16 * 16


def train(weights: Mapping[str, np.ndarray], u: np.ndarray, X: np.ndarray, mw: np.ndarray,
          params: RNNPBParams, epochs: int
          ) -> tuple[dict[str, np.ndarray], np.ndarray, float, np.ndarray]:
    """Full-batch training in the kernel's float32 arithmetic (module docstring).

    Arguments as :func:`iloci.rnnpb.reference.train` (converted to float32
    first: the weights, ``u`` (R, P), ``X`` (T, R, D), ``mw`` (T - 1, R)).

    Returns
    -------
    weights : dict of ndarray (float32)
    u : ndarray (float32), shape (R, P)
    loss : float
        The last epoch's loss (float32's value).
    losses : ndarray (float32), shape (epochs,)
    """
    X = np.asarray(X, np.float32)
    mw = np.asarray(mw, np.float32)
    u = np.array(u, np.float32)
    T, R, D = X.shape
    H, S = np.asarray(weights["w_out"]).shape
    P = u.shape[1]
    L, Sp, Hp = T - 1, _round16(S), _round16(H)
    alpha, bound = F32(params.closed_loop), F32(params.pb_bound)
    # the padded parameters, flat as the kernel holds them: Ws | Wp | bh | Wo | bo
    flat = np.concatenate([p.ravel() for p in _padded(weights, S, H, P)])
    m, v = np.zeros_like(flat), np.zeros_like(flat)
    mu, vu = np.zeros_like(u), np.zeros_like(u)
    mix = np.zeros(Sp, np.float32)
    mix[:S] = 1.0
    mix[:D] = alpha
    s0 = np.zeros((R, Sp), np.float32)
    s0[:, :D] = X[0]
    losses = np.zeros(epochs, np.float32)
    b1t = b2t = 1.0
    for t in range(1, epochs + 1):
        Ws, Wp, bh, Wo, bo = _unflat(flat, Sp, Hp, P)
        pb = bound * tanh(u)
        pre = _product(pb, Wp, P, bh)
        # forward: s_0 = [x_0, 0]; s_t = o_{t-1} mix + (1 - alpha) [x_t, 0]
        ins: list[np.ndarray] = []
        Hs: list[np.ndarray] = []
        Os: list[np.ndarray] = []
        for s in range(L):
            if s == 0:
                state = s0
            elif alpha != 1.0:
                add = np.zeros((R, Sp), np.float32)
                add[:, :D] = (F32(1.0) - alpha) * X[s]
                state = Os[s - 1] * mix + add
            else:
                state = Os[s - 1]
            ins.append(state)
            h = tanh(_product(state, Ws, S, pre))
            Hs.append(h)
            Os.append(tanh(_product(h, Wo, H, bo)))
        # loss and dL/do, row by row in time-major order
        lsum = 0.0
        G = [np.zeros((R, Sp), np.float32) for _ in range(L)]
        two_d = F32(2.0) / F32(D)
        for s in range(L):
            d = Os[s][:, :D] - X[s + 1]
            part = np.zeros(R, np.float32)
            for j in range(D):
                part = part + d[:, j] * d[:, j]
            G[s][:, :D] = (d * mw[s][:, None]) * two_d
            for r in range(R):
                lsum += float(part[r] * mw[s, r])
        losses[t - 1] = F32(lsum / D)
        # backward
        WoT = np.ascontiguousarray(Wo.T)
        WsTm = np.ascontiguousarray(Ws.T) * mix[None, :]
        DZ: list[np.ndarray] = [np.zeros(0, np.float32)] * L
        G[L - 1] = G[L - 1] * (F32(1.0) - Os[L - 1] * Os[L - 1])
        for s in range(L - 1, -1, -1):
            DZ[s] = _dtanh(_product(G[s], WoT, S, F32(0.0)), Hs[s])
            if s > 0:
                G[s - 1] = _dtanh(_product(DZ[s], WsTm, H, G[s - 1]), Os[s - 1])
        Hall, Gall, Dall = np.concatenate(Hs), np.concatenate(G), np.concatenate(DZ)
        gWo = _product_tn(Hall, Gall)
        gWs = _product_tn(np.concatenate(ins), Dall)
        gbo = _colsum(Gall)
        sdz = _colsum(np.stack(DZ))
        gbh = _colsum(sdz)
        gWp = _product_tn(pb, sdz)
        dots = np.zeros((R, P), np.float32)
        for col in range(Hp):
            dots = fma(sdz[:, col][:, None], Wp[:, col][None, :], dots)
        th = tanh(u)
        gu = (dots * bound) * (F32(1.0) - th * th)
        g = np.concatenate([p.ravel() for p in (gWs, gWp, gbh, gWo, gbo)])
        # clipping: 8 interleaved float64 partial sums of the squares
        sq8 = np.add.accumulate(g.astype(np.float64).reshape(-1, 8) ** 2, axis=0)[-1]
        sq = ((sq8[0] + sq8[1]) + (sq8[2] + sq8[3])) + ((sq8[4] + sq8[5]) + (sq8[6] + sq8[7]))
        scale = min(1.0, params.grad_clip / (math.sqrt(sq) + 1e-12))
        f = params.learning_rate_decay ** ((t - 1) / epochs)
        warm = params.warmup_epochs
        ramp = (t / warm if t < warm else 1.0) if warm > 0 else 1.0
        b1t *= 0.9
        b2t *= 0.999
        flat = _adam(flat, g, m, v, params.learning_rate * f * ramp, b1t, b2t, F32(scale))
        u = _adam(u, gu, mu, vu, params.pb_learning_rate * f, b1t, b2t, F32(1.0))
    Ws, Wp, bh, Wo, bo = _unflat(flat, Sp, Hp, P)
    out = {"w_in": np.concatenate([Ws[:S, :H], Wp[:, :H]]), "b_hidden": bh[:H].copy(),
           "w_out": Wo[:H, :S].copy(), "b_out": bo[:S].copy()}
    return out, u, float(losses[-1]) if epochs else float("nan"), losses


def _unflat(flat: np.ndarray, Sp: int, Hp: int, P: int) -> list[np.ndarray]:
    sizes = [(Sp, Hp), (P, Hp), (Hp,), (Hp, Sp), (Sp,)]
    out, i = [], 0
    for shape in sizes:
        n = int(np.prod(shape))
        out.append(flat[i:i + n].reshape(shape))
        i += n
    return out


def _adam(p: np.ndarray, g: np.ndarray, m: np.ndarray, v: np.ndarray, lr: float,
          b1t: float, b2t: float, scale: np.float32) -> np.ndarray:
    """Adam in the kernel's order; ``m`` and ``v`` are updated in place."""
    b1, b2 = F32(0.9), F32(0.999)
    step = F32(lr * math.sqrt(1.0 - b2t) / (1.0 - b1t))
    gi = g * scale
    m[...] = b1 * m + (F32(1.0) - b1) * gi
    v[...] = b2 * v + ((F32(1.0) - b2) * gi) * gi
    return p - (step * m) / (np.sqrt(v) + F32(1e-8))


def _padded(weights: Mapping[str, np.ndarray], S: int, H: int, P: int
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The kernel's padded Ws, Wp, bh, Wo, bo from the weight dict (float32)."""
    Sp, Hp = _round16(S), _round16(H)
    w_in = np.asarray(weights["w_in"], np.float32)
    Ws = np.zeros((Sp, Hp), np.float32)
    Ws[:S, :H] = w_in[:S]
    Wp = np.zeros((P, Hp), np.float32)
    Wp[:, :H] = w_in[S:]
    bh = np.zeros(Hp, np.float32)
    bh[:H] = np.asarray(weights["b_hidden"], np.float32)
    Wo = np.zeros((Hp, Sp), np.float32)
    Wo[:H, :S] = np.asarray(weights["w_out"], np.float32)
    bo = np.zeros(Sp, np.float32)
    bo[:S] = np.asarray(weights["b_out"], np.float32)
    return Ws, Wp, bh, Wo, bo


def prediction_errors(weights: Mapping[str, np.ndarray], pbs: np.ndarray, X: np.ndarray,
                      mask: np.ndarray) -> np.ndarray:
    """Closed-loop prediction error of each row under its PB, in the kernel's float32 arithmetic.

    What native-rnnpb's kernel computes to score candidate PBs
    (``iloci_rnnpb_errors``): the same bits.

    Parameters
    ----------
    weights : dict of ndarray
    pbs : ndarray, shape (R, P)
        The PBs themselves (not ``u``).
    X : ndarray, shape (T, R, D)
    mask : ndarray, shape (T - 1, R)

    Returns
    -------
    ndarray (float32), shape (R,)
        ``sum_t mask[t, r] sum_D (y_t - X[t + 1])^2 / D / max(1, sum_t mask[t, r])``.
    """
    X = np.asarray(X, np.float32)
    mask = np.asarray(mask, np.float32)
    pbs = np.asarray(pbs, np.float32)
    T, R, D = X.shape
    H, S = np.asarray(weights["w_out"]).shape
    Ws, Wp, bh, Wo, bo = _padded(weights, S, H, pbs.shape[1])
    pre = _product(pbs, Wp, pbs.shape[1], bh)
    state = np.zeros((R, _round16(S)), np.float32)
    state[:, :D] = X[0]
    total = np.zeros(R, np.float64)
    steps = np.zeros(R, np.float64)
    for t in range(T - 1):
        h = tanh(_product(state, Ws, S, pre))
        state = tanh(_product(h, Wo, H, bo))
        d = state[:, :D] - X[t + 1]
        part = np.zeros(R, np.float32)
        for j in range(D):
            part = part + d[:, j] * d[:, j]
        total += part.astype(np.float64) * mask[t].astype(np.float64)
        steps += mask[t].astype(np.float64)
    return (total / D / np.maximum(steps, 1.0)).astype(np.float32)
