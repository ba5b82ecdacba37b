"""The RNNPB in plain numpy: the reference every back end and kernel is tested against.

The network and its training as iloci defines them (:mod:`iloci.rnnpb.common`
states the model), written for clarity, not speed: the forward pass, the
closed-loop loss, back-propagation through time, gradient clipping, the
learning-rate schedule (warm-up, decay) and Adam on the weights and the PBs.
The torch operations and the native C kernel of ``torch-rnnpb`` and the XLA
program of ``jax-rnnpb`` compute exactly this, step by step, in their own
arithmetic; the tests train each of them and :func:`train` from the same
start and compare (float64 to 1e-10, float32 to 1e-4 after 5 epochs).
``native-rnnpb``'s float32 kernel is compared bit for bit with
``train(..., dtype="float32")``, which states its order of operations
(:mod:`iloci.rnnpb.float32`). A change to the recipe starts here.

One training epoch (full batch, ``t = 1 .. epochs``)::

    pb      = bound tanh(u)                                   (R, P)
    loss    = sum_{t, r} mw[t, r] mean_D (y_t - x_{t+1})^2    closed_loop a
    g, g_u  = d loss / d weights, d loss / d u                  (BPTT)
    g       = g min(1, grad_clip / (|g| + 1e-12))             global norm
    f       = learning_rate_decay ** ((t - 1) / epochs)       decay
    ramp    = min(1, t / warmup_epochs)    (1 without warm-up)
    weights = adam(weights, g,   lr = learning_rate f ramp)
    u       = adam(u,       g_u, lr = pb_learning_rate f)

``mw`` is the mask of steps to score times each sequence's weight (the back
ends use ``1 / (T_i - 1) / B``: the mean over sequences of each one's mean
squared error). Adam is Kingma & Ba (2015), Algorithm 1, with the bias
corrections folded into the step size (their Section 2's last paragraph):
``step = lr sqrt(1 - beta2^t) / (1 - beta1^t)``, ``p -= step m / (sqrt(v) + eps)``,
``beta1 = 0.9``, ``beta2 = 0.999``, ``eps = 1e-8``; its moments start at zero
each call.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from iloci.errors import InvalidInputError
from iloci.params import RNNPBParams
from iloci.rnnpb.common import WEIGHT_NAMES, pad_sequences
from iloci.rnnpb.float32 import train as train_float32

__all__ = [
    "ADAM_BETA1",
    "ADAM_BETA2",
    "ADAM_EPS",
    "reference_outputs",
    "reference_prediction_error",
    "reference_generate",
    "loss_and_gradients",
    "learning_rates",
    "adam_step",
    "TrainResult",
    "train",
]

#: Adam's hyper-parameters (Kingma & Ba 2015, the defaults they recommend).
ADAM_BETA1, ADAM_BETA2, ADAM_EPS = 0.9, 0.999, 1e-8


# -- the forward pass ----------------------------------------------------------

def reference_outputs(weights: Mapping[str, np.ndarray], pbs: np.ndarray, X: np.ndarray,
                      closed_loop: float = 1.0) -> np.ndarray:
    """Predictions of the network, plain numpy: the model's definition in code.

    Parameters
    ----------
    weights : dict of ndarray
        As :func:`init_weights` returns.
    pbs : ndarray, shape (B, P)
    X : ndarray, shape (T, B, D)
        Padded sequences (time-major).
    closed_loop : float
        ``a`` of the module docstring.

    Returns
    -------
    ndarray, shape (T - 1, B, D)
        ``y_t``, the prediction of ``X[t + 1]``.
    """
    d = X.shape[2]
    w_in, w_out = weights["w_in"], weights["w_out"]
    c = np.zeros((X.shape[1], w_out.shape[1] - d))
    pre = pbs @ w_in[d + c.shape[1]:] + weights["b_hidden"]
    x = X[0]
    ys = []
    for t in range(X.shape[0] - 1):
        h = np.tanh(np.hstack([x, c]) @ w_in[:d + c.shape[1]] + pre)
        o = np.tanh(h @ w_out + weights["b_out"])
        y, c = o[:, :d], o[:, d:]
        ys.append(y)
        x = closed_loop * y + (1.0 - closed_loop) * X[t + 1]
    return np.stack(ys)


def reference_prediction_error(weights: Mapping[str, np.ndarray],
                               sequences: Sequence[np.ndarray], pbs: np.ndarray) -> np.ndarray:
    """Closed-loop prediction error per sequence (numpy reference), shape (B,)."""
    X, mask = pad_sequences(sequences)
    Y = reference_outputs(weights, pbs, X)
    se = ((Y - X[1:]) ** 2).mean(axis=2) * mask
    return se.sum(axis=0) / mask.sum(axis=0)


def reference_generate(weights: Mapping[str, np.ndarray], pbs: np.ndarray,
                       initial_inputs: np.ndarray, lengths: Sequence[int]) -> list[np.ndarray]:
    """Closed-loop generation (numpy reference); list of (T_i, D) arrays."""
    t_max = max(lengths)
    X = np.zeros((t_max, len(pbs), initial_inputs.shape[1]))
    X[0] = initial_inputs
    Y = reference_outputs(weights, pbs, X)
    full = np.concatenate([X[:1], Y], axis=0)
    return [full[:n, i].copy() for i, n in enumerate(lengths)]


# -- one training step -----------------------------------------------------------

def loss_and_gradients(weights: Mapping[str, np.ndarray], u: np.ndarray, X: np.ndarray,
                       mw: np.ndarray, closed_loop: float, bound: float
                       ) -> tuple[float, dict[str, np.ndarray], np.ndarray]:
    """Training loss and its gradients by back-propagation through time.

    Parameters
    ----------
    weights : dict of ndarray
        ``w_in`` (D + C + P, H), ``b_hidden`` (H,), ``w_out`` (H, D + C),
        ``b_out`` (D + C,).
    u : ndarray, shape (R, P)
        Unconstrained PB parameters, ``pb = bound tanh(u)``.
    X : ndarray, shape (T, R, D)
        Padded sequences, time-major.
    mw : ndarray, shape (T - 1, R)
        Mask times each row's loss weight.
    closed_loop : float
        ``a``: input ``x_t = a y_{t-1} + (1 - a) X[t]`` for ``t >= 1``.
    bound : float
        ``pb_bound``.

    Returns
    -------
    loss : float
        ``sum_{t, r} mw[t, r] mean_D (y_t - X[t + 1])^2``.
    grads : dict of ndarray
        d loss / d weight, shaped like ``weights``.
    g_u : ndarray, shape (R, P)
        d loss / d u.
    """
    d = X.shape[2]
    w_in, w_out = weights["w_in"], weights["w_out"]
    s_width = w_out.shape[1]                      # D + C
    w_s, w_p = w_in[:s_width], w_in[s_width:]
    L, R = X.shape[0] - 1, X.shape[1]
    th = np.tanh(u)
    pb = bound * th
    pre = pb @ w_p + weights["b_hidden"]
    # s_t: the state entering step t; s_{t+1} = o_t mix + (1 - a) [X[t+1], 0]
    mix = np.ones(s_width)
    mix[:d] = closed_loop
    S = np.zeros((L, R, s_width))
    H = np.zeros((L, R, w_in.shape[1]))
    O = np.zeros((L, R, s_width))
    S[0, :, :d] = X[0]
    for t in range(L):
        H[t] = np.tanh(S[t] @ w_s + pre)
        O[t] = np.tanh(H[t] @ w_out + weights["b_out"])
        if t + 1 < L:
            S[t + 1] = O[t] * mix
            S[t + 1, :, :d] += (1.0 - closed_loop) * X[t + 1]
    diff = O[:, :, :d] - X[1:]
    loss = float(np.sum(mw[:, :, None] * diff ** 2) / d)
    # backward: G_t = d loss / d o_t, its share through s_{t+1} added on the way
    G = np.zeros_like(O)
    G[:, :, :d] = 2.0 / d * mw[:, :, None] * diff
    DZ = np.zeros_like(H)
    for t in range(L - 1, -1, -1):
        go = G[t] * (1.0 - O[t] ** 2)             # d loss / d (pre-activation of o_t)
        G[t] = go
        DZ[t] = (go @ w_out.T) * (1.0 - H[t] ** 2)
        if t > 0:
            G[t - 1] += (DZ[t] @ w_s.T) * mix
    sdz = DZ.sum(axis=0)                          # (R, H): pre is the same every step
    grads = {
        "w_in": np.vstack([np.einsum("trs,trh->sh", S, DZ), pb.T @ sdz]),
        "b_hidden": sdz.sum(axis=0),
        "w_out": np.einsum("trh,trs->hs", H, G),
        "b_out": G.sum(axis=(0, 1)),
    }
    g_u = (sdz @ w_p.T) * bound * (1.0 - th ** 2)
    return loss, grads, g_u


def learning_rates(params: RNNPBParams, t: int, epochs: int) -> tuple[float, float]:
    """Learning rates of the weights and of the PBs at epoch ``t`` (1-based) of ``epochs``.

    ``learning_rate_decay ** ((t - 1) / epochs)`` for both; the weights'
    also ramp up linearly over ``warmup_epochs``.
    """
    f = params.learning_rate_decay ** ((t - 1) / epochs)
    ramp = min(1.0, t / params.warmup_epochs) if params.warmup_epochs else 1.0
    return params.learning_rate * f * ramp, params.pb_learning_rate * f


def adam_step(p: np.ndarray, g: np.ndarray, m: np.ndarray, v: np.ndarray, t: int,
              lr: float) -> None:
    """One Adam update of ``p`` in place (moments ``m``, ``v`` too); ``t`` 1-based."""
    m *= ADAM_BETA1
    m += (1.0 - ADAM_BETA1) * g
    v *= ADAM_BETA2
    v += (1.0 - ADAM_BETA2) * g * g
    step = lr * (1.0 - ADAM_BETA2 ** t) ** 0.5 / (1.0 - ADAM_BETA1 ** t)
    p -= step * m / (np.sqrt(v) + ADAM_EPS)


@dataclass
class TrainResult:
    """What :func:`train` returns.

    Attributes
    ----------
    weights : dict of ndarray
    u : ndarray, shape (R, P)
    loss : float
        Loss of the last epoch (computed before its update), as the back
        ends report it in ``train_loss_``.
    losses : ndarray, shape (epochs,)
        Loss of every epoch.
    """

    weights: dict[str, np.ndarray]
    u: np.ndarray
    loss: float
    losses: np.ndarray


def train(weights: Mapping[str, np.ndarray], u: np.ndarray, X: np.ndarray, mw: np.ndarray,
          params: RNNPBParams, epochs: int, dtype: str = "float64") -> TrainResult:
    """Full-batch training, the recipe of the module docstring (float64, or float32).

    What a back end's ``_train_kernel`` computes: the same arguments (``mw``
    is its ``mask * weight``), the same order of updates. The inputs are not
    modified. ``dtype="float32"``: the recipe in float32 in the order of
    operations of native-rnnpb's C kernel (:mod:`iloci.rnnpb.float32`, the
    specification of that arithmetic): the same bits as the kernel on every
    instruction set; the arrays returned are float32.

    Parameters
    ----------
    weights : dict of ndarray
    u : ndarray, shape (R, P)
    X : ndarray, shape (T, R, D)
    mw : ndarray, shape (T - 1, R)
    params : RNNPBParams
        ``learning_rate``, ``pb_learning_rate``, ``learning_rate_decay``,
        ``warmup_epochs``, ``grad_clip``, ``pb_bound``, ``closed_loop``.
    epochs : int

    Returns
    -------
    TrainResult

    Raises
    ------
    InvalidInputError
        ``dtype`` is neither ``"float64"`` nor ``"float32"``.
    """
    if dtype == "float32":
        w32, u32, loss32, losses32 = train_float32(weights, u, X, mw, params, epochs)
        return TrainResult(w32, u32, loss32, losses32)
    if dtype != "float64":
        raise InvalidInputError(f"dtype must be 'float64' or 'float32', got {dtype!r}.")
    w = {k: np.array(weights[k], dtype=np.float64) for k in WEIGHT_NAMES}
    u = np.array(u, dtype=np.float64)
    mom = {k: (np.zeros_like(w[k]), np.zeros_like(w[k])) for k in WEIGHT_NAMES}
    mu, vu = np.zeros_like(u), np.zeros_like(u)
    losses = np.zeros(epochs)
    for t in range(1, epochs + 1):
        loss, g, g_u = loss_and_gradients(w, u, X, mw, params.closed_loop, params.pb_bound)
        losses[t - 1] = loss
        norm = np.sqrt(sum(float(np.sum(g[k] ** 2)) for k in WEIGHT_NAMES))
        scale = min(1.0, params.grad_clip / (norm + 1e-12))
        lr_w, lr_pb = learning_rates(params, t, epochs)
        for k in WEIGHT_NAMES:
            adam_step(w[k], g[k] * scale, *mom[k], t, lr_w)
        adam_step(u, g_u, mu, vu, t, lr_pb)
    return TrainResult(w, u, float(losses[-1]) if epochs else float("nan"), losses)
