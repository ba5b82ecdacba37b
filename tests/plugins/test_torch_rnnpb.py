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


def test_kernel_native_is_native_rnnpbs():
    from iloci.errors import IlociError
    with pytest.raises(IlociError, match="native-rnnpb"):
        TorchRNNPB(kernel="native")
    m = TorchRNNPB(seed=0, kernel="torch")
    m.train(synthetic_sequences(2, 6), epochs=1)
    assert m.kernel_ == "torch operations"


def test_kernel_setting_is_checked():
    with pytest.raises(InvalidInputError, match="kernel must be"):
        TorchRNNPB(kernel="fast")
