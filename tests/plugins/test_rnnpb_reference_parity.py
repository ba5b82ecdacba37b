"""Every back end and kernel trains as the numpy reference does (iloci.rnnpb.reference).

Each is trained 5 epochs from the same weights and PBs as
:func:`iloci.rnnpb.reference.train` (float64), on sequences of different
lengths (masking) and with warm-up, decay and clipping all active; then
every weight and PB is compared. float64 kernels agree to 1e-10 (only the
order of floating-point sums differs); float32 ones to 1e-4 (rounding).
The native kernel is checked in every instruction set this CPU runs, and
its float32 training bit for bit against the reference's float32 mode
(:mod:`iloci.rnnpb.float32`, the kernel's order of operations).
"""

from __future__ import annotations

import numpy as np
import pytest

from iloci.rnnpb import WEIGHT_NAMES, pb_to_u
from iloci.rnnpb import reference as ref
from iloci.testing.checks import synthetic_sequences

EPOCHS = 5
TOL = {"float64": 1e-10, "float32": 1e-4}

#: settings with every part of the recipe active within 5 epochs
RECIPES = {
    "closed-loop": {"warmup_epochs": 3, "learning_rate_decay": 0.2, "grad_clip": 0.05},
    "teacher-forced-half": {"closed_loop": 0.5, "warmup_epochs": 0, "learning_rate": 0.02},
}


def _kernels():
    out = []
    try:
        from iloci_native.native import ISAS, native_isas
    except ImportError:
        pass
    else:
        out += [("native", "float64", "auto")]
        out += [("native", "float32", f"native-{isa}") for isa in ISAS if isa in native_isas()]
    try:
        import iloci_torch  # noqa: F401
        out += [("torch", "float64", "torch"), ("torch", "float32", "torch")]
    except ImportError:
        pass
    try:
        import iloci_jax  # noqa: F401
        out += [("jax", "float64", "auto"), ("jax", "float32", "auto")]
    except ImportError:
        pass
    return out


def _model(backend, dtype, kernel, monkeypatch, **params):
    if kernel.startswith("native-"):
        from iloci_native.native import ISA_ENV
        monkeypatch.setenv(ISA_ENV, kernel.split("-", 1)[1])
        kernel = "native"
    if backend == "native":
        import warnings

        from iloci_native.rnnpb import NativeFallbackWarning, NativeRNNPB
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NativeFallbackWarning)   # float64: the reference
            return NativeRNNPB(seed=3, dtype=dtype, kernel=kernel, **params)
    if backend == "torch":
        from iloci_torch.rnnpb import TorchRNNPB
        return TorchRNNPB(seed=3, dtype=dtype, kernel=kernel, **params)
    from iloci_jax.rnnpb import JaxRNNPB
    return JaxRNNPB(seed=3, dtype=dtype, **params)


@pytest.mark.parametrize("recipe", list(RECIPES))
@pytest.mark.parametrize("backend,dtype,kernel", _kernels(),
                         ids=lambda v: v if isinstance(v, str) else None)
def test_training_matches_the_reference(backend, dtype, kernel, recipe, monkeypatch):
    seqs = synthetic_sequences(5, 6, lengths=(14, 20, 9), seed=2)
    model = _model(backend, dtype, kernel, monkeypatch, hidden=24, context=9, **RECIPES[recipe])
    w0 = {k: model.state()[k] for k in WEIGHT_NAMES}     # in the model's dtype already
    pbs0 = np.random.default_rng(0).uniform(-0.5, 0.5, size=(len(seqs), model.pb_size))
    # the reference gets exactly what the back end's kernel gets
    X, mask, per_seq = model._padded(seqs, geometric=False)
    u0 = np.zeros((X.shape[1], model.pb_size))
    u0[:len(seqs)] = pb_to_u(pbs0, model.params.pb_bound)
    want = ref.train(w0, u0, X, mask * (per_seq / len(seqs))[None, :], model.params, EPOCHS)

    pbs = model.train(seqs, pbs_init=pbs0, epochs=EPOCHS)
    got = model.state()
    tol = TOL[dtype]
    for k in WEIGHT_NAMES:
        np.testing.assert_allclose(got[k], want.weights[k], rtol=0, atol=tol, err_msg=k)
    np.testing.assert_allclose(pbs, model.params.pb_bound * np.tanh(want.u[:len(seqs)]),
                               rtol=0, atol=tol)
    assert model.train_loss_ == pytest.approx(want.loss, rel=tol)
    # the comparison is not vacuous: training moved every weight array
    assert all(np.abs(got[k] - w0[k]).max() > 100 * tol for k in WEIGHT_NAMES)


def _native_isas():
    try:
        from iloci_native.native import ISAS, native_isas
    except ImportError:
        return []
    return [isa for isa in ISAS if isa in native_isas()]


@pytest.mark.parametrize("recipe", list(RECIPES))
@pytest.mark.parametrize("isa", _native_isas())
def test_native_float32_kernel_is_the_reference_float32_mode_bit_for_bit(isa, recipe,
                                                                         monkeypatch):
    # iloci.rnnpb.float32 states the kernel's order of operations: the same bits
    seqs = synthetic_sequences(5, 6, lengths=(14, 20, 9), seed=2)
    model = _model("native", "float32", f"native-{isa}", monkeypatch, hidden=24, context=9,
                   **RECIPES[recipe])
    w0 = {k: model.state()[k] for k in WEIGHT_NAMES}
    pbs0 = np.random.default_rng(0).uniform(-0.5, 0.5, size=(len(seqs), model.pb_size))
    X, mask, per_seq = model._padded(seqs, geometric=False)
    u0 = np.zeros((X.shape[1], model.pb_size))
    u0[:len(seqs)] = pb_to_u(pbs0, model.params.pb_bound)
    epochs = 12
    want = ref.train(w0, u0, X, mask * (per_seq / len(seqs))[None, :], model.params, epochs,
                     dtype="float32")
    pbs = model.train(seqs, pbs_init=pbs0, epochs=epochs)
    assert model.kernel_ == f"native kernel ({isa})"
    got = model.state()
    for k in WEIGHT_NAMES:
        assert want.weights[k].dtype == np.float32
        np.testing.assert_array_equal(got[k], want.weights[k].astype(np.float64), err_msg=k)
    u = want.u[:len(seqs)].astype(np.float64)
    np.testing.assert_array_equal(pbs, model.params.pb_bound * np.tanh(u))
    assert model.train_loss_ == want.loss
    np.testing.assert_array_equal(model._loss_history, want.losses.astype(np.float64))
    # not vacuous: training moved every weight array well beyond float32's rounding
    assert all(np.abs(got[k] - w0[k]).max() > 1e-3 for k in WEIGHT_NAMES)


def _nearest_float32(x):
    """The float32 nearest the rational ``x`` (ties to even), by exact arithmetic."""
    from fractions import Fraction

    f = np.float32(float(x))
    near = [np.nextafter(f, np.float32(-np.inf)), f, np.nextafter(f, np.float32(np.inf))]
    return min(near, key=lambda c: (abs(Fraction(float(c)) - x),
                                    int(np.array(c).view(np.int32)) & 1))


def test_reference_float32_fma_rounds_once():
    from fractions import Fraction

    from iloci.rnnpb.float32 import fma

    f = np.float32
    # a product rounded before the sum loses what fma keeps
    e = f(2.0 ** -23)
    assert fma(f(1) + e, f(1) - e, f(-1)) == f(-(2.0 ** -46))
    assert (f(1) + e) * (f(1) - e) - f(1) == 0.0
    # double rounding: a b = 1 + 2^-11 + 2^-24, a float32 midpoint; 2^-60 more rounds up,
    # which the float64 sum (1 + 2^-11 + 2^-24: a tie, to even, down) would lose
    a = f(1 + 2.0 ** -12)
    assert fma(a, a, f(2.0 ** -60)) == f(1 + 2.0 ** -11 + 2.0 ** -23)
    assert fma(a, a, f(-(2.0 ** -60))) == f(1 + 2.0 ** -11)
    assert np.float32(float(a) * float(a) + 2.0 ** -60) == f(1 + 2.0 ** -11)
    # against exact rational arithmetic, over a wide range of exponents
    rng = np.random.default_rng(0)
    x, y, z = (rng.standard_normal(3000) * 2.0 ** rng.integers(-30, 30, 3000) for _ in range(3))
    x, y, z = x.astype(f), y.astype(f), z.astype(f)
    got = fma(x, y, z)
    for p, q, r, g in zip(x, y, z, got):
        want = _nearest_float32(Fraction(float(p)) * Fraction(float(q)) + Fraction(float(r)))
        assert g == want, (p, q, r)


@pytest.mark.parametrize("isa", _native_isas())
def test_native_scores_are_the_reference_float32_errors_bit_for_bit(isa, monkeypatch):
    # Weaker than the training's test: each error is a float64 sum rounded once
    # to float32, which absorbs a last-bit difference inside the forward pass
    # (an unfused multiply-add there passes this test, not the training's).
    from iloci.rnnpb.float32 import prediction_errors

    seqs = synthetic_sequences(5, 6, lengths=(14, 20, 9), seed=2)
    model = _model("native", "float32", f"native-{isa}", monkeypatch, hidden=24, context=9)
    model.train(seqs, epochs=30)
    X, mask, _ = model._padded(seqs, geometric=False)
    pbs = np.random.default_rng(1).uniform(-0.9, 0.9, size=(X.shape[1], model.pb_size))
    got = model._error_kernel(X, mask, pbs, exact=False)
    w = {k: model.state()[k] for k in WEIGHT_NAMES}
    want = prediction_errors(w, pbs, X, mask)
    assert want.dtype == np.float32 and np.all(want[:len(seqs)] > 0)  # padding rows: 0
    np.testing.assert_array_equal(got, want.astype(np.float64))
