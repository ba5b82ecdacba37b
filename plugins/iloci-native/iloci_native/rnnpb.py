"""native-rnnpb: the RNNPB with its float32 training and recognition in a C kernel, numpy elsewhere.

The model is defined in :mod:`iloci.rnnpb`. Float32 training (every epoch in
one call), Levenberg-Marquardt recognition and the scoring of candidate PBs
run in ``_native.c``, which computes one float32 arithmetic on every
instruction set (AVX-512, AVX2, portable C; NEON on aarch64): the same seed
gives bit-identical networks, PBs and recognitions on any CPU ("The float32
arithmetic" in ``_native.c`` defines it; the tests force each instruction set
and compare bit for bit). Figures: ``benchmarks/results/rnnpb_speed.json``.

Generation and :meth:`prediction_error` (float64 by contract) run the
kernel's float64 code, in the one order of :mod:`iloci.rnnpb.float64`:
the same bits on every CPU. Everything else runs the numpy reference
(:mod:`iloci.rnnpb.reference`, in float64): ``dtype = "float64"``, sizes
beyond the kernel (more than 256 hidden or state units), an install
without a C compiler (generation too), Adam recognition
(``recognition_method = "adam"``). A model built on the reference says so
once, as a :class:`NativeFallbackWarning`. The reference uses numpy's
BLAS, whose last bits may differ between CPUs.

No torch: the plugin needs numpy and, to build the kernel, a C compiler.
"""

from __future__ import annotations

from collections.abc import Mapping
import ctypes
import warnings

import numpy as np

from iloci.errors import IlociError
from iloci.rnnpb import (LM_DOWN, LM_MAX, LM_MIN, LM_TINY, LM_U_MAX, LM_UP,
                         WEIGHT_NAMES, RNNPBBase, diverged_error)
from iloci.rnnpb.reference import adam_step, loss_and_gradients, reference_outputs, train
from iloci_native.native import (ISAS, NATIVE_CODES, NATIVE_WIDTH_MAX, RecognizeArgs,
                                 TrainArgs, kernel_info, native_lib, requested_isa)

__all__ = ["NativeRNNPB", "NativeFallbackWarning"]


class NativeFallbackWarning(UserWarning):
    """A native-rnnpb model runs the numpy reference, not the C kernel (said once per model)."""


def _f32(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32)


def _residuals_and_jacobian(w: Mapping[str, np.ndarray], u: np.ndarray, bound: float,
                            X: np.ndarray, sw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closed-loop residuals ``r`` (L, R, D) and ``J = dr/du`` (L, P, R, D), float64.

    ``pb = bound tanh(u)``; ``sw`` (L, R) scales each step's residual. The
    derivatives along each of the ``P`` coordinates of ``u`` are carried
    through the steps (forward mode), as torch-rnnpb and the C kernel do.
    """
    d = X.shape[2]
    S = w["w_out"].shape[1]
    w_s, w_p, w_o = w["w_in"][:S], w["w_in"][S:], w["w_out"]
    L, R = X.shape[0] - 1, X.shape[1]
    P = u.shape[1]
    th = np.tanh(u)
    pre = bound * th @ w_p + w["b_hidden"]
    dpre = (bound * (1.0 - th * th)).T[:, :, None] * w_p[:, None, :]       # (P, R, H)
    s = np.zeros((R, S))
    s[:, :d] = X[0]
    ds = np.zeros((P, R, S))                       # d s_0 / du = 0: s_0 is the data
    r = np.empty((L, R, d))
    J = np.empty((L, P, R, d))
    for t in range(L):
        h = np.tanh(s @ w_s + pre)
        o = np.tanh(h @ w_o + w["b_out"])
        dh = (ds @ w_s + dpre) * (1.0 - h * h)
        do = (dh @ w_o) * (1.0 - o * o)
        r[t] = (o[:, :d] - X[t + 1]) * sw[t][:, None]
        J[t] = do[:, :, :d] * sw[t][None, :, None]
        s, ds = o, do
    return r, J


def _solve(A: np.ndarray, g: np.ndarray) -> np.ndarray:
    """``A[r]^-1 g[r]`` per row; NaN where a system is singular (the step is then rejected)."""
    try:
        return np.linalg.solve(A, g[:, :, None])[:, :, 0]
    except np.linalg.LinAlgError:
        out = np.full_like(g, np.nan)
        for i in range(len(g)):
            try:
                out[i] = np.linalg.solve(A[i], g[i])
            except np.linalg.LinAlgError:
                pass
        return out


class NativeRNNPB(RNNPBBase):
    """RNNPB (recurrent network with parametric bias), float32 in a C kernel.

    Implements :class:`iloci.interfaces.PerceptualModel`; the public
    methods and their contract are documented in
    :class:`iloci.rnnpb.RNNPBBase`, the network in :mod:`iloci.rnnpb`.
    Single-threaded.

    Float32 training, Levenberg-Marquardt recognition and candidate scoring
    run in the native kernel (``_native.c``) in the widest instruction set
    the CPU has (AVX-512, AVX2 + FMA, or portable C; ``ILOCI_RNNPB_ISA``
    forces one): every one computes the same bits. The rest runs the numpy
    reference in float64 (see the module docstring); a model that trains on
    the reference says so once when built (:class:`NativeFallbackWarning`).
    Its state loads into torch-rnnpb and jax-rnnpb and theirs into it.

    Attributes
    ----------
    kernel_ : str
        What the last :meth:`train` ran: ``"native kernel (avx512)"``,
        ``"native kernel (avx2)"``, ``"native kernel (portable)"`` or
        ``"numpy reference"``.

    Parameters
    ----------
    seed : int
        Seeds the initial weights (identical to the other back ends').
    **params
        Fields of :class:`iloci.params.RNNPBParams`. ``kernel``: ``"auto"``
        (the C kernel where it runs, else the numpy reference) or
        ``"native"`` (the C kernel or an error); ``"torch"`` is
        torch-rnnpb's.

    Raises
    ------
    IlociError
        ``kernel = "torch"``.

    Examples
    --------
    >>> model = NativeRNNPB(seed=0, epochs=300)       # doctest: +SKIP
    >>> pbs = model.train(sequences)                  # (B, 4)
    >>> pb_obs = model.recognize([new_sequence])      # (1, 4)
    """

    backend = "native"

    def _setup(self) -> None:
        p = self.params
        if p.kernel == "torch":
            raise IlociError('kernel = "torch" names torch-rnnpb\'s torch operations; '
                             'native-rnnpb runs kernel = "auto" or "native" (or set '
                             '[perceptual_model] name = "torch-rnnpb").')
        self._sizes = (p.input_size, p.hidden, p.context, p.pb)
        d, h, c, _ = self._sizes
        self._fits = max(-(-h // 16), -(-(d + c) // 16)) * 16 <= NATIVE_WIDTH_MAX
        info = kernel_info(p.kernel, p.dtype, self._fits)
        self._native = info.startswith("native kernel")
        self.kernel_ = info if self._native else "numpy reference"
        if not self._native:
            if p.kernel == "native":
                raise IlociError(f'kernel = "native" cannot run here: {info}. Set kernel = '
                                 '"auto" to use the numpy reference.')
            if getattr(self, "_said", None) != info:   # once: not again on load_state
                warnings.warn(f"native-rnnpb trains on the {info}, not the C kernel.",
                              NativeFallbackWarning, stacklevel=4)
        self._said = info

    def _set_weights(self, weights: Mapping[str, np.ndarray]) -> None:
        # held in the compute dtype, as the other back ends hold them: float32
        # weights are float32 values (the float64 copy is for the reference)
        self._w32 = {k: _f32(weights[k]) for k in WEIGHT_NAMES}
        if self.params.dtype == "float32":
            self._w = {k: v.astype(np.float64) for k, v in self._w32.items()}
        else:
            self._w = {k: np.array(weights[k], dtype=np.float64) for k in WEIGHT_NAMES}

    def _get_weights(self) -> dict[str, np.ndarray]:
        return {k: v.copy() for k, v in self._w.items()}

    def _lib(self) -> ctypes.CDLL | None:
        """The kernel if this model's settings run on it, else None (the reference runs)."""
        return native_lib() if self._native else None

    def _train_multiple(self) -> int:
        # the kernel compiles nothing per shape, and a padded row costs what a
        # real one does; its results do not depend on the padding (tested)
        return 1 if self._lib() is not None else self.batch_multiple

    def _ran(self, code: int, what: str) -> None:
        """Raise for a non-zero return of the kernel's ``what`` ("train", "recognize", "score")."""
        if code == 1:
            raise IlociError(f"not enough memory to {what} this batch; {what} fewer or shorter "
                             "sequences at once. The model was left unchanged.")
        if code != 0:
            raise IlociError(f"the native kernel refused to {what} (code {code}: "
                             f"{NATIVE_CODES.get(code, 'unknown')}).")

    def _weight_args(self, w: Mapping[str, np.ndarray]) -> dict[str, int]:
        return {k: w[k].ctypes.data for k in WEIGHT_NAMES}

    def _train_kernel(self, X, mask, weight, u, epochs, params=None):
        lib = self._lib()
        p = self.params if params is None else params
        mw = mask * weight[None, :]
        if lib is None:
            res = train(self._w, u, X, mw, p, epochs)
            if not all(np.isfinite(a).all() for a in res.weights.values()):
                raise diverged_error()
            self._set_weights(res.weights)
            self._loss_history = res.losses
            self.kernel_ = "numpy reference"
            return res.u, res.loss
        d, h, c, pb = self._sizes
        # copies: the model changes only once the kernel has finished and succeeded
        w = {k: v.copy() for k, v in self._w32.items()}
        Xf, mwf, uf = _f32(X), _f32(mw), np.array(u, np.float32, order="C")
        history = np.zeros(max(int(epochs), 1), np.float32)
        args = TrainArgs(
            size=ctypes.sizeof(TrainArgs), isa=ISAS.get(requested_isa(), 0), epochs=int(epochs),
            T=X.shape[0], R=X.shape[1], D=d, C=c, H=h, P=pb, warmup=int(p.warmup_epochs),
            alpha=float(p.closed_loop), bound=float(p.pb_bound),
            lr=float(p.learning_rate), pb_lr=float(p.pb_learning_rate),
            decay=float(p.learning_rate_decay), clip=float(p.grad_clip),
            X=Xf.ctypes.data, mw=mwf.ctypes.data, u=uf.ctypes.data,
            loss_history=history.ctypes.data, **self._weight_args(w))
        self._ran(lib.iloci_rnnpb_train(ctypes.byref(args)), "train")
        if not all(np.isfinite(a).all() for a in w.values()):
            raise diverged_error()
        self._w32 = w
        self._w = {k: v.astype(np.float64) for k, v in w.items()}
        self._loss_history = history[:args.epochs_run].astype(np.float64)
        self.kernel_ = "native kernel (" + {v: k for k, v in ISAS.items()}[args.isa_used] + ")"
        return uf.astype(np.float64), float(args.loss)

    def _recognize_args(self, X: np.ndarray, rows: np.ndarray, u: np.ndarray,
                        err: np.ndarray | None, keep: list) -> RecognizeArgs:
        """The kernel's arguments for recognition (``rows``: sqrt of mask times weight) or scoring
        (``rows``: the mask; ``u``: the PBs); ``keep`` holds the arrays they point into."""
        p = self.params
        d, h, c, pb = self._sizes
        Xf, rf = _f32(X), _f32(rows)
        keep += [Xf, rf]
        return RecognizeArgs(
            size=ctypes.sizeof(RecognizeArgs), isa=ISAS.get(requested_isa(), 0),
            steps=int(p.recognition_steps), T=X.shape[0], R=X.shape[1], D=d, C=c, H=h, P=pb,
            bound=float(p.pb_bound), damping=float(p.recognition_damping),
            down=LM_DOWN, up=LM_UP, lam_min=LM_MIN, lam_max=LM_MAX, tiny=LM_TINY,
            u_max=LM_U_MAX, X=Xf.ctypes.data, sw=rf.ctypes.data, u=u.ctypes.data,
            err=None if err is None else err.ctypes.data, **self._weight_args(self._w32))

    def _recognize_kernel(self, X, mask, weight, u):
        p = self.params
        lib = self._lib()
        if p.recognition_method == "adam":
            return self._recognize_adam(X, mask, weight, u)
        if lib is None or p.pb > 16:  # LM_P_MAX of _native.c
            if p.kernel == "native":
                raise IlociError('kernel = "native" recognizes at most 16 PB units; set '
                                 'kernel = "auto" to use the numpy reference.')
            return self._recognize_lm_numpy(X, mask, weight, u)
        uf = np.array(u, np.float32, order="C")
        keep: list = []
        args = self._recognize_args(X, np.sqrt(mask * weight[None, :]), uf, None, keep)
        self._ran(lib.iloci_rnnpb_recognize(ctypes.byref(args)), "recognize")
        return uf.astype(np.float64)

    def _recognize_lm_numpy(self, X, mask, weight, u):
        """Levenberg-Marquardt in numpy (float64): the kernel's and torch-rnnpb's steps."""
        p = self.params
        bound = p.pb_bound
        sw = np.sqrt(mask * weight[None, :])
        u = np.array(u, dtype=np.float64)
        r, J = _residuals_and_jacobian(self._w, u, bound, X, sw)
        e = np.square(r).sum(axis=(0, 2))
        lam = np.full(len(u), p.recognition_damping)
        eye = np.eye(p.pb)
        with np.errstate(all="ignore"):
            for _ in range(p.recognition_steps):
                A = np.einsum("lprd,lqrd->rpq", J, J)
                g = np.einsum("lprd,lrd->rp", J, r)
                damp = lam[:, None] * (np.diagonal(A, axis1=1, axis2=2) + LM_TINY)
                delta = _solve(A + damp[:, :, None] * eye, g)
                trial = np.clip(u - delta, -LM_U_MAX, LM_U_MAX)
                trial[~np.isfinite(delta).all(axis=1)] = np.nan
                r_new, J_new = _residuals_and_jacobian(self._w, np.nan_to_num(trial), bound,
                                                       X, sw)
                e_new = np.square(r_new).sum(axis=(0, 2))
                ok = (e_new < e) & np.isfinite(trial).all(axis=1)
                u = np.where(ok[:, None], trial, u)
                r = np.where(ok[None, :, None], r_new, r)
                J = np.where(ok[None, None, :, None], J_new, J)
                lam = np.clip(np.where(ok, lam * LM_DOWN, lam * LM_UP), LM_MIN, LM_MAX)
                e = np.where(ok, e_new, e)
        return u

    def _recognize_adam(self, X, mask, weight, u):
        """Adam on the PBs (``recognition_method = "adam"``), numpy reference gradients."""
        p = self.params
        mw = mask * weight[None, :]
        u = np.array(u, dtype=np.float64)
        m, v = np.zeros_like(u), np.zeros_like(u)
        for t in range(1, p.recognition_steps + 1):
            _, _, g_u = loss_and_gradients(self._w, u, X, mw, 1.0, p.pb_bound)
            adam_step(u, g_u, m, v, t, p.recognition_learning_rate)
        return u

    def _error_kernel(self, X, mask, pbs, exact):
        lib = None if exact else self._lib()
        if lib is None:
            # closed loop from each row's first step: generation (float64, the same
            # bits on every CPU where the kernel is built)
            Y = self._generate_kernel(pbs, X[0], X.shape[0] - 1)
            se = np.square(Y - X[1:]).mean(axis=2) * mask
            return se.sum(axis=0) / np.maximum(mask.sum(axis=0), 1.0)
        pf = np.array(pbs, np.float32, order="C")
        err = np.zeros(X.shape[1], np.float32)
        keep: list = []
        args = self._recognize_args(X, mask, pf, err, keep)
        self._ran(lib.iloci_rnnpb_errors(ctypes.byref(args)), "score")
        return err.astype(np.float64)

    def _generate_kernel(self, pbs, x0, steps):
        lib = native_lib()
        if lib is None:
            X = np.zeros((steps + 1,) + x0.shape)
            X[0] = x0
            return reference_outputs(self._w, pbs, X)
        # float64 in the kernel's one order (iloci.rnnpb.float64): the same bits on every CPU
        w = {k: np.ascontiguousarray(self._w[k], dtype=np.float64) for k in WEIGHT_NAMES}
        pb = np.ascontiguousarray(pbs, dtype=np.float64)
        x = np.ascontiguousarray(x0, dtype=np.float64)
        d, h, c, _ = self._sizes
        out = np.empty((steps, len(x), d))
        self._ran(lib.iloci_rnnpb_generate64(
            len(x), d, c, h, pb.shape[1], steps, w["w_in"].ctypes.data,
            w["b_hidden"].ctypes.data, w["w_out"].ctypes.data, w["b_out"].ctypes.data,
            pb.ctypes.data, x.ctypes.data, out.ctypes.data), "generate")
        return out
