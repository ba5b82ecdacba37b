"""The ``native-rnnpb`` perceptual model (plugin iloci-native): the C kernel and its fallbacks.

The kernel's float32 arithmetic is one definition for every instruction
set ("The float32 arithmetic" in ``_native.c``): here each instruction set
this CPU runs is forced in turn and the trained networks, PBs, recognitions
and scores compared bit for bit; ``test_native_aarch64.py`` compares an
aarch64 build under qemu-user with them.
"""

from __future__ import annotations

import hashlib
import subprocess
import sys
import warnings

import numpy as np
import pytest

pytest.importorskip("iloci_native")

from iloci.errors import IlociError, InvalidInputError  # noqa: E402
from iloci.rnnpb import WEIGHT_NAMES  # noqa: E402
from iloci.testing import parametrize_with_checks, registry_factory  # noqa: E402
from iloci.testing.checks import synthetic_sequences  # noqa: E402
from iloci_native.native import (ISA_ENV, ISAS, kernel_info, native_isas,  # noqa: E402
                                 native_kernel_available)
from iloci_native.rnnpb import NativeFallbackWarning, NativeRNNPB  # noqa: E402
from rnnpb_cases import *  # noqa: E402,F401,F403  (shared behaviour tests)

needs_native = pytest.mark.skipif(not native_kernel_available(),
                                  reason="native kernel not built")


def _quiet(**kw):
    """A model whose fallback to the reference (float64, wide) is expected here."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NativeFallbackWarning)
        return NativeRNNPB(**kw)


@pytest.fixture
def make():
    return lambda **kw: _quiet(**kw)


@parametrize_with_checks([("perceptual_model", lambda seed: NativeRNNPB(seed=seed))])
def test_conformance(component, check):
    check(component)


def test_registered_and_built_by_name():
    make = registry_factory("perceptual_model", "native-rnnpb", hidden=20, epochs=7)
    m = make(3)
    assert isinstance(m, NativeRNNPB)
    assert (m.params.hidden, m.params.epochs, m.seed) == (20, 7, 3)


def test_imports_no_torch():
    code = ("import sys, iloci, iloci_native.rnnpb; m = iloci_native.rnnpb.NativeRNNPB(); "
            "print('torch' in sys.modules, 'jax' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False False"


def _checksum(model, *arrays):
    st = model.state()
    h = hashlib.sha256()
    for k in WEIGHT_NAMES:
        h.update(np.ascontiguousarray(st[k]).tobytes())
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def _run_everything(isa, monkeypatch, **params):
    """Train, recognize and score with the instruction set forced; the bits of every result."""
    monkeypatch.setenv(ISA_ENV, isa)
    seqs = synthetic_sequences(7, 6, lengths=(12, 17, 9), seed=5)
    m = NativeRNNPB(seed=4, epochs=150, **params)
    pbs = m.train(seqs)
    assert m.kernel_ == f"native kernel ({isa})"
    rng = np.random.default_rng(0)
    probes = [s + rng.normal(0.0, 0.02, s.shape) for s in seqs]
    rec = m.recognize(probes)
    X, mask, _ = m._padded(probes)
    scores = m._error_kernel(X, mask, np.resize(pbs, (X.shape[1], m.pb_size)), exact=False)
    return _checksum(m, pbs, rec, scores, np.float64(m.train_loss_))


@needs_native
@pytest.mark.parametrize("params", [
    {},                                                       # paper sizes: 31 -> 32, 60 -> 64
    {"closed_loop": 0.5, "warmup_epochs": 3, "learning_rate_decay": 0.5},
    {"hidden": 100, "context": 40, "pb": 2},                 # 7 and 3 registers per row
], ids=["paper", "teacher-forced-warmup-decay", "wide"])
def test_every_instruction_set_computes_the_same_bits(params, monkeypatch):
    isas = native_isas()
    if len(isas) < 2:
        pytest.skip(f"this CPU runs only {isas}: nothing to compare")
    sums = {isa: _run_everything(isa, monkeypatch, **params) for isa in isas}
    assert len(set(sums.values())) == 1, sums


@needs_native
@pytest.mark.parametrize("isa", list(ISAS))
def test_native_kernel_trains_like_the_reference_step_by_step(isa, monkeypatch):
    """Float32 kernel against the float64 numpy reference: the same recipe, other rounding."""
    from iloci.rnnpb import pb_to_u
    from iloci.rnnpb import reference as ref
    if isa not in native_isas():
        pytest.skip(f"this CPU cannot run {isa}")
    monkeypatch.setenv(ISA_ENV, isa)
    seqs = synthetic_sequences(7, 6, lengths=(12, 17, 9))
    m = NativeRNNPB(seed=4, closed_loop=0.5, warmup_epochs=3, learning_rate_decay=0.5)
    w0 = {k: m.state()[k] for k in WEIGHT_NAMES}
    X, mask, per_seq = m._padded(seqs, geometric=False, multiple=1)
    want = ref.train(w0, np.zeros((len(seqs), m.pb_size)), X,
                     mask * (per_seq / len(seqs))[None, :], m.params, 5)
    pbs = m.train(seqs, epochs=5)
    got = m.state()
    for k in WEIGHT_NAMES:
        np.testing.assert_allclose(got[k], want.weights[k], rtol=0, atol=1e-5, err_msg=k)
    np.testing.assert_allclose(pbs, m.params.pb_bound * np.tanh(want.u), atol=1e-5)
    assert pb_to_u(pbs, m.params.pb_bound).shape == (7, m.pb_size)


@needs_native
@pytest.mark.parametrize("params", [
    {},
    {"hidden": 20, "context": 5, "pb": 2},
    {"hidden": 100, "context": 40, "recognition_damping": 1.0},
], ids=["paper", "small", "wide-damped"])
def test_native_recognition_steps_like_the_numpy_ones(params):
    """Levenberg-Marquardt in the kernel (float32) and in numpy (float64): the same steps."""
    seqs = synthetic_sequences(6, 6, lengths=(14, 20, 11))
    native = NativeRNNPB(seed=3, epochs=60, **params)
    pbs = native.train(seqs)
    ref = _quiet(seed=3, dtype="float64", **params)
    ref.load_state(native.state())
    rng = np.random.default_rng(0)
    probes = [s + rng.normal(0.0, 0.02, s.shape) for s in seqs]
    got, want = native.recognize(probes, pbs), ref.recognize(probes, pbs)
    # the minima are shallow: float32 rounding moves the PB found by ~1e-3
    np.testing.assert_allclose(got, want, atol=5e-3)
    e_got, e_want = native.prediction_error(probes, got), ref.prediction_error(probes, want)
    np.testing.assert_allclose(e_got, e_want, rtol=1e-3)
    # and the steps did something: the error is below the best start's
    starts = ref.prediction_error(probes, pbs[np.argmin(
        [[ref.prediction_error([p], pbs[[k]])[0] for k in range(len(pbs))] for p in probes],
        axis=1)])
    assert np.all(e_got <= starts + 1e-9) and np.any(e_got < 0.99 * starts)


@needs_native
def test_native_scores_like_the_reference():
    seqs = synthetic_sequences(5, 6, lengths=(12, 17, 9))
    m = NativeRNNPB(seed=1, epochs=20)
    pbs = m.train(seqs)
    X, mask, _ = m._padded(seqs)
    p = np.zeros((X.shape[1], m.pb_size))
    p[:len(pbs)] = pbs
    np.testing.assert_allclose(m._error_kernel(X, mask, p, exact=False),
                               m._error_kernel(X, mask, p, exact=True), rtol=1e-4, atol=1e-7)


@needs_native
def test_native_training_pads_no_rows_and_padding_would_change_nothing(monkeypatch):
    seqs = synthetic_sequences(5, 6, lengths=(12, 17, 9))
    a = NativeRNNPB(seed=2)
    assert a._train_multiple() == 1
    pbs_a = a.train(seqs, epochs=20)
    b = NativeRNNPB(seed=2)
    monkeypatch.setattr(b, "_train_multiple", lambda: 4)    # 5 rows padded to 8
    pbs_b = b.train(seqs, epochs=20)
    for k in WEIGHT_NAMES:
        np.testing.assert_array_equal(a.state()[k], b.state()[k])
    np.testing.assert_array_equal(pbs_a, pbs_b)


def test_float64_and_wide_sizes_run_the_reference_and_say_so_once():
    seqs = synthetic_sequences(3, 6)
    with pytest.warns(NativeFallbackWarning, match="float64"):
        m = NativeRNNPB(seed=4, dtype="float64")
    with warnings.catch_warnings():
        warnings.simplefilter("error")                     # said once: at build, not per call
        m.train(seqs, epochs=2)
        m.recognize(seqs)
    assert m.kernel_ == "numpy reference"
    # 257 hidden units pad to 272 columns, more than the kernel's 256
    with pytest.warns(NativeFallbackWarning, match="256"):
        w = NativeRNNPB(seed=4, hidden=257)
    w.train(seqs, epochs=1)
    assert w.kernel_ == "numpy reference"


@needs_native
def test_kernel_native_refuses_what_it_cannot_train():
    with pytest.raises(IlociError, match="256 hidden or state units"):
        NativeRNNPB(seed=0, hidden=257, kernel="native")
    with pytest.raises(InvalidInputError, match="float32 only"):
        NativeRNNPB(kernel="native", dtype="float64")
    with pytest.raises(IlociError, match="torch-rnnpb"):
        NativeRNNPB(kernel="torch")


@needs_native
def test_forcing_an_instruction_set(monkeypatch):
    monkeypatch.setenv(ISA_ENV, "portable")             # runs everywhere it was built
    assert kernel_info() == f"native kernel (portable; forced by {ISA_ENV})"
    monkeypatch.setenv(ISA_ENV, "sse9")
    with pytest.raises(IlociError, match="no instruction set"):
        NativeRNNPB(seed=0).train(synthetic_sequences(2, 6), epochs=1)
    missing = [isa for isa in ISAS if isa not in native_isas()]
    if missing:
        monkeypatch.setenv(ISA_ENV, missing[0])
        with pytest.raises(IlociError, match="cannot run"):
            kernel_info()
    monkeypatch.setenv(ISA_ENV, "auto")
    assert kernel_info() == f"native kernel ({native_isas()[0]})"


@needs_native
def test_native_divergence_leaves_the_model_unchanged():
    seqs = [s * 1e30 for s in synthetic_sequences(3, 6)]  # overflows float32
    m = NativeRNNPB(seed=0)
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
    assert importlib.util.find_spec("iloci_native._native") is not None, \
        "iloci_native._native was not compiled at install time"
    assert native_kernel_available()


# -- float64 generation: one order of operations on every CPU ---------------------

@needs_native
@pytest.mark.parametrize("sizes", [{}, {"hidden": 7, "context": 3, "pb": 1}],
                         ids=["paper", "odd"])
def test_generation_computes_the_float64_spec_bit_for_bit(sizes):
    """The kernel's float64 generation (iloci_rnnpb_generate64) is
    iloci.rnnpb.float64.generate64 bit for bit, and within rounding of numpy's ``@``."""
    from iloci.rnnpb.float64 import generate64
    from iloci.rnnpb.reference import reference_outputs

    m = NativeRNNPB(seed=3, epochs=30, **sizes)
    m.train(synthetic_sequences(5, 6, lengths=(12, 17, 9), seed=2))
    rng = np.random.default_rng(4)
    pbs = rng.normal(0.0, 1.0, (5, m.pb_size))
    x0 = rng.normal(0.0, 0.3, (5, m.input_size))
    x0[0, 0] = 25.0                                       # a saturated unit: tanh 1
    got = m._generate_kernel(pbs, x0, 40)
    want = generate64(m.state(), pbs, x0, 40)
    assert got.shape == (40, 5, m.input_size)
    np.testing.assert_array_equal(got.view(np.int64), want.view(np.int64))
    X = np.zeros((41,) + x0.shape)
    X[0] = x0
    np.testing.assert_allclose(got, reference_outputs(m.state(), pbs, X), rtol=0, atol=1e-12)


def test_float64_tanh_is_accurate_and_handles_every_value():
    import math

    from iloci.rnnpb.float64 import tanh64

    x = np.concatenate([np.linspace(-30.0, 30.0, 120001), [0.0, -0.0, 1e-300, -5e-324,
                                                           21.9, 22.0, 22.1, 1e308]])
    got = tanh64(x)
    exact = np.array([math.tanh(v) for v in x])
    ulps = np.abs(got - exact) / np.spacing(np.abs(exact))
    assert ulps.max() <= 4.0         # iloci/rnnpb/float64.py: at most 4 on 1.2M points
    assert np.array_equal(np.signbit(got), np.signbit(x))            # -0.0 stays -0.0
    special = tanh64(np.array([np.inf, -np.inf, np.nan]))
    assert special[0] == 1.0 and special[1] == -1.0 and np.isnan(special[2])


@needs_native
def test_generation_of_special_values_matches_the_spec():
    """Inf and NaN in a first input go through the kernel as through the spec."""
    from iloci.rnnpb.float64 import generate64

    m = NativeRNNPB(seed=1)
    x0 = np.zeros((3, m.input_size))
    x0[1, 0], x0[2, 1] = np.inf, np.nan
    pbs = np.zeros((3, m.pb_size))
    got, want = m._generate_kernel(pbs, x0, 3), generate64(m.state(), pbs, x0, 3)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    np.testing.assert_array_equal(np.nan_to_num(got).view(np.int64),
                                  np.nan_to_num(want).view(np.int64))


#: OpenBLAS kernels to force (``OPENBLAS_CORETYPE``) and the CPU flag each needs.
CORETYPES = {"Nehalem": "sse4_2", "Haswell": "avx2", "SkylakeX": "avx512f"}

_SESSION = """
import pathlib, sys, tempfile
sys.path.insert(0, {tests!r})
import test_golden
from iloci.testing.golden import digest
with tempfile.TemporaryDirectory() as d:
    print(digest(test_golden.sessions(pathlib.Path(d))))
"""


@needs_native
def test_the_scripted_sessions_learn_the_same_bits_with_every_blas_kernel():
    """Same seed, same memory, whatever matrix kernels numpy's OpenBLAS picks for this CPU.

    OpenBLAS chooses its kernels by CPU model; ``OPENBLAS_CORETYPE`` forces one,
    as another machine would pick it. The golden sessions of tests/test_golden.py
    (IK, generation, rehearsal, recognition, the saved memory) must give one
    digest under each kernel this CPU runs; they did not while generation and IK
    used numpy's ``@`` (found when the golden outputs, recorded on one x86-64
    machine, did not hold on another).
    """
    pytest.importorskip("pinocchio")
    from pathlib import Path

    flags = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
    cores = [c for c, flag in CORETYPES.items() if f" {flag}" in flags]
    if len(cores) < 2:
        pytest.skip(f"this CPU runs {cores or 'none'} of {list(CORETYPES)}: nothing to compare")
    tests = str(Path(__file__).resolve().parents[1])
    digests = {}
    for core in cores:
        env = {**__import__("os").environ, "OPENBLAS_CORETYPE": core}
        out = subprocess.run([sys.executable, "-c", _SESSION.format(tests=tests)], env=env,
                             capture_output=True, text=True, timeout=600)
        assert out.returncode == 0, out.stderr[-2000:]
        digests[core] = out.stdout.strip().splitlines()[-1]
    assert len(set(digests.values())) == 1, digests


def test_config_check_refuses_a_kernel_the_back_end_does_not_have():
    """`iloci config check` said ok to kernel = "torch" on native-rnnpb (and "native" on
    jax-rnnpb); the run then refused it. Now the config is refused."""
    from iloci.config import load_config
    from iloci.errors import ConfigError

    OTHERS = ("clusterer", "teacher", "ik", "simulator")  # not looked up: any installed
    with pytest.raises(ConfigError, match=r'kernel = "torch" names torch-rnnpb\'s torch '
                                          r'operations.*name = "torch-rnnpb"'):
        load_config({"perceptual_model": {"name": "native-rnnpb", "kernel": "torch"}},
                    supplied=OTHERS)
    pytest.importorskip("iloci_jax", reason="jax-rnnpb not installed")
    with pytest.raises(ConfigError, match=r"jax-rnnpb has one kernel \(XLA's\), got kernel "
                                          r"= 'native'.*\"native\" is native-rnnpb's"):
        load_config({"perceptual_model": {"name": "jax-rnnpb", "kernel": "native"}},
                    supplied=OTHERS)
