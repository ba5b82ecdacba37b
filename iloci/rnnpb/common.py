"""What the RNNPB back ends share: the model's definition, input checks, state format.

This module holds the definition (below), the parameters and initial
weights, and the shared front end :class:`RNNPBBase`; the input checks and
padding are in :mod:`iloci.rnnpb.inputs`, the weights' layout, the PB
reparametrisation and the state format in :mod:`iloci.rnnpb.state`, all
importable from here too.

Numpy only; the torch and JAX back ends (plugins ``iloci-torch`` and
``iloci-jax``) compute with their own libraries but agree on everything
here, so a state saved by one loads into the other and both give the same
``generate`` and ``prediction_error``. What they compute is written out in
plain numpy in :mod:`iloci.rnnpb.reference`.

The network (a Jordan-type RNN with parametric bias, Tani's RNNPB at the
paper's sizes ``D = 6`` inputs, ``C = 25`` context, ``P = 4`` PB, ``H = 60``
hidden units)::

    h_t     = tanh([x_t, c_t, pb] @ w_in + b_hidden)           (H,)
    o_t     = tanh(h_t @ w_out + b_out)                        (D + C,)
    y_t     = o_t[:D]          prediction of step t + 1 of the sequence
    c_{t+1} = o_t[D:]          next context;  c_0 = 0

A sequence ``s`` of ``T`` rows gives ``T - 1`` predictions ``y_0..y_{T-2}``
of ``s[1..T-1]``. The input is ``x_0 = s[0]`` and, for ``t >= 1``,
``x_t = a * y_{t-1} + (1 - a) * s[t]`` with ``a = closed_loop``: ``a = 1``
runs the network on its own output (closed loop), ``a = 0`` feeds it the
true previous step (teacher forcing). The *prediction error* of a sequence
is the mean over its ``T - 1`` steps and ``D`` features of the squared
difference between ``y_t`` and ``s[t + 1]``, always closed loop (``a = 1``).

Why closed loop: trained teacher-forced, the next delta of a smooth motion
is almost the current one, so the network predicts well without looking at
its PB and the PB carries no shape (PB nearest-neighbour accuracy ~17 % on
LASA). Fed its own output, the network can only reproduce a sequence from
the initial step, the context and the PB, so the PB must encode the shape.

PB vectors are kept bounded by a reparametrisation: the optimisers move an
unconstrained ``u`` and ``pb = pb_bound * tanh(u)``, so every PB lies in
``(-pb_bound, pb_bound)`` without clipping (which would stall gradients).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import fields, replace
from typing import Any

import numpy as np

from iloci.errors import IlociError, InvalidInputError
from iloci.params import RNNPBParams
# input checks and padding, the weights' layout and the state: their own
# modules, re-exported here (``from iloci.rnnpb.common import ...`` keeps working)
from iloci.rnnpb.inputs import (bucket, check_generate_args, check_pbs, check_sequences,
                                pad_sequences)
from iloci.rnnpb.state import (FORMAT, FORMAT_VERSION, WEIGHT_NAMES, make_state, pb_to_u,
                               read_state, u_to_pb, weight_shapes)
from iloci.validation import is_integer

__all__ = [
    "FORMAT", "FORMAT_VERSION", "WEIGHT_NAMES", "make_params", "weight_shapes", "init_weights",
    "check_sequences", "pad_sequences", "bucket", "check_pbs", "check_generate_args",
    "pb_to_u", "u_to_pb", "make_state", "read_state", "best_starts", "diverged_error",
    "RNNPBBase", "LM_DOWN", "LM_UP", "LM_MIN", "LM_MAX", "LM_TINY", "LM_U_MAX",
]


def make_params(**kwargs: Any) -> RNNPBParams:
    """An :class:`RNNPBParams` from keyword arguments, checked.

    Raises
    ------
    InvalidInputError
        An unknown name or an out-of-range value.
    """
    known = {f.name for f in fields(RNNPBParams)}
    unknown = sorted(set(kwargs) - known)
    if unknown:
        raise InvalidInputError(f"unknown RNNPB parameter(s) {', '.join(unknown)}; valid "
                                f"ones are {', '.join(sorted(known))}.")
    try:
        params = RNNPBParams(**kwargs)
        params.validate()
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"invalid RNNPB parameters: {exc}.") from None
    return params


def init_weights(params: RNNPBParams, seed: int) -> dict[str, np.ndarray]:
    """Fresh weights, the same for every back end given the same seed.

    Uniform in ``+-init_scale / sqrt(fan_in)`` (the usual scale for dense
    layers), biases included.

    Returns
    -------
    dict of str to ndarray (float64)
    """
    rng = np.random.default_rng(np.random.SeedSequence(int(seed)))
    shapes = weight_shapes(params.input_size, params.hidden, params.context, params.pb)
    fan_in = {"w_in": shapes["w_in"][0], "b_hidden": shapes["w_in"][0],
              "w_out": params.hidden, "b_out": params.hidden}
    out = {}
    for name in WEIGHT_NAMES:
        k = params.init_scale / np.sqrt(fan_in[name])
        out[name] = rng.uniform(-k, k, size=shapes[name])
    return out


# -- recognition -------------------------------------------------------------

#: Levenberg-Marquardt damping of recognition, shared by the back ends: the
#: damping shrinks by LM_DOWN after a step that lowers a sequence's error and
#: grows by LM_UP after one that does not, within [LM_MIN, LM_MAX]; LM_TINY
#: keeps the normal equations of an all-padding row (all zeros) regular.
LM_DOWN, LM_UP, LM_MIN, LM_MAX, LM_TINY = 0.3, 4.0, 1e-9, 1e9, 1e-12
#: Steps keep ``|u| <= LM_U_MAX`` (``|pb| <= 0.999 pb_bound``, as
#: :func:`pb_to_u`): where ``tanh`` saturates the Jacobian vanishes and a
#: Gauss-Newton step could throw ``u`` to where ``tanh(u)`` rounds to 1.
LM_U_MAX = float(np.arctanh(0.999))

def diverged_error() -> IlociError:
    """The error every back end raises when a training leaves non-finite weights."""
    return IlociError("training diverged (non-finite weights); lower learning_rate "
                      "or grad_clip. The model was left unchanged.")


def best_starts(errors: np.ndarray, n: int) -> np.ndarray:
    """Indices of the ``n`` lowest errors per row (ties: lower index first).

    Parameters
    ----------
    errors : ndarray, shape (B, K)
        Prediction error of each sequence under each candidate PB.

    Returns
    -------
    ndarray of int, shape (B, min(n, K))
    """
    return np.argsort(errors, axis=1, kind="stable")[:, :min(n, errors.shape[1])]


# -- the shared front end of both back ends ------------------------------------

class RNNPBBase:
    """The public side of an RNNPB back end: checks, batching, multi-start, state.

    A back end (``TorchRNNPB``, ``JaxRNNPB``) inherits this and supplies the
    numeric kernels below, working on padded, time-major numpy arrays; so
    both back ends check inputs, pad, bucket, choose recognition starts and
    save state in exactly the same way, and differ only in arithmetic.

    Parameters
    ----------
    seed : int
        Seeds the initial weights (the same weights in every back end).
        Training and recognition are full-batch and deterministic.
    **params
        Fields of :class:`iloci.params.RNNPBParams`.

    Attributes
    ----------
    input_size : int
        ``D``.
    pb_size : int
        ``P``.
    params : RNNPBParams
    pbs_ : ndarray, shape (K, P)
        PBs learned by the last :meth:`train` (or restored by
        :meth:`load_state`); the default starts of :meth:`recognize`.
    train_loss_ : float
        Training loss (mean squared error, at the training's ``closed_loop``)
        after the last epoch of the last :meth:`train`.
    """

    #: Name of the back end, stored in ``state()["backend"]``.
    backend = "numpy"
    #: Sequences are padded to a multiple of this many rows so compiled
    #: kernels are reused as the memory grows one entry at a time.
    batch_multiple = 4
    #: Pad to ``batch_multiple`` times a power of two instead (for back ends
    #: whose compilation costs more than the padded rows); recognition,
    #: scoring and generation only, training always pads to the next multiple.
    geometric_buckets = False
    #: Most rows scored at once when ranking candidate PBs.
    score_chunk = 8192

    def __init__(self, *, seed: int = 0, **params: Any) -> None:
        if not is_integer(seed):
            raise InvalidInputError(f"seed must be an integer, got {seed!r}.")
        self.params = make_params(**params)
        self.seed = int(seed)
        self._setup()
        self._set_weights(init_weights(self.params, self.seed))
        self.pbs_ = np.zeros((0, self.params.pb))
        self.train_loss_ = float("nan")

    @property
    def input_size(self) -> int:
        return self.params.input_size

    @property
    def pb_size(self) -> int:
        return self.params.pb

    def __repr__(self) -> str:
        p = self.params
        return (f"{type(self).__name__}(D={p.input_size}, H={p.hidden}, C={p.context}, "
                f"P={p.pb}, dtype={p.dtype}, seed={self.seed}, stored_pbs={len(self.pbs_)})")

    # -- kernels a back end supplies -------------------------------------------

    def _setup(self) -> None:
        """(Re)build whatever depends on ``self.params`` (sizes, dtype)."""

    def _set_weights(self, weights: Mapping[str, np.ndarray]) -> None:
        raise NotImplementedError

    def _get_weights(self) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def _train_kernel(self, X: np.ndarray, mask: np.ndarray, weight: np.ndarray,
                      u: np.ndarray, epochs: int, params: RNNPBParams | None = None
                      ) -> tuple[np.ndarray, float]:
        """Full-batch Adam on weights and PBs; returns the new ``u`` and final loss.

        ``X`` (T, R, D), ``mask`` (T - 1, R), ``weight`` (R,) per-sequence
        factor of the loss (``1 / (T_i - 1) / B``, 0 for padding rows),
        ``u`` (R, P). ``params``: this call's settings (:meth:`train`'s
        ``learning_rate`` in place), ``self.params`` when ``None``. Updates
        the weights in place.
        """
        raise NotImplementedError

    def _recognize_kernel(self, X: np.ndarray, mask: np.ndarray, weight: np.ndarray,
                          u: np.ndarray) -> np.ndarray:
        """Refine ``u`` (R, P), weights frozen, closed loop; returns the new ``u``.

        ``recognition_steps`` steps of ``recognition_method`` minimising each
        row's ``sum_t mask * weight * sum_D (y - x)^2``: Levenberg-Marquardt
        (damping from ``recognition_damping``, adapted per row, ``LM_*``) or
        Adam (``recognition_learning_rate``).
        """
        raise NotImplementedError

    def _train_multiple(self) -> int:
        """Rows :meth:`train` pads its batch to a multiple of (``batch_multiple``).

        A back end whose training kernel compiles nothing per shape returns
        1: padded rows cost as much as real ones in every epoch.
        """
        return self.batch_multiple

    def _error_kernel(self, X: np.ndarray, mask: np.ndarray, pbs: np.ndarray,
                      exact: bool) -> np.ndarray:
        """Closed-loop prediction error per row (R,); float64 when ``exact``."""
        raise NotImplementedError

    def _generate_kernel(self, pbs: np.ndarray, x0: np.ndarray, steps: int) -> np.ndarray:
        """Closed-loop outputs ``y_0..y_{steps-1}``, shape (steps, B, D), float64."""
        raise NotImplementedError

    # -- public API ------------------------------------------------------------

    def _padded(self, seqs: list[np.ndarray], geometric: bool | None = None,
                multiple: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        geometric = self.geometric_buckets if geometric is None else geometric
        rows = bucket(len(seqs), self.batch_multiple if multiple is None else multiple,
                      geometric)
        X, mask = pad_sequences(seqs, rows)
        steps = mask.sum(axis=0)
        per_seq = np.divide(1.0, steps, out=np.zeros(rows), where=steps > 0)
        return X, mask, per_seq

    def train(self, sequences: Sequence[np.ndarray], pbs_init: np.ndarray | None = None,
              epochs: int | None = None, *, learning_rate: float | None = None
              ) -> np.ndarray:
        """Train the weights and one PB per sequence, continuing from the current weights.

        Full-batch Adam (``learning_rate`` for weights, or the argument of
        that name for this call; ``pb_learning_rate`` for PBs) on the mean
        over sequences of each sequence's mean squared
        prediction error, run at ``closed_loop`` (1: the network's own
        output is its next input), back-propagated through time over every
        sequence at once (different lengths are masked). The weight
        gradient's global norm is clipped to ``grad_clip``. Adam's moments
        start afresh at each call; the weights do not.

        Parameters
        ----------
        sequences : list of ndarray, each (T_i, D), T_i >= 2
        pbs_init : ndarray, shape (B, P), optional
            Starting PBs (e.g. the stored PBs of rehearsed entries); zeros
            when omitted. Pulled inside ``(-pb_bound, pb_bound)``.
        epochs : int, optional
            Full-batch steps; defaults to ``params.epochs``. 0 leaves the
            model unchanged.
        learning_rate : float, optional
            The weights' Adam learning rate of this call only, in place of
            ``params.learning_rate`` (which is left as it is): the memory's
            rehearsal passes ``params.rehearsal_learning_rate`` here
            (:func:`iloci.concepts.rehearsal.rehearse`). Every back end
            reads it as it reads ``params.learning_rate``: the same result
            as a model built with that ``learning_rate``.

        Returns
        -------
        ndarray, shape (B, P)
            The learned PB of each sequence (also kept as :attr:`pbs_`).

        Raises
        ------
        InvalidInputError
            Empty list, NaN or inf, wrong width, a sequence shorter than 2
            steps, ``pbs_init`` of the wrong shape, negative ``epochs``, a
            ``learning_rate`` that is not a number > 0.
        """
        seqs = check_sequences(sequences, self.input_size)
        b = len(seqs)
        if pbs_init is None:
            pbs0 = np.zeros((b, self.pb_size))
        else:
            pbs0 = check_pbs(pbs_init, b, self.pb_size, "pbs_init")
        n = self.params.epochs if epochs is None else epochs
        if not is_integer(n) or n < 0:
            raise InvalidInputError(f"epochs must be an integer >= 0, got {epochs!r}.")
        params = self.params
        if learning_rate is not None:
            if (isinstance(learning_rate, bool)
                    or not isinstance(learning_rate, (int, float, np.integer, np.floating))
                    or not 0 < float(learning_rate) < float("inf")):
                raise InvalidInputError(f"learning_rate must be a number > 0, got "
                                        f"{learning_rate!r}.")
            params = replace(params, learning_rate=float(learning_rate))
        # training pads to the next multiple only: its cost grows with the
        # padded rows over every epoch, which outweighs a compilation
        X, mask, per_seq = self._padded(seqs, geometric=False, multiple=self._train_multiple())
        u = np.zeros((X.shape[1], self.pb_size))
        u[:b] = pb_to_u(pbs0, self.params.pb_bound)
        if n > 0:
            u, self.train_loss_ = self._train_kernel(X, mask, per_seq / b, u, int(n), params)
        pbs = u_to_pb(u[:b], self.params.pb_bound)
        self.pbs_ = pbs.copy()
        return pbs

    def _score(self, seqs: list[np.ndarray], cands: np.ndarray) -> np.ndarray:
        """Prediction error (compute dtype) of every sequence under every candidate, (B, K)."""
        b, k = len(seqs), len(cands)
        out = np.empty((b, k))
        per = max(1, self.score_chunk // k)
        for lo in range(0, b, per):
            part = seqs[lo:lo + per]
            X, mask, _ = self._padded(part)
            rows = bucket(len(part) * k, self.batch_multiple, self.geometric_buckets)
            Xr = np.zeros((X.shape[0], rows, X.shape[2]))
            mr = np.zeros((mask.shape[0], rows))
            pr = np.zeros((rows, self.pb_size))
            Xr[:, :len(part) * k] = np.repeat(X[:, :len(part)], k, axis=1)
            mr[:, :len(part) * k] = np.repeat(mask[:, :len(part)], k, axis=1)
            pr[:len(part) * k] = np.tile(cands, (len(part), 1))
            err = self._error_kernel(Xr, mr, pr, exact=False)
            out[lo:lo + len(part)] = err[:len(part) * k].reshape(len(part), k)
        return out

    def recognize(self, sequences: Sequence[np.ndarray],
                  candidate_pbs: np.ndarray | None = None) -> np.ndarray:
        """Find the PB of each sequence, the weights frozen (PB_obs / PB_rec).

        Multi-start: every candidate PB (``candidate_pbs``, else the stored
        :attr:`pbs_`, plus the zero PB) is scored by its closed-loop
        prediction error on the sequence; the ``recognition_starts`` best
        are refined by ``recognition_steps`` steps of ``recognition_method``
        on the PB, all sequences and starts in one batch; each sequence gets
        the refined PB with the lowest prediction error. Starting from zero
        alone stalls in local minima.

        ``"lm"``, Levenberg-Marquardt (initial damping
        ``recognition_damping``): each sequence's PB is a least-squares
        problem in only ``P`` unknowns, so the ``P`` forward-mode
        derivatives of the residuals and a ``P x P`` solve per sequence give
        a Gauss-Newton step; 10 such steps reach the prediction error of
        200 Adam steps at about a sixth of the arithmetic. ``"adam"``:
        gradient descent on the PB (back-propagation as in Tani's RNNPB; the
        paper does not say), ``recognition_learning_rate``. From a single start
        LM stops in the nearest local minimum where Adam's momentum may carry
        on; from the default starts both reach the same errors.

        Parameters
        ----------
        sequences : list of ndarray, each (T_i, D), T_i >= 2
        candidate_pbs : ndarray, shape (K, P), optional
            Known PBs to start from (e.g. the PBs of the memory's entries).

        Returns
        -------
        ndarray, shape (B, P)

        Raises
        ------
        InvalidInputError
            Bad sequences (see :meth:`train`) or candidates not (K, P).
        """
        seqs = check_sequences(sequences, self.input_size)
        if candidate_pbs is None:
            cands = self.pbs_
        else:
            cands = check_pbs(candidate_pbs, None, self.pb_size, "candidate_pbs")
        bound = self.params.pb_bound
        # candidates live in the bounded PB space; the zero PB is the
        # neutral start and costs one column
        cands = np.clip(np.vstack([cands, np.zeros((1, self.pb_size))]),
                        -0.999 * bound, 0.999 * bound)
        b = len(seqs)
        idx = best_starts(self._score(seqs, cands), self.params.recognition_starts)
        n = idx.shape[1]
        starts = cands[idx].reshape(b * n, self.pb_size)
        rep = [s for s in seqs for _ in range(n)]
        X, mask, per_seq = self._padded(rep)
        u = np.zeros((X.shape[1], self.pb_size))
        u[:b * n] = pb_to_u(starts, bound)
        if self.params.recognition_steps > 0:
            u = self._recognize_kernel(X, mask, per_seq, u)
        pbs = u_to_pb(u[:b * n], bound)
        err = self._error_kernel(X, mask, np.vstack([pbs, np.zeros((len(u) - b * n,
                                                                    self.pb_size))]),
                                 exact=False)[:b * n].reshape(b, n)
        best = np.argmin(err, axis=1)
        return pbs.reshape(b, n, self.pb_size)[np.arange(b), best].copy()

    def generate(self, pbs: np.ndarray, initial_inputs: np.ndarray,
                 lengths: Sequence[int]) -> list[np.ndarray]:
        """Run the network closed-loop from each PB (float64).

        Parameters
        ----------
        pbs : ndarray, shape (B, P)
        initial_inputs : ndarray, shape (B, D)
            First step of each sequence (the paper's initialInfo).
        lengths : sequence of int, length B
            Steps ``T_i >= 1`` to produce, the first being the initial input.

        Returns
        -------
        list of ndarray, each (T_i, D)
        """
        p, x0, lens = check_generate_args(pbs, initial_inputs, lengths, self.input_size,
                                          self.pb_size)
        steps = max(lens) - 1
        if steps == 0:
            return [x0[i:i + 1].copy() for i in range(len(p))]
        # padded to a bucket, like training, so compiled kernels are reused
        rows = bucket(len(p), self.batch_multiple, self.geometric_buckets)
        pr = np.zeros((rows, self.pb_size))
        xr = np.zeros((rows, self.input_size))
        pr[:len(p)], xr[:len(p)] = p, x0
        Y = self._generate_kernel(pr, xr, steps)[:, :len(p)]
        full = np.concatenate([x0[None], Y], axis=0)
        return [np.ascontiguousarray(full[:n, i]) for i, n in enumerate(lens)]

    def prediction_error(self, sequences: Sequence[np.ndarray], pbs: np.ndarray) -> np.ndarray:
        """Closed-loop prediction error of each sequence under its PB (float64).

        The network starts from the sequence's first step and runs on its
        own output; the error is the mean over the ``T_i - 1`` predicted
        steps and ``D`` features of the squared difference.

        Parameters
        ----------
        sequences : list of ndarray, each (T_i, D), T_i >= 2
        pbs : ndarray, shape (B, P)

        Returns
        -------
        ndarray, shape (B,)
        """
        seqs = check_sequences(sequences, self.input_size)
        p = check_pbs(pbs, len(seqs), self.pb_size)
        X, mask, _ = self._padded(seqs)
        pr = np.zeros((X.shape[1], self.pb_size))
        pr[:len(p)] = p
        return self._error_kernel(X, mask, pr, exact=True)[:len(seqs)].copy()

    def state(self) -> dict[str, np.ndarray]:
        """Weights, stored PBs and settings as a flat dict of numpy arrays (no pickle).

        Loads into either back end (see :func:`make_state` for the keys).
        """
        return make_state(self.params, self._get_weights(), self.pbs_, self.backend)

    def load_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Restore what :meth:`state` returned, from this or the other back end.

        The state's sizes and settings replace this model's (except
        ``dtype``).

        Raises
        ------
        InvalidInputError
            Not an RNNPB state, a newer version, or inconsistent arrays.
        """
        weights, pbs, params = read_state(state, self.params)
        if params != self.params:
            self.params = params
            self._setup()
        self._set_weights(weights)
        self.pbs_ = pbs.copy()
