"""The ``jax-rnnpb`` perceptual model (plugin iloci-jax)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

jax = pytest.importorskip("jax")

import jax.numpy as jnp  # noqa: E402

from iloci.rnnpb import init_weights, make_params, pad_sequences  # noqa: E402
from iloci.testing import parametrize_with_checks, registry_factory  # noqa: E402
from iloci.testing.checks import synthetic_sequences  # noqa: E402
from iloci_jax import rnnpb as jr  # noqa: E402
from iloci_jax.rnnpb import JaxRNNPB  # noqa: E402
from rnnpb_cases import *  # noqa: E402,F401,F403  (shared behaviour tests)


@pytest.fixture
def make():
    return lambda **kw: JaxRNNPB(**kw)


@parametrize_with_checks([("perceptual_model", lambda seed: JaxRNNPB(seed=seed))])
def test_conformance(component, check):
    check(component)


def test_registered_and_built_by_name():
    make = registry_factory("perceptual_model", "jax-rnnpb", context=10, pb=2)
    m = make(1)
    assert isinstance(m, JaxRNNPB)
    assert (m.params.context, m.pb_size, m.seed) == (10, 2, 1)


def test_plugin_module_imports_without_jax():
    code = "import sys, iloci_jax; print('jax' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("alpha", [1.0, 0.5, 0.0])
def test_hand_written_bptt_equals_jax_grad(alpha):
    seqs = synthetic_sequences(3, 6, (12, 17, 9), seed=2)
    X, mask = pad_sequences(seqs, 4)
    rng = np.random.default_rng(0)
    weight = rng.uniform(0.5, 2.0, size=4)
    pb = rng.uniform(-0.9, 0.9, (4, 4))
    with jax.enable_x64(True):
        w = {k: jnp.asarray(v) for k, v in init_weights(make_params(), 7).items()}
        args = (jnp.asarray(X), jnp.asarray(mask), jnp.asarray(weight))
        loss, grads, g_pb = jr._loss_and_grads(w, jnp.asarray(pb), *args, alpha, True)

        def plain(w, pb):  # the same loss, differentiated by JAX
            O = jr._forward(w, pb, args[0], alpha, keep=False)
            se = ((O[:, :, :6] - args[0][1:]) ** 2).mean(axis=2)
            return jnp.sum(se * args[1] * args[2][None])

        ref_w, ref_pb = jax.grad(plain, argnums=(0, 1))(w, jnp.asarray(pb))
        assert float(loss) == pytest.approx(float(plain(w, jnp.asarray(pb))), rel=1e-12)
        for k in grads:
            np.testing.assert_allclose(grads[k], ref_w[k], rtol=1e-9, atol=1e-13)
        np.testing.assert_allclose(g_pb, ref_pb, rtol=1e-9, atol=1e-13)


def test_float64_does_not_switch_jax_to_64_bits_globally():
    before = jax.config.jax_enable_x64
    m = JaxRNNPB(seed=0, epochs=5, dtype="float64")
    m.train(synthetic_sequences(2, 6))
    assert jax.config.jax_enable_x64 == before
    assert jnp.zeros(1).dtype == (jnp.float64 if before else jnp.float32)


def test_float32_and_float64_train_alike():
    seqs = synthetic_sequences(3, 6, seed=1)
    p32 = JaxRNNPB(seed=0, epochs=50).train(seqs)
    p64 = JaxRNNPB(seed=0, epochs=50, dtype="float64").train(seqs)
    assert p32.dtype == np.float64
    # float32 rounding compounds over 50 epochs of closed-loop BPTT; the PBs
    # stay within 1 % of the PB range
    np.testing.assert_allclose(p32, p64, atol=1e-2)
