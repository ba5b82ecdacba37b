"""The RNNPB in PyTorch: hand-written batched BPTT, no autograd.

The model is defined in :mod:`iloci.rnnpb`. A training step runs
every sequence at once over padded, time-major tensors: per time step the
forward pass is two ``addmm`` + ``tanh_`` and the backward pass two
matrix products and two element-wise products, all written into buffers
allocated once per batch shape; the weight gradients are then single
matrix products over all steps. Autograd would record and replay ~20 nodes
per step and allocate every intermediate, which is what makes a naive
eager RNN slow on a CPU. The weights live in one flat tensor, so Adam and
gradient clipping are a handful of vector operations.

Even so, at paper size (36 sequences x 50 steps) a step issues ~450 torch
operations of a microsecond or two each, more than their arithmetic: the C
kernel of native-rnnpb (plugins/iloci-native) runs the same algorithm
several times faster, with one result on every CPU. This back end is torch
operations throughout (their float32 results depend on the CPU's BLAS
kernels). Figures: ``benchmarks/results/rnnpb_speed.json``
(``step_ms_by_kernel``).

The layers compute ``tanh`` directly: in torch 2.13 ``tanh_`` is faster than
``2 sigmoid(2z) - 1``, and in float32 it keeps its relative precision near
zero (CHANGELOG.md has the measurements that decided it).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Iterator, Mapping
from contextlib import contextmanager

import numpy as np
import torch

from iloci.errors import IlociError
from iloci.rnnpb import (LM_DOWN, LM_MAX, LM_MIN, LM_TINY, LM_U_MAX, LM_UP,
                         WEIGHT_NAMES, RNNPBBase, diverged_error, weight_shapes)

__all__ = ["TorchRNNPB"]

_B1, _B2, _EPS = 0.9, 0.999, 1e-8


@contextmanager
def _one_thread() -> Iterator[None]:
    """Run torch single-threaded inside, restoring the caller's setting after.

    The per-step matrices (tens of rows) are too small to split: extra
    OpenMP threads only add synchronisation, and when the cores are busy
    with other work their spin-waits slow a training step down a hundredfold.
    """
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)


class _Net:
    """Flat weights of one dtype and the forward/backward passes over them.

    Parameters
    ----------
    weights : dict of ndarray (float64)
    sizes : (D, H, C, P)
    dtype : torch.dtype
    """

    def __init__(self, weights: Mapping[str, np.ndarray], sizes: tuple[int, int, int, int],
                 dtype: torch.dtype) -> None:
        self.d, self.h, self.c, self.p = sizes
        self.s = self.d + self.c
        self.dtype = dtype
        shapes = weight_shapes(*sizes)
        n = sum(int(np.prod(shapes[k])) for k in WEIGHT_NAMES)
        self.flat = torch.empty(n, dtype=dtype)
        self.views = self.split(self.flat)
        for k in WEIGHT_NAMES:
            self.views[k].copy_(torch.from_numpy(np.asarray(weights[k], dtype=np.float64)))
        self._work: OrderedDict = OrderedDict()
        self._mix: dict[float, torch.Tensor] = {}

    def split(self, flat: torch.Tensor) -> dict[str, torch.Tensor]:
        """Views of a flat vector shaped like the weights."""
        shapes = weight_shapes(self.d, self.h, self.c, self.p)
        out, i = {}, 0
        for k in WEIGHT_NAMES:
            n = int(np.prod(shapes[k]))
            out[k] = flat[i:i + n].view(shapes[k])
            i += n
        return out

    def mix(self, alpha: float) -> torch.Tensor:
        """``[alpha] * D + [1] * C``: how much of ``o_t`` enters ``s_{t+1}`` (cached)."""
        m = self._mix.get(alpha)
        if m is None:
            m = torch.ones(self.s, dtype=self.dtype)
            m[:self.d] = alpha
            self._mix[alpha] = m
        return m

    def numpy(self) -> dict[str, np.ndarray]:
        return {k: v.detach().numpy().astype(np.float64) for k, v in self.views.items()}

    def workspace(self, steps: int, rows: int) -> dict[str, torch.Tensor]:
        """Buffers for ``steps`` predictions of ``rows`` sequences (reused)."""
        key = (steps, rows)
        ws = self._work.get(key)
        if ws is None:
            e = lambda *shape: torch.empty(*shape, dtype=self.dtype)  # noqa: E731
            L, R, S, H = steps, rows, self.s, self.h
            ws = {"H": e(L, R, H), "O": e(L, R, S), "G": e(L, R, S), "DZ": e(L, R, H),
                  "dtO": e(L, R, S), "dtH": e(L, R, H), "IN": e(L, R, S),
                  "diff": e(L, R, self.d), "pre": e(R, H),
                  "w_r": e(S, H), "w_oT": e(S, H),
                  "w_sT": e(H, S), "sdz": e(R, H), "grad": torch.empty_like(self.flat)}
            # per-step views, made once: indexing in the loop costs as much as the maths
            for name in ("H", "O", "G", "DZ", "dtO", "dtH"):
                ws[name + "_t"] = ws[name].unbind(0)
            self._work[key] = ws
            while len(self._work) > 6:  # bound the memory held for past batch shapes
                self._work.popitem(last=False)
        else:
            self._work.move_to_end(key)
        return ws

    def forward(self, pb: torch.Tensor, X: torch.Tensor, alpha: float,
                ws: dict[str, torch.Tensor]) -> torch.Tensor:
        """Run the network; fills ``ws["H"]`` (L, R, H); returns ``O`` (L, R, S).

        With ``s_{t+1} = o_t * mix + (1 - alpha) [X_{t+1}, 0]``, the hidden
        pre-activation is ``o_{t-1} @ (mix w_s) + pre + (1 - alpha) X_t @ w_s[:D]``:
        one ``addmm`` per layer and step, the teacher-forced share of all steps
        computed beforehand in one product.
        """
        v, d = self.views, self.d
        w_s = v["w_in"][:self.s]
        L = X.shape[0] - 1
        Hs, Os = ws["H_t"], ws["O_t"]
        pre = torch.addmm(v["b_hidden"], pb, v["w_in"][self.s:], out=ws["pre"])
        torch.mul(w_s, self.mix(alpha)[:, None], out=ws["w_r"])
        if alpha != 1.0:
            forced = torch.matmul(X[1:L], w_s[:d]).mul_(1.0 - alpha).add_(pre)
            biases = forced.unbind(0)
        else:
            biases = [pre] * max(L - 1, 0)
        w_r, w_o, b_o = ws["w_r"], v["w_out"], v["b_out"]
        torch.addmm(pre, X[0], w_s[:d], out=Hs[0]).tanh_()
        torch.addmm(b_o, Hs[0], w_o, out=Os[0]).tanh_()
        for t in range(1, L):
            torch.addmm(biases[t - 1], Os[t - 1], w_r, out=Hs[t]).tanh_()
            torch.addmm(b_o, Hs[t], w_o, out=Os[t]).tanh_()
        return ws["O"]

    def errors(self, pb: torch.Tensor, X: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """Closed-loop mean squared prediction error per row, shape (R,)."""
        ws = self.workspace(X.shape[0] - 1, X.shape[1])
        O = self.forward(pb, X, 1.0, ws)
        diff = torch.sub(O[:, :, :self.d], X[1:], out=ws["diff"])
        se = diff.square_().mean(dim=2).mul_(mask)
        return se.sum(dim=0) / mask.sum(dim=0).clamp_(min=1.0)

    def sse(self, u: torch.Tensor, bound: float, X: torch.Tensor,
            sw: torch.Tensor) -> torch.Tensor:
        """Closed-loop ``sum_t sum_D (sw (y - x))^2`` per row, shape (R,).

        ``u`` (R, P) with ``pb = bound tanh(u)``; ``sw`` (L, R) scales each
        step's residual (square root of mask times the row's weight).
        """
        ws = self.workspace(X.shape[0] - 1, X.shape[1])
        O = self.forward(torch.tanh(u).mul_(bound), X, 1.0, ws)
        r = torch.sub(O[:, :, :self.d], X[1:], out=ws["diff"]).mul_(sw.unsqueeze(2))
        return r.square_().sum(dim=(0, 2))

    def residuals_and_jacobian(self, u: torch.Tensor, bound: float, X: torch.Tensor,
                               sw: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Closed-loop residuals ``r`` (L, R, D) and ``J = dr/du`` (L, P, R, D).

        The states come from :meth:`forward`; the derivatives along each of
        the ``P`` coordinates of ``u`` are then carried through the steps
        (forward mode), as ``P`` stacked copies of the batch, so each step is
        one matrix product per layer for all of them.
        """
        v, d, S = self.views, self.d, self.s
        R, P = u.shape
        L = X.shape[0] - 1
        th = torch.tanh(u)
        ws = self.workspace(L, R)
        O = self.forward(th * bound, X, 1.0, ws)
        w_s, w_p, w_o = v["w_in"][:S], v["w_in"][S:], v["w_out"]
        swd = sw.unsqueeze(2)                                                 # (L, R, 1)
        r = (O[:, :, :d] - X[1:]).mul_(swd)
        # d tanh / d z = 1 - tanh^2, for all steps at once (one operation each)
        torch.mul(ws["H"], ws["H"], out=ws["dtH"]).neg_().add_(1.0)
        torch.mul(O, O, out=ws["dtO"]).neg_().add_(1.0)
        dtH, dtO = ws["dtH_t"], ws["dtO_t"]
        # d pre / d u_k = bound (1 - tanh(u_k)^2) w_p[k]: (P R, H), the same every step
        dpre = ((bound * (1.0 - th * th)).T.unsqueeze(2) * w_p.unsqueeze(1)).reshape(P * R, -1)
        J = X.new_empty(L, P, R, d)
        Jf = J.view(L, P * R, d)
        swp = swd.repeat(1, P, 1)                                             # (L, P R, 1)
        # the P derivative copies of the batch stacked as P R rows: one matrix
        # product per layer and step for all of them
        dz = dpre.clone()                          # d s_0 / du = 0: s_0 is the data
        dh = torch.empty_like(dpre)
        do = dpre.new_empty(P * R, S)
        # views made once: in the loop they cost as much as the arithmetic
        dz3, dh3, do3, do_d = dz.view(P, R, -1), dh.view(P, R, -1), do.view(P, R, S), do[:, :d]
        Jt, swt = Jf.unbind(0), swp.unbind(0)
        for t in range(L):
            if t:
                torch.addmm(dpre, do, w_s, out=dz)  # closed loop: s_t = o_{t-1}
            torch.mul(dz3, dtH[t], out=dh3)
            torch.mm(dh, w_o, out=do)
            do3.mul_(dtO[t])
            torch.mul(do_d, swt[t], out=Jt[t])
        return r, J

    def loss_and_grads(self, pb: torch.Tensor, X: torch.Tensor, mask_w: torch.Tensor,
                       alpha: float, weights_too: bool
                       ) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor]:
        """Loss ``sum mask_w * mean_D (y - x)^2`` and its gradients (hand-written BPTT).

        ``mask_w`` (L, R) is the mask times each row's loss weight. Returns
        (loss, flat weight gradient or None, dL/dpb (R, P)).
        """
        L, R = X.shape[0] - 1, X.shape[1]
        d, v = self.d, self.views
        ws = self.workspace(L, R)
        O = self.forward(pb, X, alpha, ws)
        diff = torch.sub(O[:, :, :d], X[1:], out=ws["diff"])
        mw = mask_w.unsqueeze(2)
        loss = torch.sum(diff.square().mul_(mw)) / d
        G = ws["G"]
        G.zero_()
        torch.mul(diff, mw, out=G[:, :, :d]).mul_(2.0 / d)
        Hh = ws["H"]
        # d tanh / d z = 1 - tanh^2
        torch.mul(O, O, out=ws["dtO"]).neg_().add_(1.0)
        torch.mul(Hh, Hh, out=ws["dtH"]).neg_().add_(1.0)
        ws["w_oT"].copy_(v["w_out"].T)
        mix = self.mix(alpha)
        torch.mul(v["w_in"][:self.s].T, mix, out=ws["w_sT"])
        Gt, DZt, dtO, dtH = ws["G_t"], ws["DZ_t"], ws["dtO_t"], ws["dtH_t"]
        w_oT, w_sT = ws["w_oT"], ws["w_sT"]
        for t in range(L - 1, -1, -1):
            go = Gt[t].mul_(dtO[t])                       # G[t] becomes dL/dz_o
            dz = torch.mm(go, w_oT, out=DZt[t]).mul_(dtH[t])
            if t > 0:                                     # through s_t = o_{t-1} * mix + ...
                Gt[t - 1].addmm_(dz, w_sT)
        sdz = torch.sum(ws["DZ"], dim=0, out=ws["sdz"])
        g_pb = sdz @ v["w_in"][self.s:].T
        if not weights_too:
            return loss, None, g_pb
        grad = ws["grad"]
        gv = self.split(grad)
        S, H = self.s, self.h
        torch.mm(Hh.view(-1, H).T, G.view(-1, S), out=gv["w_out"])
        torch.sum(G.view(-1, S), dim=0, out=gv["b_out"])
        IN = ws["IN"]
        IN[0, :, :d] = X[0]
        IN[0, :, d:] = 0.0
        if L > 1:
            torch.mul(O[:-1], mix, out=IN[1:])
            if alpha != 1.0:
                IN[1:, :, :d].add_(X[1:L], alpha=1.0 - alpha)
        torch.mm(IN.view(-1, S).T, ws["DZ"].view(-1, H), out=gv["w_in"][:S])
        torch.mm(pb.T, sdz, out=gv["w_in"][S:])
        torch.sum(sdz, dim=0, out=gv["b_hidden"])
        return loss, grad, g_pb


def _adam(p: torch.Tensor, g: torch.Tensor, m: torch.Tensor, v: torch.Tensor,
          den: torch.Tensor, t: int, lr: float) -> None:
    m.mul_(_B1).add_(g, alpha=1.0 - _B1)
    v.mul_(_B2).addcmul_(g, g, value=1.0 - _B2)
    step = lr * (1.0 - _B2 ** t) ** 0.5 / (1.0 - _B1 ** t)
    p.addcdiv_(m, torch.sqrt(v, out=den).add_(_EPS), value=-step)


class TorchRNNPB(RNNPBBase):
    """RNNPB (recurrent network with parametric bias) in PyTorch.

    Implements :class:`iloci.interfaces.PerceptualModel`; the public
    methods and their contract are documented in
    :class:`iloci.rnnpb.RNNPBBase`, the network in
    :mod:`iloci.rnnpb`. Runs on the CPU, single-threaded (the
    caller's ``torch.set_num_threads`` is restored after each call).

    Training, recognition, scoring and generation are torch operations,
    following the algorithm and update order of the numpy reference
    (:mod:`iloci.rnnpb.reference`); float32 results differ from it (and
    between CPUs) in rounding only. The C kernel with one result on every
    CPU is native-rnnpb's (the default perceptual model).

    Attributes
    ----------
    kernel_ : str
        ``"torch operations"``.

    Parameters
    ----------
    seed : int
        Seeds the initial weights (identical to the JAX back end's).
    **params
        Fields of :class:`iloci.params.RNNPBParams` (sizes, epochs, learning
        rates, ``closed_loop``, ``dtype``, ...); ``kernel``: ``"auto"`` or
        ``"torch"`` (the same here).

    Raises
    ------
    IlociError
        ``kernel = "native"`` (native-rnnpb's).

    Examples
    --------
    >>> model = TorchRNNPB(seed=0, epochs=300)        # doctest: +SKIP
    >>> pbs = model.train(sequences)                  # (B, 4)
    >>> pb_obs = model.recognize([new_sequence])      # (1, 4)
    """

    backend = "torch"

    kernel_ = "torch operations"

    def _setup(self) -> None:
        if self.params.kernel == "native":
            raise IlociError('kernel = "native" is the C kernel of native-rnnpb; set '
                             'perceptual_model = "native-rnnpb", or kernel = "auto" for '
                             'torch operations.')
        self._dtype = torch.float64 if self.params.dtype == "float64" else torch.float32
        p = self.params
        self._sizes = (p.input_size, p.hidden, p.context, p.pb)

    def _set_weights(self, weights: Mapping[str, np.ndarray]) -> None:
        self._net = _Net(weights, self._sizes, self._dtype)
        self._net64 = self._net if self._dtype == torch.float64 else None

    def _get_weights(self) -> dict[str, np.ndarray]:
        return self._net.numpy()

    def _exact(self) -> _Net:
        if self._net64 is None:
            self._net64 = _Net(self._net.numpy(), self._sizes, torch.float64)
        return self._net64

    def _t(self, a: np.ndarray, dtype: torch.dtype | None = None) -> torch.Tensor:
        return torch.from_numpy(np.ascontiguousarray(a)).to(dtype or self._dtype)

    def _train_kernel(self, X, mask, weight, u, epochs, params=None):
        p = self.params if params is None else params
        net = self._net
        backup = net.flat.clone()
        Xt, mw = self._t(X), self._t(mask * weight[None, :])
        ut = self._t(u)
        m, v, den = (torch.zeros_like(net.flat) for _ in range(3))
        mu, vu, denu = (torch.zeros_like(ut) for _ in range(3))
        bound, clip = p.pb_bound, p.grad_clip
        with torch.no_grad(), _one_thread():
            for t in range(1, epochs + 1):
                th = torch.tanh(ut)
                loss, g, gpb = net.loss_and_grads(th * bound, Xt, mw, p.closed_loop, True)
                gu = gpb.mul_(th.square_().neg_().add_(1.0)).mul_(bound)
                # the norm as a Python float: a handful of scalar tensor ops fewer
                g.mul_(min(1.0, clip / (float(torch.dot(g, g)) ** 0.5 + 1e-12)))
                f = p.learning_rate_decay ** ((t - 1) / epochs)
                ramp = min(1.0, t / p.warmup_epochs) if p.warmup_epochs else 1.0
                _adam(net.flat, g, m, v, den, t, p.learning_rate * f * ramp)
                _adam(ut, gu, mu, vu, denu, t, p.pb_learning_rate * f)
        if not bool(torch.isfinite(net.flat).all()):
            net.flat.copy_(backup)
            raise diverged_error()
        self._net64 = net if self._dtype == torch.float64 else None
        self.kernel_ = "torch operations"
        return ut.numpy().astype(np.float64), float(loss)

    def _recognize_kernel(self, X, mask, weight, u):
        if self.params.recognition_method == "adam":
            return self._recognize_adam(X, mask, weight, u)
        p = self.params
        net = self._net
        Xt, ut = self._t(X), self._t(u)
        sw = self._t(np.sqrt(mask * weight[None, :]))
        bound = p.pb_bound
        eye = torch.eye(p.pb, dtype=net.dtype)
        with torch.no_grad(), _one_thread():
            # each trial's residuals come with their Jacobian (one pass through
            # the steps): an accepted trial's are the next step's
            r, J = net.residuals_and_jacobian(ut, bound, Xt, sw)
            e = r.square().sum(dim=(0, 2))
            lam = torch.full((len(ut),), p.recognition_damping, dtype=net.dtype)
            for _ in range(p.recognition_steps):
                A = torch.einsum("lprd,lqrd->rpq", J, J)                 # (R, P, P)
                g = torch.einsum("lprd,lrd->rp", J, r)                   # (R, P)
                damp = lam.unsqueeze(1) * (torch.diagonal(A, dim1=1, dim2=2) + LM_TINY)
                # solve_ex: a singular system gives non-finite steps, rejected below
                delta = torch.linalg.solve_ex(A + damp.unsqueeze(2) * eye,
                                              g.unsqueeze(2))[0].squeeze(2)
                trial = (ut - delta).clamp_(-LM_U_MAX, LM_U_MAX)
                r_new, J_new = net.residuals_and_jacobian(trial, bound, Xt, sw)
                e_new = r_new.square().sum(dim=(0, 2))
                ok = e_new < e                 # False for NaN: a bad step is never kept
                ut = torch.where(ok.unsqueeze(1), trial, ut)
                r = torch.where(ok.view(1, -1, 1), r_new, r)
                J = torch.where(ok.view(1, 1, -1, 1), J_new, J)
                lam = torch.where(ok, lam * LM_DOWN, lam * LM_UP).clamp_(LM_MIN, LM_MAX)
                e = torch.where(ok, e_new, e)
        return ut.numpy().astype(np.float64)

    def _recognize_adam(self, X, mask, weight, u):
        p = self.params
        net = self._net
        Xt, mw, ut = self._t(X), self._t(mask * weight[None, :]), self._t(u)
        m, v, den = (torch.zeros_like(ut) for _ in range(3))
        bound = p.pb_bound
        with torch.no_grad(), _one_thread():
            for t in range(1, p.recognition_steps + 1):
                th = torch.tanh(ut)
                _, _, gpb = net.loss_and_grads(th * bound, Xt, mw, 1.0, False)
                gu = gpb.mul_(th.square_().neg_().add_(1.0)).mul_(bound)
                _adam(ut, gu, m, v, den, t, p.recognition_learning_rate)
        return ut.numpy().astype(np.float64)

    def _error_kernel(self, X, mask, pbs, exact):
        net = self._exact() if exact else self._net
        with torch.no_grad(), _one_thread():
            err = net.errors(self._t(pbs, net.dtype), self._t(X, net.dtype),
                             self._t(mask, net.dtype))
        return err.numpy().astype(np.float64)

    def _generate_kernel(self, pbs, x0, steps):
        net = self._exact()
        X = np.zeros((steps + 1,) + x0.shape)
        X[0] = x0
        with torch.no_grad(), _one_thread():
            ws = net.workspace(steps, len(x0))
            O = net.forward(self._t(pbs, net.dtype), self._t(X, net.dtype), 1.0, ws)
            return O[:, :, :net.d].numpy().astype(np.float64)
