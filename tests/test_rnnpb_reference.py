"""The numpy reference of the RNNPB's training (iloci.rnnpb.reference) is right.

Numpy only (runs without any back end): its gradients agree with central
finite differences of its loss, its loss with the forward pass that defines
the model, and its schedule and clipping with the recipe written in its
docstring. The back ends are then tested against it
(tests/plugins/test_rnnpb_reference_parity.py).
"""

from __future__ import annotations

import numpy as np
import pytest

from iloci.rnnpb import init_weights, make_params, pad_sequences, pb_to_u
from iloci.rnnpb import reference as ref
from iloci.testing.checks import synthetic_sequences


def _problem(closed_loop=1.0, seed=0):
    params = make_params(hidden=7, context=3, pb=2, closed_loop=closed_loop)
    seqs = synthetic_sequences(3, 6, lengths=(5, 7, 4), seed=seed)
    X, mask = pad_sequences(seqs, 4)                       # one all-padding row
    mw = mask / np.maximum(mask.sum(axis=0), 1.0) / 3
    w = init_weights(params, seed)
    u = np.random.default_rng(seed).normal(size=(4, 2)) * 0.5
    return params, w, u, X, mw


@pytest.mark.parametrize("closed_loop", [1.0, 0.3, 0.0])
def test_gradients_agree_with_finite_differences(closed_loop):
    params, w, u, X, mw = _problem(closed_loop)
    _, grads, g_u = ref.loss_and_gradients(w, u, X, mw, closed_loop, params.pb_bound)
    h = 1e-6

    def loss(w2, u2):
        return ref.loss_and_gradients(w2, u2, X, mw, closed_loop, params.pb_bound)[0]

    rng = np.random.default_rng(1)
    for name in w:
        flat = w[name].reshape(-1)
        for i in rng.choice(flat.size, size=min(flat.size, 12), replace=False):
            up = {k: v.copy() for k, v in w.items()}
            dn = {k: v.copy() for k, v in w.items()}
            up[name].reshape(-1)[i] += h
            dn[name].reshape(-1)[i] -= h
            fd = (loss(up, u) - loss(dn, u)) / (2 * h)
            assert grads[name].reshape(-1)[i] == pytest.approx(fd, rel=1e-5, abs=1e-9), name
    for i in np.ndindex(u.shape):
        up, dn = u.copy(), u.copy()
        up[i] += h
        dn[i] -= h
        fd = (loss(w, up) - loss(w, dn)) / (2 * h)
        assert g_u[i] == pytest.approx(fd, rel=1e-5, abs=1e-9)
    assert np.all(g_u[3] == 0.0)                           # the padding row learns nothing


def test_loss_is_that_of_the_defining_forward_pass():
    params, w, u, X, mw = _problem(0.5)
    pbs = params.pb_bound * np.tanh(u)
    Y = ref.reference_outputs(w, pbs, X, closed_loop=0.5)
    want = float(np.sum(mw * ((Y - X[1:]) ** 2).mean(axis=2)))
    got = ref.loss_and_gradients(w, u, X, mw, 0.5, params.pb_bound)[0]
    assert got == pytest.approx(want, rel=1e-12)


def test_schedule_warms_up_and_decays():
    p = make_params(learning_rate=0.01, pb_learning_rate=0.1, warmup_epochs=10,
                    learning_rate_decay=0.1)
    assert ref.learning_rates(p, 1, 100) == pytest.approx((0.001, 0.1))
    assert ref.learning_rates(p, 10, 100)[0] == pytest.approx(0.01 * 0.1 ** (9 / 100))
    assert ref.learning_rates(p, 100, 100)[1] == pytest.approx(0.1 * 0.1 ** (99 / 100))
    flat = make_params(warmup_epochs=0, learning_rate_decay=1.0)
    assert ref.learning_rates(flat, 1, 5) == (flat.learning_rate, flat.pb_learning_rate)


def test_adam_first_step_moves_each_parameter_by_the_learning_rate():
    # bias-corrected, the first step is lr * g / (|g| + eps): lr in the sign of -g
    p, g = np.zeros(3), np.array([2.0, -0.5, 1e-3])
    ref.adam_step(p, g, np.zeros(3), np.zeros(3), 1, 0.01)
    np.testing.assert_allclose(p, -0.01 * np.sign(g), rtol=1e-3)  # eps: 3e-4 at g = 1e-3


def test_training_lowers_the_loss_and_clips():
    params, w, u, X, mw = _problem()
    res = ref.train(w, u, X, mw, params, 100)
    assert res.losses.shape == (100,) and res.loss == res.losses[-1]
    assert res.losses[-1] < 0.7 * res.losses[0]            # measured: 0.183 -> 0.105
    assert all(res.weights[k].shape == w[k].shape for k in w)
    # a clip far below the gradient's norm moves the weights by no more than Adam's
    # first-step bound lr, whatever the clip; the PBs are not clipped
    tiny = make_params(hidden=7, context=3, pb=2, grad_clip=1e-9, warmup_epochs=0)
    one = ref.train(w, u, X, mw, tiny, 1)
    for k in w:
        assert np.abs(one.weights[k] - w[k]).max() <= tiny.learning_rate * (1 + 1e-6)
    assert not np.allclose(one.u[:3], u[:3])


def test_training_leaves_its_inputs_alone():
    params, w, u, X, mw = _problem()
    before = {k: v.copy() for k, v in w.items()}, u.copy()
    ref.train(w, u, X, mw, params, 2)
    assert all(np.array_equal(before[0][k], w[k]) for k in w)
    assert np.array_equal(before[1], u)
    assert pb_to_u(np.zeros((1, 2)), 1.0).shape == (1, 2)
