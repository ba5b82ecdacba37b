"""The native, torch and JAX back ends are the same model.

Each test runs on every pair of the back ends installed (at least two).
native-rnnpb's float64 paths are the numpy reference; its float32 training
and recognition the C kernel.

Tolerances, by what is compared:

* initial weights of the same seed: identical (each holds them in its
  compute dtype, rounded the same way);
* ``generate`` and ``prediction_error`` of the same state and PBs: all
  always compute in float64, so they agree to 1e-12 (absolute), whatever
  dtype the models train in and whichever back end saved the state;
* training in float64 from the same seed: PBs and weights agree to 1e-9
  after 30 epochs (measured: ~1e-13; only the order of floating-point sums
  differs); in float32 to 1e-5 after 10 epochs (measured: ~1e-6);
* recognition in float64, Adam: to 1e-9 (measured ~1e-13); Levenberg-Marquardt:
  identical to ~1e-12 while it is
  still descending (measured after 1-5 steps); once it has converged, a
  step that changes the error only in its last bits is kept by one back end
  and rejected by the other, so recognized PBs agree to 1e-6 (measured:
  ~4e-8, the width of the minimum at float64 resolution) and their
  prediction errors to 1e-12.

Over long trainings they drift apart like any two runs of a chaotic
optimisation whose arithmetic differs in the last bit (after 300 float64
epochs PBs differ by ~0.1); that all reach the same accuracy is shown by
``offline_ccr`` in ``benchmarks/results/rnnpb.json``.
"""

from __future__ import annotations

from itertools import combinations, permutations

import numpy as np
import pytest

from iloci.rnnpb import WEIGHT_NAMES
from iloci.testing.checks import synthetic_sequences


def _backends() -> dict:
    out = {}
    try:
        from iloci_native.rnnpb import NativeRNNPB
        out["native"] = NativeRNNPB
    except ImportError:
        pass
    try:
        from iloci_torch.rnnpb import TorchRNNPB
        out["torch"] = TorchRNNPB
    except ImportError:
        pass
    try:
        from iloci_jax.rnnpb import JaxRNNPB
        out["jax"] = JaxRNNPB
    except ImportError:
        pass
    return out


pytestmark = pytest.mark.filterwarnings("ignore:native-rnnpb trains on the numpy reference")

BACKENDS = _backends()
if len(BACKENDS) < 2:
    pytest.skip("fewer than two RNNPB back ends installed", allow_module_level=True)
PAIRS = list(combinations(BACKENDS, 2))


def _seqs():
    return synthetic_sequences(4, 6, (16, 22, 30), seed=3)


def _w(model):
    st = model.state()
    return {k: st[k] for k in WEIGHT_NAMES}


@pytest.mark.parametrize("pair", PAIRS, ids="-".join)
@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_same_seed_same_initial_weights(dtype, pair):
    a, b = (BACKENDS[n](seed=21, dtype=dtype) for n in pair)
    for k in WEIGHT_NAMES:
        np.testing.assert_array_equal(_w(a)[k], _w(b)[k])


@pytest.mark.parametrize("src,dst", list(permutations(BACKENDS, 2)))
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


@pytest.mark.parametrize("pair", PAIRS, ids="-".join)
def test_float64_training_and_recognition_agree(pair):
    seqs = _seqs()
    kw = dict(seed=4, epochs=30, learning_rate=0.01, dtype="float64", recognition_steps=20)
    A, B = (BACKENDS[n] for n in pair)
    a, b = A(**kw), B(**kw)
    pa, pb = a.train(seqs), b.train(seqs)
    np.testing.assert_allclose(pa, pb, rtol=0, atol=1e-9)
    for k in WEIGHT_NAMES:
        np.testing.assert_allclose(_w(a)[k], _w(b)[k], rtol=0, atol=1e-9)
    ra, rb = a.recognize(seqs), b.recognize(seqs)
    np.testing.assert_allclose(ra, rb, rtol=0, atol=1e-6)
    np.testing.assert_allclose(a.prediction_error(seqs, ra), b.prediction_error(seqs, rb),
                               rtol=0, atol=1e-12)
    # before convergence, step for step the same arithmetic
    a3, b3 = (cls(**{**kw, "recognition_steps": 3}) for cls in (A, B))
    a3.train(seqs), b3.train(seqs)
    np.testing.assert_allclose(a3.recognize(seqs), b3.recognize(seqs), rtol=0, atol=1e-12)
    # gradient descent (Adam): the same arithmetic all the way
    ka = {**kw, "recognition_method": "adam", "recognition_steps": 20}
    aa, ba = A(**ka), B(**ka)
    aa.train(seqs), ba.train(seqs)
    np.testing.assert_allclose(aa.recognize(seqs), ba.recognize(seqs), rtol=0, atol=1e-9)


@pytest.mark.parametrize("pair", PAIRS, ids="-".join)
def test_float32_training_agrees_loosely(pair):
    seqs = _seqs()
    kw = dict(seed=4, epochs=10, learning_rate=1e-3, pb_learning_rate=1e-3)
    a, b = (BACKENDS[n](**kw) for n in pair)
    np.testing.assert_allclose(a.train(seqs), b.train(seqs), rtol=0, atol=1e-5)
    for k in WEIGHT_NAMES:
        np.testing.assert_allclose(_w(a)[k], _w(b)[k], rtol=0, atol=1e-5)
