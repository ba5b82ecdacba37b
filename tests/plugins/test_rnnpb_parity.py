"""The torch and JAX back ends are the same model.

Tolerances, by what is compared:

* initial weights of the same seed: identical (both hold them in their
  compute dtype, rounded the same way);
* ``generate`` and ``prediction_error`` of the same state and PBs: both
  always compute in float64, so they agree to 1e-12 (absolute), whatever
  dtype the models train in and whichever back end saved the state;
* training in float64 from the same seed: PBs and weights agree to 1e-9
  after 30 epochs (measured: ~1e-13; only the order of floating-point sums
  differs); in float32 to 1e-5 after 10 epochs (measured: ~1e-6);
* recognition in float64, Adam: to 1e-9 (measured ~1e-13); Levenberg-Marquardt:
  identical to ~1e-15 while it is
  still descending (measured after 1-5 steps); once it has converged, a
  step that changes the error only in its last bits is kept by one back end
  and rejected by the other, so recognized PBs agree to 1e-6 (measured:
  ~4e-8, the width of the minimum at float64 resolution) and their
  prediction errors to 1e-12.

Over long trainings the two drift apart like any two runs of a chaotic
optimisation whose arithmetic differs in the last bit (after 300 float64
epochs PBs differ by ~0.1); that both reach the same accuracy is shown by
``offline_ccr`` in ``benchmarks/results/rnnpb.json``.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("jax")

from iloci.rnnpb import WEIGHT_NAMES  # noqa: E402
from iloci.testing.checks import synthetic_sequences  # noqa: E402
from iloci_jax.rnnpb import JaxRNNPB  # noqa: E402
from iloci_torch.rnnpb import TorchRNNPB  # noqa: E402

BACKENDS = {"torch": TorchRNNPB, "jax": JaxRNNPB}


def _seqs():
    return synthetic_sequences(4, 6, (16, 22, 30), seed=3)


def _w(model):
    st = model.state()
    return {k: st[k] for k in WEIGHT_NAMES}


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_same_seed_same_initial_weights(dtype):
    a, b = TorchRNNPB(seed=21, dtype=dtype), JaxRNNPB(seed=21, dtype=dtype)
    for k in WEIGHT_NAMES:
        np.testing.assert_array_equal(_w(a)[k], _w(b)[k])


@pytest.mark.parametrize("src,dst", [("torch", "jax"), ("jax", "torch")])
def test_a_state_from_one_back_end_runs_identically_in_the_other(src, dst):
    seqs = _seqs()
    a = BACKENDS[src](seed=2, epochs=60, learning_rate=0.01)
    pbs = a.train(seqs)
    b = BACKENDS[dst](seed=99)
    b.load_state(a.state())
    assert str(a.state()["backend"]) == src and str(b.state()["backend"]) == dst
    np.testing.assert_array_equal(b.pbs_, a.pbs_)
    for k in WEIGHT_NAMES:
        np.testing.assert_array_equal(_w(b)[k], _w(a)[k])
    x0 = np.stack([s[0] for s in seqs])
    lengths = [len(s) for s in seqs]
    for ga, gb in zip(a.generate(pbs, x0, lengths), b.generate(pbs, x0, lengths)):
        np.testing.assert_allclose(ga, gb, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.prediction_error(seqs, pbs), b.prediction_error(seqs, pbs),
                               rtol=0, atol=1e-12)
    # random PBs too, not only the trained ones
    other = np.random.default_rng(0).uniform(-1, 1, pbs.shape)
    np.testing.assert_allclose(a.prediction_error(seqs, other), b.prediction_error(seqs, other),
                               rtol=0, atol=1e-12)


def test_float64_training_and_recognition_agree():
    seqs = _seqs()
    kw = dict(seed=4, epochs=30, learning_rate=0.01, dtype="float64", recognition_steps=20)
    a, b = TorchRNNPB(**kw), JaxRNNPB(**kw)
    pa, pb = a.train(seqs), b.train(seqs)
    np.testing.assert_allclose(pa, pb, rtol=0, atol=1e-9)
    for k in WEIGHT_NAMES:
        np.testing.assert_allclose(_w(a)[k], _w(b)[k], rtol=0, atol=1e-9)
    ra, rb = a.recognize(seqs), b.recognize(seqs)
    np.testing.assert_allclose(ra, rb, rtol=0, atol=1e-6)
    np.testing.assert_allclose(a.prediction_error(seqs, ra), b.prediction_error(seqs, rb),
                               rtol=0, atol=1e-12)
    # before convergence, step for step the same arithmetic
    a3, b3 = (cls(**{**kw, "recognition_steps": 3}) for cls in (TorchRNNPB, JaxRNNPB))
    a3.train(seqs), b3.train(seqs)
    np.testing.assert_allclose(a3.recognize(seqs), b3.recognize(seqs), rtol=0, atol=1e-12)
    # gradient descent (Adam): the same arithmetic all the way
    ka = {**kw, "recognition_method": "adam", "recognition_steps": 20}
    aa, ba = TorchRNNPB(**ka), JaxRNNPB(**ka)
    aa.train(seqs), ba.train(seqs)
    np.testing.assert_allclose(aa.recognize(seqs), ba.recognize(seqs), rtol=0, atol=1e-9)


def test_float32_training_agrees_loosely():
    seqs = _seqs()
    kw = dict(seed=4, epochs=10, learning_rate=1e-3, pb_learning_rate=1e-3)
    a, b = TorchRNNPB(**kw), JaxRNNPB(**kw)
    np.testing.assert_allclose(a.train(seqs), b.train(seqs), rtol=0, atol=1e-5)
    for k in WEIGHT_NAMES:
        np.testing.assert_allclose(_w(a)[k], _w(b)[k], rtol=0, atol=1e-5)
