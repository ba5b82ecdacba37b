"""The ``torch-rnnpb`` perceptual model (plugin iloci-torch)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from iloci.errors import InvalidInputError  # noqa: E402
from iloci.rnnpb import init_weights, make_params, pad_sequences  # noqa: E402
from iloci.testing import parametrize_with_checks, registry_factory  # noqa: E402
from iloci.testing.checks import synthetic_sequences  # noqa: E402
from iloci_torch.rnnpb import TorchRNNPB, _Net  # noqa: E402
from rnnpb_cases import *  # noqa: E402,F401,F403  (shared behaviour tests)


@pytest.fixture
def make():
    return lambda **kw: TorchRNNPB(**kw)


@parametrize_with_checks([("perceptual_model", lambda seed: TorchRNNPB(seed=seed))])
def test_conformance(component, check):
    check(component)


def test_registered_and_built_by_name():
    make = registry_factory("perceptual_model", "torch-rnnpb", hidden=20, epochs=7)
    m = make(3)
    assert isinstance(m, TorchRNNPB)
    assert (m.params.hidden, m.params.epochs, m.seed) == (20, 7, 3)


def test_plugin_module_imports_without_torch():
    code = "import sys, iloci_torch; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def _autograd_loss(weights, pb, X, mask_w, alpha):
    """The model's loss written plainly with autograd: an independent check of the BPTT."""
    w_in, b_h, w_out, b_out = (weights[k] for k in ("w_in", "b_hidden", "w_out", "b_out"))
    d = X.shape[2]
    c = torch.zeros(X.shape[1], w_out.shape[1] - d, dtype=X.dtype)
    x = X[0]
    loss = 0.0
    for t in range(X.shape[0] - 1):
        h = torch.tanh(torch.cat([x, c, pb], dim=1) @ w_in + b_h)
        o = torch.tanh(h @ w_out + b_out)
        y, c = o[:, :d], o[:, d:]
        loss = loss + (((y - X[t + 1]) ** 2).mean(dim=1) * mask_w[t]).sum()
        x = alpha * y + (1 - alpha) * X[t + 1]
    return loss


@pytest.mark.parametrize("alpha", [1.0, 0.5, 0.0])
def test_hand_written_bptt_equals_autograd(alpha):
    seqs = synthetic_sequences(3, 6, (12, 17, 9), seed=2)
    X, mask = pad_sequences(seqs, 4)
    rng = np.random.default_rng(0)
    mask_w = mask * rng.uniform(0.5, 2.0, size=4)[None]
    weights = init_weights(make_params(), 7)
    pb = rng.uniform(-0.9, 0.9, (4, 4))
    net = _Net(weights, (6, 60, 25, 4), torch.float64)
    loss, grad, g_pb = net.loss_and_grads(torch.tensor(pb), torch.tensor(X),
                                          torch.tensor(mask_w), alpha, True)
    tw = {k: torch.tensor(v, requires_grad=True) for k, v in weights.items()}
    tpb = torch.tensor(pb, requires_grad=True)
    ref = _autograd_loss(tw, tpb, torch.tensor(X), torch.tensor(mask_w), alpha)
    ref.backward()
    ref = ref.detach()
    assert float(loss) == pytest.approx(ref.item(), rel=1e-12)
    for k, g in net.split(grad).items():
        np.testing.assert_allclose(g.numpy(), tw[k].grad.numpy(), rtol=1e-9, atol=1e-13)
    np.testing.assert_allclose(g_pb.numpy(), tpb.grad.numpy(), rtol=1e-9, atol=1e-13)


def test_float32_and_float64_train_alike():
    seqs = synthetic_sequences(3, 6, seed=1)
    p32 = TorchRNNPB(seed=0, epochs=50).train(seqs)
    p64 = TorchRNNPB(seed=0, epochs=50, dtype="float64").train(seqs)
    assert p32.dtype == np.float64
    np.testing.assert_allclose(p32, p64, atol=1e-3)


# -- the native float32 training kernel (_native.c) ----------------------------------

from iloci_torch.native import (ISA_ENV, ISAS, kernel_info, native_isas,  # noqa: E402
                                native_kernel_available)

needs_native = pytest.mark.skipif(not native_kernel_available(),
                                  reason="native kernel not built")


def _train_both(seqs, epochs, **params):
    """The same training with the native kernel and with torch operations."""
    native = TorchRNNPB(seed=4, kernel="native", **params)
    ops = TorchRNNPB(seed=4, kernel="torch", **params)
    return native, native.train(seqs, epochs=epochs), ops, ops.train(seqs, epochs=epochs)


def _max_weight_difference(a, b):
    sa, sb = a.state(), b.state()
    return max(float(np.abs(sa[k] - sb[k]).max()) for k in ("w_in", "b_hidden", "w_out", "b_out"))


@needs_native
@pytest.mark.parametrize("isa", list(ISAS))
@pytest.mark.parametrize("params", [
    {},                                                       # paper sizes: 31 -> 32, 60 -> 64
    {"closed_loop": 0.5, "warmup_epochs": 3, "learning_rate_decay": 0.5},
    {"hidden": 20, "context": 5, "pb": 2},                   # 11 -> 16, 20 -> 32
    {"hidden": 100, "context": 40},                          # 7 and 3 registers per row
], ids=["paper", "teacher-forced-warmup-decay", "small", "wide"])
def test_native_kernel_trains_like_the_torch_operations(params, isa, monkeypatch):
    if isa not in native_isas():
        pytest.skip(f"this CPU cannot run {isa}")
    monkeypatch.setenv(ISA_ENV, isa)
    # lengths differ (masking), the row count is no multiple of the kernel's row block
    seqs = synthetic_sequences(7, 6, lengths=(12, 17, 9))
    native, pbs_native, ops, pbs_ops = _train_both(seqs, 5, **params)
    assert native.kernel_ == f"native kernel ({isa})" and ops.kernel_ == "torch operations"
    # float32, different rounding: 5 epochs stay within a few float32 ulps of the weights
    assert _max_weight_difference(native, ops) < 1e-5
    np.testing.assert_allclose(pbs_native, pbs_ops, atol=1e-5)
    assert native.train_loss_ == pytest.approx(ops.train_loss_, rel=1e-5)


@needs_native
@pytest.mark.parametrize("isa", list(ISAS))
@pytest.mark.parametrize("params", [
    {},
    {"hidden": 20, "context": 5, "pb": 2},
    {"hidden": 100, "context": 40, "recognition_damping": 1.0},
], ids=["paper", "small", "wide-damped"])
def test_native_recognition_steps_like_the_torch_operations(params, isa, monkeypatch):
    """Levenberg-Marquardt in the native kernel: the torch path's steps, other rounding."""
    if isa not in native_isas():
        pytest.skip(f"this CPU cannot run {isa}")
    monkeypatch.setenv(ISA_ENV, isa)
    seqs = synthetic_sequences(6, 6, lengths=(14, 20, 11))
    native = TorchRNNPB(seed=3, epochs=60, **params)
    pbs = native.train(seqs)
    ops = TorchRNNPB(seed=3, kernel="torch", **params)
    ops.load_state(native.state())
    # new drawings: the learned ones, perturbed, started from every stored PB
    rng = np.random.default_rng(0)
    probes = [s + rng.normal(0.0, 0.02, s.shape) for s in seqs]
    got, want = native.recognize(probes, pbs), ops.recognize(probes, pbs)
    # the minima are shallow: float32 rounding (the torch path also forms
    # J^T J in float32, the kernel in float64) moves the PB found by ~1e-3
    np.testing.assert_allclose(got, want, atol=5e-3)
    e_got, e_want = native.prediction_error(probes, got), ops.prediction_error(probes, want)
    np.testing.assert_allclose(e_got, e_want, rtol=1e-3)
    # and the steps did something: the error is below the best start's
    starts = ops.prediction_error(probes, pbs[np.argmin(
        [[ops.prediction_error([p], pbs[[k]])[0] for k in range(len(pbs))] for p in probes],
        axis=1)])
    assert np.all(e_got <= starts + 1e-9) and np.any(e_got < 0.99 * starts)


@needs_native
def test_native_training_pads_no_rows_and_padding_would_change_nothing(monkeypatch):
    seqs = synthetic_sequences(5, 6, lengths=(12, 17, 9))
    a = TorchRNNPB(seed=2)
    assert a._train_multiple() == 1 and TorchRNNPB(seed=2, kernel="torch")._train_multiple() == 4
    pbs_a = a.train(seqs, epochs=20)
    b = TorchRNNPB(seed=2)
    monkeypatch.setattr(b, "_train_multiple", lambda: 4)    # 5 rows padded to 8, as before
    pbs_b = b.train(seqs, epochs=20)
    assert _max_weight_difference(a, b) == 0.0
    np.testing.assert_array_equal(pbs_a, pbs_b)


@needs_native
def test_native_kernel_continues_from_the_current_weights():
    seqs = synthetic_sequences(4, 6)
    native, _, ops, _ = _train_both(seqs, 3)
    native.train(seqs, epochs=3)
    ops.train(seqs, epochs=3)
    assert _max_weight_difference(native, ops) < 1e-5


def test_sizes_beyond_the_native_kernel_use_torch_operations():
    # 257 hidden units pad to 272 columns, more than the kernel's 256
    seqs = synthetic_sequences(3, 6)
    a = TorchRNNPB(seed=4, hidden=257)
    b = TorchRNNPB(seed=4, hidden=257, kernel="torch")
    pbs_a, pbs_b = a.train(seqs, epochs=2), b.train(seqs, epochs=2)
    assert a.kernel_ == "torch operations"
    assert _max_weight_difference(a, b) == 0.0
    np.testing.assert_array_equal(pbs_a, pbs_b)


@needs_native
def test_kernel_native_refuses_what_it_cannot_train():
    from iloci.errors import IlociError
    with pytest.raises(IlociError, match="256 hidden or state units"):
        TorchRNNPB(seed=0, hidden=257, kernel="native").train(synthetic_sequences(2, 6),
                                                               epochs=1)


def test_kernel_setting_is_checked():
    with pytest.raises(InvalidInputError, match="kernel must be"):
        TorchRNNPB(kernel="fast")
    with pytest.raises(InvalidInputError, match="float32 only"):
        TorchRNNPB(kernel="native", dtype="float64")


def test_kernel_torch_trains_with_torch_operations():
    m = TorchRNNPB(seed=0, kernel="torch")
    m.train(synthetic_sequences(2, 6), epochs=1)
    assert m.kernel_ == "torch operations"
    assert kernel_info("torch").startswith("torch operations")
    assert kernel_info("auto", "float64").startswith("torch operations")


@needs_native
def test_forcing_an_instruction_set(monkeypatch):
    from iloci.errors import IlociError
    monkeypatch.setenv(ISA_ENV, "portable")             # runs everywhere it was built
    assert kernel_info() == f"native kernel (portable; forced by {ISA_ENV})"
    monkeypatch.setenv(ISA_ENV, "sse9")
    with pytest.raises(IlociError, match="no instruction set"):
        TorchRNNPB(seed=0).train(synthetic_sequences(2, 6), epochs=1)
    missing = [isa for isa in ISAS if isa not in native_isas()]
    if missing:
        monkeypatch.setenv(ISA_ENV, missing[0])
        with pytest.raises(IlociError, match="cannot run"):
            kernel_info()
    monkeypatch.setenv(ISA_ENV, "auto")
    assert kernel_info() == f"native kernel ({native_isas()[0]})"


@needs_native
def test_native_divergence_leaves_the_model_unchanged():
    from iloci.errors import IlociError
    seqs = [s * 1e30 for s in synthetic_sequences(3, 6)]  # overflows float32
    m = TorchRNNPB(seed=0)
    before = m.state()
    with pytest.raises(IlociError, match="diverged"):
        m.train(seqs, epochs=2)
    after = m.state()
    assert all(np.array_equal(before[k], after[k]) for k in ("w_in", "b_hidden", "w_out"))


def test_native_kernel_is_built_and_used_where_it_can_be():
    # The extension is optional, so a failed build installs silently: catch
    # that here, on machines that have a C compiler.
    import importlib.util
    import shutil
    if not (shutil.which("cc") or shutil.which("gcc")):
        pytest.skip("no C compiler: the native kernel is not expected")
    assert importlib.util.find_spec("iloci_torch._native") is not None, \
        "iloci_torch._native was not compiled at install time"
    assert native_kernel_available()
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
            flags = set(next(line for line in fh if line.startswith("flags")).split())
    except (OSError, StopIteration):
        pytest.skip("no /proc/cpuinfo flags to tell which instruction sets the CPU has")
    expected = tuple(isa for isa, needs in [("avx512", {"avx512f", "fma"}),
                                            ("avx2", {"avx2", "fma"}), ("portable", set())]
                     if needs <= flags)
    assert native_isas() == expected
    m = TorchRNNPB(seed=0)
    m.train(synthetic_sequences(2, 6), epochs=1)
    assert m.kernel_ == f"native kernel ({expected[0]})" == kernel_info()
