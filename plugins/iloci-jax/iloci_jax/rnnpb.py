"""The RNNPB in JAX: jit-compiled closed-loop BPTT over padded batches.

The model is defined in :mod:`iloci.rnnpb`. Here every kernel is
one ``jax.jit`` function over padded, time-major arrays: the time loop is a
``lax.scan``, the whole training (all epochs, Adam, clipping) or recognition
(all Levenberg-Marquardt steps, the Jacobian by ``jax.linearize``) is one
``lax.fori_loop``, so Python runs once per call, not once
per step. The backward pass is written by hand (two matrix products per
time step; the weight gradients are single matrix products over all steps
afterwards), which is about twice as fast as differentiating the scan.

``dtype = "float64"`` runs under ``jax.enable_x64`` locally, without
switching JAX to 64 bits for the rest of the process. ``generate`` and
``prediction_error`` always run in float64.
"""

from __future__ import annotations

from collections.abc import Mapping
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from iloci.errors import InvalidInputError
from iloci_jax import _ONE_KERNEL
from iloci.rnnpb import (LM_DOWN, LM_MAX, LM_MIN, LM_TINY, LM_U_MAX, LM_UP,
                          WEIGHT_NAMES, RNNPBBase, diverged_error)

__all__ = ["JaxRNNPB"]

_B1, _B2, _EPS = 0.9, 0.999, 1e-8
#: Hidden and state sizes are padded to multiples of this (float32 lanes of AVX-512).
_LANES = 16


def _padded_weights(w: Mapping[str, np.ndarray], pb: int, lanes: int = _LANES) -> dict:
    """The weights with ``S = D + C`` and ``H`` zero-padded up to multiples of ``lanes``.

    XLA's CPU matrix products are a third faster on 32 x 64 than on 31 x 60
    (whole AVX-512 registers). The padding is exact and stays zero through
    training: padded hidden units and state entries are ``tanh(0) = 0``,
    they reach nothing through the zero rows and columns, so their
    gradients, and Adam's updates of them, are zero.
    """
    s, h = w["w_out"].shape[1], w["w_out"].shape[0]
    sp, hp = -(-s // lanes) * lanes, -(-h // lanes) * lanes
    w_in = np.zeros((sp + pb, hp), w["w_in"].dtype)
    w_in[:s, :h], w_in[sp:, :h] = w["w_in"][:s], w["w_in"][s:]
    w_out = np.zeros((hp, sp), w["w_out"].dtype)
    w_out[:h, :s] = w["w_out"]
    return {"w_in": w_in, "b_hidden": np.pad(w["b_hidden"], (0, hp - h)),
            "w_out": w_out, "b_out": np.pad(w["b_out"], (0, sp - s))}


def _unpadded_weights(w: Mapping[str, np.ndarray], sizes: tuple[int, int, int, int]) -> dict:
    """Inverse of :func:`_padded_weights` for sizes ``(D, H, C, P)``."""
    d, h, c, _ = sizes
    s, sp = d + c, w["w_out"].shape[1]
    return {"w_in": np.concatenate([w["w_in"][:s, :h], w["w_in"][sp:, :h]]),
            "b_hidden": w["b_hidden"][:h], "w_out": w["w_out"][:h, :s], "b_out": w["b_out"][:s]}


def _split(w: dict, d: int) -> tuple:
    """Weights as (w_state (S, H), w_pb (P, H), b_hidden, w_out (H, S), b_out), S = D + C."""
    s = w["w_out"].shape[1]
    return w["w_in"][:s], w["w_in"][s:], w["b_hidden"], w["w_out"], w["b_out"]


def _forward(w: dict, pb, X, alpha, keep: bool):
    """Run the network over padded sequences.

    ``X`` (T, R, D), ``pb`` (R, P). The state fed to step ``t`` is
    ``s_t = [x_t, c_t]``; ``s_{t+1} = o_t * mix + (1 - alpha) [X[t+1], 0]``
    with ``mix = [alpha] * D + [1] * C``. Returns the outputs ``O``
    (T - 1, R, S); with ``keep`` also the states ``IN`` and hidden ``Hs``.
    """
    d = X.shape[2]
    w_s, w_p, b_h, w_o, b_o = _split(w, d)
    s_dim = w_o.shape[1]
    pre = pb @ w_p + b_h
    mix = _mix(alpha, d, s_dim, X.dtype)
    xpad = jnp.concatenate([X, jnp.zeros(X.shape[:2] + (s_dim - d,), X.dtype)], axis=2)
    forced = (1.0 - alpha) * xpad[1:]

    def step(s, f):
        h = jnp.tanh(s @ w_s + pre)
        o = jnp.tanh(h @ w_o + b_o)
        return o * mix + f, (h, o) if keep else o

    _, out = jax.lax.scan(step, xpad[0], forced)
    if not keep:
        return out
    Hs, O = out
    IN = jnp.concatenate([xpad[:1], O[:-1] * mix + forced[:-1]], axis=0)
    return IN, Hs, O


def _mix(alpha, d, s_dim, dtype):
    """How much of ``o_t`` enters ``s_{t+1}``: ``alpha`` for the input part, 1 for context."""
    return jnp.concatenate([jnp.full((d,), alpha, dtype), jnp.ones((s_dim - d,), dtype)])


def _errors(w, pb, X, mask):
    """Closed-loop mean squared prediction error per row, shape (R,)."""
    O = _forward(w, pb, X, 1.0, keep=False)
    d = X.shape[2]
    se = ((O[:, :, :d] - X[1:]) ** 2).mean(axis=2) * mask
    return se.sum(axis=0) / jnp.maximum(mask.sum(axis=0), 1.0)


def _loss_and_grads(w, pb, X, mask, weight, alpha, weights_too: bool):
    """Loss ``sum_i weight_i * sum_t mask * mean_D (y - x)^2`` and its gradients.

    Hand-written BPTT. Returns (loss, weight gradients or None, dL/dpb (R, P)).
    """
    d = X.shape[2]
    w_s, w_p, b_h, w_o, b_o = _split(w, d)
    s_dim = w_o.shape[1]
    IN, Hs, O = _forward(w, pb, X, alpha, keep=True)
    diff = O[:, :, :d] - X[1:]
    wm = mask * weight[None, :]                                   # (L, R)
    loss = jnp.sum((diff ** 2).mean(axis=2) * wm)
    g_y = diff * (2.0 / d) * wm[:, :, None]
    G = jnp.concatenate([g_y, jnp.zeros(g_y.shape[:2] + (s_dim - d,), X.dtype)], axis=2)
    dtO = 1.0 - O * O                      # d o / d z_o
    dtH = 1.0 - Hs * Hs                    # d h / d z_h
    w_oT = w_o.T
    w_sTm = w_s.T * _mix(alpha, d, s_dim, X.dtype)   # s_{t+1} holds o_t * mix

    def back(carry, inp):
        # carry = the part of dL/do_t that flows back from step t + 1
        g, dto, dth = inp
        go = (g + carry) * dto
        dz = (go @ w_oT) * dth
        return dz @ w_sTm, (go, dz)

    _, (GO, DZ) = jax.lax.scan(back, jnp.zeros_like(G[0]), (G, dtO, dtH), reverse=True)
    sdz = DZ.sum(axis=0)                                          # (R, H)
    g_pb = sdz @ w_p.T
    if not weights_too:
        return loss, None, g_pb
    flat = lambda a: a.reshape(-1, a.shape[-1])  # noqa: E731
    grads = {
        "w_in": jnp.concatenate([flat(IN).T @ flat(DZ), pb.T @ sdz], axis=0),
        "b_hidden": sdz.sum(axis=0),
        "w_out": flat(Hs).T @ flat(GO),
        "b_out": GO.sum(axis=(0, 1)),
    }
    return loss, grads, g_pb


def _adam(p, g, m, v, t, lr):
    m = _B1 * m + (1.0 - _B1) * g
    v = _B2 * v + (1.0 - _B2) * g * g
    step = lr * jnp.sqrt(1.0 - _B2 ** t) / (1.0 - _B1 ** t)
    return p - step * m / (jnp.sqrt(v) + _EPS), m, v


@jax.jit
def _train(w, u, X, mask, weight, epochs, lr, pb_lr, decay, warmup, clip, bound, alpha):
    zeros = jax.tree.map(jnp.zeros_like, (w, u))

    def body(i, carry):
        (w, u), (mw, mu), (vw, vu), _ = carry
        th = jnp.tanh(u)
        loss, gw, gpb = _loss_and_grads(w, bound * th, X, mask, weight, alpha, True)
        gu = gpb * bound * (1.0 - th * th)
        norm = jnp.sqrt(sum(jnp.sum(g * g) for g in jax.tree.leaves(gw)))
        scale = jnp.minimum(1.0, clip / (norm + 1e-12))
        t = (i + 1).astype(X.dtype)
        f = decay ** (i.astype(X.dtype) / epochs)
        ramp = jnp.minimum(1.0, t / jnp.maximum(warmup, 1))
        ramp = jnp.where(warmup > 0, ramp, 1.0)
        new_w, new_mw, new_vw = {}, {}, {}
        for k in w:
            new_w[k], new_mw[k], new_vw[k] = _adam(w[k], gw[k] * scale, mw[k], vw[k], t,
                                                   lr * f * ramp)
        u, mu, vu = _adam(u, gu, mu, vu, t, pb_lr * f)
        return (new_w, u), (new_mw, mu), (new_vw, vu), loss

    (w, u), _, _, loss = jax.lax.fori_loop(
        0, epochs, body, ((w, u), zeros, zeros, jnp.zeros((), X.dtype)))
    return w, u, loss


@jax.jit
def _recognize_adam(w, u, X, mask, weight, steps, lr, bound):
    """Adam on each row's PB (weights frozen): gradient descent, as in Tani's RNNPB."""
    def body(i, carry):
        u, m, v = carry
        th = jnp.tanh(u)
        _, _, gpb = _loss_and_grads(w, bound * th, X, mask, weight, 1.0, False)
        return _adam(u, gpb * bound * (1.0 - th * th), m, v, (i + 1).astype(X.dtype), lr)

    z = jnp.zeros_like(u)
    return jax.lax.fori_loop(0, steps, body, (u, z, z))[0]


@jax.jit
def _recognize_lm(w, u, X, mask, weight, steps, damping, bound):
    """Levenberg-Marquardt on each row's PB (weights frozen); returns the new ``u``.

    Every row is its own least-squares problem in ``P`` unknowns: the
    residuals ``r = sqrt(mask * weight) (y - x)`` (L, R, D) and their
    Jacobian with respect to ``u`` (P forward-mode directions through the
    closed loop) give the ``P x P`` normal equations of each row, damped by
    ``lam * diag`` (Marquardt). A step is kept only where it lowers that
    row's error; ``lam`` then shrinks, else it grows.
    """
    d = X.shape[2]
    sw = jnp.sqrt(mask * weight[None, :])[:, :, None]
    eye = jnp.eye(u.shape[1], dtype=u.dtype)

    def residuals(u):
        O = _forward(w, bound * jnp.tanh(u), X, 1.0, keep=False)
        return (O[:, :, :d] - X[1:]) * sw

    def sse(r):
        return jnp.sum(r * r, axis=(0, 2))

    def body(i, carry):
        u, lam, e = carry
        r, jvp = jax.linearize(residuals, u)
        J = jax.vmap(lambda k: jvp(jnp.broadcast_to(k, u.shape)))(eye)   # (P, L, R, D)
        A = jnp.einsum("plrd,qlrd->rpq", J, J)
        g = jnp.einsum("plrd,lrd->rp", J, r)
        damp = lam[:, None] * (jnp.diagonal(A, axis1=1, axis2=2) + LM_TINY)
        delta = -jnp.linalg.solve(A + damp[:, :, None] * eye, g[..., None])[..., 0]
        trial = jnp.clip(u + delta, -LM_U_MAX, LM_U_MAX)
        e_new = sse(residuals(trial))
        ok = e_new < e                    # False for NaN: a bad step is never kept
        return (jnp.where(ok[:, None], trial, u),
                jnp.clip(jnp.where(ok, lam * LM_DOWN, lam * LM_UP), LM_MIN, LM_MAX),
                jnp.where(ok, e_new, e))

    lam = jnp.full(u.shape[:1], damping, u.dtype)
    return jax.lax.fori_loop(0, steps, body, (u, lam, sse(residuals(u))))[0]


_errors_jit = jax.jit(_errors)


@partial(jax.jit, static_argnums=3)
def _generate(w, pb, x0, steps):
    X = jnp.zeros((steps + 1,) + x0.shape, x0.dtype).at[0].set(x0)
    return _forward(w, pb, X, 1.0, keep=False)[:, :, :x0.shape[1]]


class JaxRNNPB(RNNPBBase):
    """RNNPB (recurrent network with parametric bias) in JAX.

    Implements :class:`iloci.interfaces.PerceptualModel`; the public
    methods and their contract are documented in
    :class:`iloci.rnnpb.RNNPBBase`, the network in
    :mod:`iloci.rnnpb`.

    Parameters
    ----------
    seed : int
        Seeds the initial weights (identical to the torch back end's).
    **params
        Fields of :class:`iloci.params.RNNPBParams` (sizes, epochs, learning
        rates, ``closed_loop``, ``dtype``, ...).

    Examples
    --------
    >>> model = JaxRNNPB(seed=0, epochs=300)          # doctest: +SKIP
    >>> pbs = model.train(sequences)                  # (B, 4)
    >>> pb_obs = model.recognize([new_sequence])      # (1, 4)
    """

    backend = "jax"
    # each new batch shape costs about a second of XLA compilation, more
    # than the padded rows of a power-of-two bucket cost in recognition
    geometric_buckets = True

    def _setup(self) -> None:
        if self.params.kernel != "auto":
            raise InvalidInputError(_ONE_KERNEL.format(kernel=self.params.kernel) + ".")
        self._x64 = self.params.dtype == "float64"
        self._dtype = np.float64 if self._x64 else np.float32

    def _set_weights(self, weights: Mapping[str, np.ndarray]) -> None:
        # held in the compute dtype, like the torch back end: the float64
        # copy (for generate and prediction_error) is the same numbers
        self._w64 = {k: np.asarray(weights[k], dtype=self._dtype).astype(np.float64)
                     for k in WEIGHT_NAMES}
        self._w64_padded = _padded_weights(self._w64, self.params.pb)
        with jax.enable_x64(self._x64):
            self._w = {k: jnp.asarray(v, self._dtype) for k, v in self._w64_padded.items()}

    def _get_weights(self) -> dict[str, np.ndarray]:
        return {k: v.copy() for k, v in self._w64.items()}

    def _exact_weights(self) -> dict:
        """The padded weights in float64 (call under ``jax.enable_x64(True)``)."""
        return {k: jnp.asarray(v) for k, v in self._w64_padded.items()}

    def _cast(self, *arrays: np.ndarray) -> list:
        return [jnp.asarray(a, self._dtype) for a in arrays]

    def _train_kernel(self, X, mask, weight, u, epochs, params=None):
        p = self.params if params is None else params
        with jax.enable_x64(self._x64):
            Xj, mj, wj, uj = self._cast(X, mask, weight, u)
            w, u_new, loss = _train(self._w, uj, Xj, mj, wj, epochs, p.learning_rate,
                                    p.pb_learning_rate, p.learning_rate_decay,
                                    p.warmup_epochs, p.grad_clip,
                                    p.pb_bound, p.closed_loop)
            w = _unpadded_weights({k: np.asarray(v, dtype=np.float64) for k, v in w.items()},
                                  (p.input_size, p.hidden, p.context, p.pb))
            out = np.asarray(u_new, dtype=np.float64), float(loss)
        if not all(np.all(np.isfinite(v)) for v in w.values()):
            raise diverged_error()
        self._set_weights(w)
        return out

    def _recognize_kernel(self, X, mask, weight, u):
        p = self.params
        with jax.enable_x64(self._x64):
            Xj, mj, wj, uj = self._cast(X, mask, weight, u)
            if p.recognition_method == "adam":
                out = _recognize_adam(self._w, uj, Xj, mj, wj, p.recognition_steps,
                                      p.recognition_learning_rate, p.pb_bound)
            else:
                out = _recognize_lm(self._w, uj, Xj, mj, wj, p.recognition_steps,
                                    p.recognition_damping, p.pb_bound)
            return np.asarray(out, dtype=np.float64)

    def _error_kernel(self, X, mask, pbs, exact):
        if exact:
            with jax.enable_x64(True):
                w = self._exact_weights()
                return np.asarray(_errors_jit(w, jnp.asarray(pbs), jnp.asarray(X),
                                              jnp.asarray(mask)), dtype=np.float64)
        with jax.enable_x64(self._x64):
            pj, Xj, mj = self._cast(pbs, X, mask)
            return np.asarray(_errors_jit(self._w, pj, Xj, mj), dtype=np.float64)

    def _generate_kernel(self, pbs, x0, steps):
        with jax.enable_x64(True):
            w = self._exact_weights()
            return np.asarray(_generate(w, jnp.asarray(pbs), jnp.asarray(x0), steps),
                              dtype=np.float64)
