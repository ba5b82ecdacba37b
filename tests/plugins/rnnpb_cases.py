"""Behaviour tests every RNNPB back end must pass (imported by test_torch_rnnpb.py
and test_jax_rnnpb.py, which provide the ``make`` fixture: ``make(**params)``
builds a model of their back end).
"""

from __future__ import annotations

import io

import numpy as np
import pytest

from iloci.errors import InvalidInputError
from iloci.rnnpb import (FORMAT_VERSION, WEIGHT_NAMES, init_weights, make_params,
                         reference_generate, reference_prediction_error)
from iloci.testing.checks import synthetic_sequences


def _seqs(n=4, lengths=(20, 24, 28), seed=0):
    return synthetic_sequences(n, 6, lengths, seed=seed)


def _weights(model):
    st = model.state()
    return {k: st[k] for k in WEIGHT_NAMES}


# -- the network is the one defined in iloci.rnnpb ------------------------

def test_generate_and_error_match_the_numpy_reference(make):
    m = make(seed=3)
    seqs = _seqs()
    pbs = np.random.default_rng(1).uniform(-0.8, 0.8, (len(seqs), 4))
    w = _weights(m)
    np.testing.assert_allclose(m.prediction_error(seqs, pbs),
                               reference_prediction_error(w, seqs, pbs), rtol=1e-12, atol=1e-14)
    x0 = np.stack([s[0] for s in seqs])
    lengths = [len(s) for s in seqs]
    for a, b in zip(m.generate(pbs, x0, lengths), reference_generate(w, pbs, x0, lengths)):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-14)


def test_initial_weights_are_the_shared_seeded_ones(make):
    m = make(seed=11)
    expected = init_weights(make_params(), 11)
    for k in WEIGHT_NAMES:
        np.testing.assert_allclose(_weights(m)[k], expected[k], rtol=0, atol=1e-7)
    assert not np.allclose(_weights(make(seed=12))["w_in"], expected["w_in"])


def test_generate_lengths_and_first_row(make):
    m = make()
    pbs = np.zeros((3, 4))
    x0 = np.full((3, 6), 0.1)
    out = m.generate(pbs, x0, [1, 5, 12])
    assert [o.shape for o in out] == [(1, 6), (5, 6), (12, 6)]
    assert all(np.array_equal(o[0], x0[i]) for i, o in enumerate(out))
    # a shorter run is the prefix of a longer one (closed loop, same PB)
    np.testing.assert_allclose(out[1], out[2][:5], rtol=0, atol=1e-14)


# -- training -----------------------------------------------------------------

def test_training_lowers_the_error_and_pbs_separate_patterns(make):
    m = make(seed=0, epochs=400, learning_rate=0.01)
    seqs = _seqs(4)
    before = m.prediction_error(seqs, np.zeros((4, 4))).mean()
    pbs = m.train(seqs)
    after = m.prediction_error(seqs, pbs).mean()
    assert after < 0.5 * before, (before, after)
    assert np.isfinite(m.train_loss_)
    d = np.linalg.norm(pbs[:, None] - pbs[None], axis=-1)
    assert d[~np.eye(4, dtype=bool)].min() > 0.05, "each pattern should get its own PB"
    np.testing.assert_array_equal(m.pbs_, pbs)


def test_training_continues_from_the_current_weights(make):
    seqs = _seqs(3)
    m = make(seed=0, epochs=150, learning_rate=0.01)
    pbs = m.train(seqs)
    first = m.train_loss_
    w_now = _weights(m)
    # zero epochs changes nothing ...
    m.train(seqs, pbs_init=pbs, epochs=0)
    for k in WEIGHT_NAMES:
        np.testing.assert_array_equal(_weights(m)[k], w_now[k])
    # ... and a second call (a rehearsal) starts where the first ended: a few
    # epochs keep the loss near the first call's (the warm-up spares the
    # trained weights Adam's first full-size steps), far below a fresh
    # model's after as many epochs
    m.train(seqs, pbs_init=pbs, epochs=5)
    fresh = make(seed=0, epochs=5, learning_rate=0.01)
    fresh.train(seqs)
    assert m.train_loss_ < 1.1 * first and m.train_loss_ < 0.5 * fresh.train_loss_


def test_warmup_protects_trained_weights_at_the_start_of_a_rehearsal(make):
    seqs = _seqs(3)
    losses = {}
    for warmup in (0, 50):
        m = make(seed=0, epochs=150, learning_rate=0.01, warmup_epochs=warmup)
        pbs = m.train(seqs)
        m.train(seqs, pbs_init=pbs, epochs=5)
        losses[warmup] = m.train_loss_
    assert losses[50] < losses[0]


def test_a_calls_learning_rate_trains_as_a_model_built_with_it(make):
    """train(learning_rate=...) (a rehearsal's rate) is params.learning_rate for that call."""
    seqs = _seqs(3)
    given = make(seed=0, epochs=40)
    built = make(seed=0, epochs=40, learning_rate=0.001)
    pbs = given.train(seqs, learning_rate=0.001)
    np.testing.assert_array_equal(pbs, built.train(seqs))
    assert given.train_loss_ == built.train_loss_
    for k in WEIGHT_NAMES:
        np.testing.assert_array_equal(_weights(given)[k], _weights(built)[k])
    assert given.params.learning_rate == 0.005          # the model's own rate is kept
    # and a different rate gives different weights: the argument is read
    other = make(seed=0, epochs=40)
    other.train(seqs, learning_rate=0.02)
    assert not np.array_equal(_weights(other)["w_in"], _weights(built)["w_in"])
    for bad in (0.0, -0.001, float("nan"), float("inf"), "0.001", True):
        with pytest.raises(InvalidInputError, match="learning_rate"):
            given.train(seqs, epochs=1, learning_rate=bad)


def test_a_state_saved_before_rehearsal_learning_rate_takes_the_loading_models(make):
    m = make(seed=2, epochs=10)
    m.train(_seqs(2))
    st = m.state()
    assert float(st["param.rehearsal_learning_rate"]) == 0.001
    old = {k: v for k, v in st.items() if k != "param.rehearsal_learning_rate"}
    other = make(seed=0, rehearsal_learning_rate=0.002)
    other.load_state(old)
    assert other.params.rehearsal_learning_rate == 0.002
    other.load_state(st)                                # a newer state brings its own
    assert other.params.rehearsal_learning_rate == 0.001


def test_pbs_stay_inside_the_bound(make):
    m = make(seed=0, epochs=200, pb_bound=0.3, pb_learning_rate=0.5)
    pbs = m.train(_seqs(4), pbs_init=np.full((4, 4), 5.0))  # starts beyond the bound
    assert np.all(np.abs(pbs) < 0.3)
    rec = m.recognize(_seqs(2), candidate_pbs=np.full((1, 4), -9.0))
    assert np.all(np.abs(rec) < 0.3)


def test_padding_does_not_leak_into_training(make):
    """A sequence trained alone, or beside a longer one with zero weight, gets the same update."""
    a, b = _seqs(2, lengths=(15, 30))
    m1, m2 = make(seed=5, dtype="float64"), make(seed=5, dtype="float64")
    X1, mask1, per1 = m1._padded([a])
    X2, mask2, per2 = m2._padded([a, b])
    per2[1:] = 0.0  # b present in the batch but weighted out: only masking separates them
    u1 = np.zeros((X1.shape[1], 4))
    u2 = np.zeros((X2.shape[1], 4))
    u1, _ = m1._train_kernel(X1, mask1, per1, u1, 3)
    u2, _ = m2._train_kernel(X2, mask2, per2, u2, 3)
    np.testing.assert_allclose(u1[0], u2[0], rtol=1e-9, atol=1e-12)
    for k in WEIGHT_NAMES:
        np.testing.assert_allclose(_weights(m1)[k], _weights(m2)[k], rtol=1e-9, atol=1e-12)


def test_training_is_seeded(make):
    seqs = _seqs(3)
    p1 = make(seed=4, epochs=30).train(seqs)
    p2 = make(seed=4, epochs=30).train(seqs)
    p3 = make(seed=5, epochs=30).train(seqs)
    np.testing.assert_array_equal(p1, p2)
    assert not np.allclose(p1, p3)


# -- recognition ----------------------------------------------------------------

@pytest.mark.parametrize("method", [{}, {"recognition_method": "adam",
                                           "recognition_steps": 200}],
                         ids=["lm", "adam"])
def test_recognition_finds_the_trained_pb(make, method):
    seqs = _seqs(4)
    m = make(seed=0, epochs=400, learning_rate=0.01, **method)
    pbs = m.train(seqs)
    rec = m.recognize(seqs)
    # the recognized PB fits its sequence at least as well as the trained one
    assert np.all(m.prediction_error(seqs, rec) <= m.prediction_error(seqs, pbs) * 1.05 + 1e-6)
    d = np.linalg.norm(rec[:, None] - pbs[None], axis=-1)
    np.testing.assert_array_equal(d.argmin(axis=1), np.arange(4))


def test_lm_recognition_gets_as_far_as_200_adam_steps(make):
    """The default (10 Levenberg-Marquardt steps) against RNNPB's usual gradient descent.

    From the default starts (stored PBs + zero). From the zero PB alone,
    LM can stop in the nearest local minimum where Adam's momentum carries
    on (measured here: one of 4 sequences, error 0.107 against 0.0075).
    """
    seqs = _seqs(4)
    lm = make(seed=3, epochs=300, learning_rate=0.01)
    lm.train(seqs)
    adam = make(seed=0)
    adam.load_state({**lm.state(), "param.recognition_method": np.array("adam"),
                     "param.recognition_steps": np.array(200)})
    e_lm = lm.prediction_error(seqs, lm.recognize(seqs))
    e_adam = adam.prediction_error(seqs, adam.recognize(seqs))
    assert np.all(e_lm <= e_adam * 1.001 + 1e-9)


def test_recognition_multistart_beats_a_single_zero_start(make):
    seqs = _seqs(4)
    m = make(seed=0, epochs=400, learning_rate=0.01, recognition_steps=30)
    m.train(seqs)
    multi = m.recognize(seqs)                                   # stored PBs + zero
    zero = m.recognize(seqs, candidate_pbs=np.zeros((0, 4)))    # the zero PB alone
    e_multi, e_zero = m.prediction_error(seqs, multi), m.prediction_error(seqs, zero)
    assert e_multi.mean() < e_zero.mean()


def test_recognize_batch_equals_one_at_a_time(make):
    seqs = _seqs(3, lengths=(18, 30, 24))
    m = make(seed=1, epochs=100, dtype="float64")
    m.train(seqs)
    batch = m.recognize(seqs)
    for i, s in enumerate(seqs):
        np.testing.assert_allclose(m.recognize([s])[0], batch[i], rtol=1e-6, atol=1e-8)


# -- state ----------------------------------------------------------------------

def test_state_is_versioned_and_pickle_free(make, tmp_path):
    m = make(seed=2, epochs=20, hidden=30)
    seqs = _seqs(3)
    pbs = m.train(seqs)
    st = m.state()
    assert str(st["format"]) == "iloci-rnnpb" and int(st["version"]) == FORMAT_VERSION
    assert int(st["param.hidden"]) == 30 and st["w_in"].shape == (6 + 25 + 4, 30)
    np.testing.assert_array_equal(st["pbs"], pbs)
    path = tmp_path / "rnnpb.npz"
    np.savez(path, **st)
    with np.load(path, allow_pickle=False) as f:
        loaded = {k: f[k] for k in f.files}
    other = make(seed=9)                          # paper sizes: H = 60
    other.load_state(loaded)
    assert other.params.hidden == 30
    np.testing.assert_array_equal(other.pbs_, pbs)
    np.testing.assert_allclose(other.prediction_error(seqs, pbs), m.prediction_error(seqs, pbs),
                               rtol=0, atol=1e-12)


def test_a_version_1_state_recognizes_as_it_was_saved(make):
    """Format 1 predates recognition_method: its recognition_steps counted Adam steps."""
    m = make(seed=2, epochs=20)
    m.train(_seqs(2))
    old = {k: v for k, v in m.state().items() if k != "param.recognition_method"}
    old.update({"version": np.array(1), "param.recognition_steps": np.array(200)})
    other = make(seed=0)
    other.load_state(old)
    assert other.params.recognition_method == "adam"
    assert other.params.recognition_steps == 200


def test_an_unknown_recognition_method_is_refused(make):
    with pytest.raises(InvalidInputError, match="recognition_method"):
        make(seed=0, recognition_method="newton")


def test_bad_states_are_refused(make):
    m = make(seed=0)
    good = m.state()
    bad = [
        ("a list", [1, 2]),
        ("wrong format", {**good, "format": np.array("something-else")}),
        ("newer version", {**good, "version": np.array(FORMAT_VERSION + 1)}),
        ("missing weights", {k: v for k, v in good.items() if k != "w_out"}),
        ("wrong shape", {**good, "w_in": np.zeros((3, 3))}),
        ("NaN weights", {**good, "b_out": np.full(31, np.nan)}),
        ("bad PBs", {**good, "pbs": np.zeros((2, 7))}),
    ]
    for what, state in bad:
        try:
            m.load_state(state)
        except InvalidInputError:
            continue
        pytest.fail(f"load_state accepted a bad state ({what})")
    # a refused state leaves the model as it was
    for k in WEIGHT_NAMES:
        np.testing.assert_array_equal(m.state()[k], good[k])


# -- bad input ------------------------------------------------------------------

BAD_SEQUENCES = {
    "empty list": ([], "empty"),
    "NaN": ([np.r_[np.zeros((4, 6)), np.full((1, 6), np.nan)]], "NaN"),
    "inf": ([np.r_[np.zeros((4, 6)), np.full((1, 6), np.inf)]], "NaN or inf"),
    "wrong width": ([np.zeros((10, 5))], "(T, 6)"),
    "length 1": ([np.zeros((1, 6))], "at least 2"),
    "1-D": ([np.zeros(6)], "(T, 6)"),
    "one bare array": (np.zeros((10, 6)), "wrap a single sequence"),
    "not numeric": ([[["a"] * 6] * 3], "numeric"),
}


@pytest.mark.parametrize("case", list(BAD_SEQUENCES))
def test_bad_sequences_raise_one_clear_error(make, case):
    seqs, words = BAD_SEQUENCES[case]
    m = make()
    for call in (lambda: m.train(seqs, None, 1), lambda: m.recognize(seqs),
                 lambda: m.prediction_error(seqs, np.zeros((max(len(seqs), 1), 4)))):
        with pytest.raises(InvalidInputError) as exc:
            call()
        assert words in str(exc.value), str(exc.value)


def test_bad_arguments_raise_one_clear_error(make):
    m = make()
    seqs = _seqs(2)
    cases = [
        lambda: m.train(seqs, pbs_init=np.zeros((3, 4))),          # wrong count
        lambda: m.train(seqs, pbs_init=np.zeros((2, 5))),          # wrong width
        lambda: m.train(seqs, epochs=-1),
        lambda: m.train(seqs, epochs=2.5),
        lambda: m.recognize(seqs, candidate_pbs=np.zeros((3, 2))),
        lambda: m.recognize(seqs, candidate_pbs=np.full((1, 4), np.nan)),
        lambda: m.prediction_error(seqs, np.zeros((1, 4))),
        lambda: m.generate(np.zeros((2, 4)), np.zeros((2, 6)), [5]),
        lambda: m.generate(np.zeros((2, 4)), np.zeros((2, 6)), [5, 0]),
        lambda: m.generate(np.zeros((2, 4)), np.zeros((2, 6)), [5, 2.5]),
        lambda: m.generate(np.zeros((2, 4)), np.zeros((1, 6)), [5, 5]),
        lambda: m.generate(np.zeros((0, 4)), np.zeros((0, 6)), []),
        lambda: m.generate(np.zeros((1, 4)), np.full((1, 6), np.nan), [3]),
    ]
    for i, call in enumerate(cases):
        with pytest.raises(InvalidInputError):
            call()
            pytest.fail(f"case {i} raised nothing")


def test_bad_parameters_raise_one_clear_error(make):
    for kw in ({"hidden": 0}, {"closed_loop": 1.5}, {"dtype": "float16"},
               {"learning_rate": -1.0}, {"rehearsal_learning_rate": 0.0},
               {"no_such_setting": 1}):
        with pytest.raises(InvalidInputError):
            make(**kw)
    with pytest.raises(InvalidInputError):
        make(seed="zero")


def test_state_round_trips_through_an_in_memory_npz(make):
    m = make(seed=1, epochs=10)
    m.train(_seqs(2))
    buf = io.BytesIO()
    np.savez(buf, **m.state())
    buf.seek(0)
    with np.load(buf, allow_pickle=False) as f:
        st = {k: f[k] for k in f.files}
    m2 = make(seed=2)
    m2.load_state(st)
    for k in WEIGHT_NAMES:
        np.testing.assert_array_equal(m2.state()[k], m.state()[k])
