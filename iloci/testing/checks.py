"""Conformance checks, one list per interface (a robot preset's in :mod:`iloci.testing.robots`).

Each check is a function ``check(make) -> None`` that raises
``AssertionError`` (or any exception) with a message when the component
misbehaves. ``make(seed)`` builds a fresh component; checks build as many as
they need (determinism and state round trips need two).
"""

from __future__ import annotations

from collections.abc import Callable
import io
from typing import Any

import numpy as np

from iloci.errors import IlociError, InvalidInputError, UnreachableTargetError
from iloci.interfaces import Demonstration, Execution, Response
from iloci.sensorimotor.robots import get_robot
from iloci.testing.robots import ROBOT_CHECKS

Factory = Callable[[int], Any]
#: A conformance check: raises when the component ``make`` builds misbehaves.
Check = Callable[[Factory], None]


# -- helpers -----------------------------------------------------------------

def _expect_error(fn: Callable[[], Any], what: str,
                  types: tuple[type[BaseException], ...] = (IlociError,)) -> None:
    """``fn`` must raise one of ``types`` (an iloci error), not a deep traceback."""
    try:
        fn()
    except types:
        return
    except Exception as exc:  # the wrong kind of error
        raise AssertionError(
            f"{what}: raised {type(exc).__name__} ({exc}); expected an iloci error "
            f"({', '.join(t.__name__ for t in types)}) with a clear message") from None
    raise AssertionError(f"{what}: no error raised")


def _has(obj: Any, *names: str) -> None:
    missing = [n for n in names if not hasattr(obj, n)]
    assert not missing, f"missing attribute(s)/method(s): {', '.join(missing)}"


def synthetic_sequences(n: int, width: int, lengths: tuple[int, ...] = (20, 24, 28),
                        seed: int = 0) -> list[np.ndarray]:
    """Smooth, distinct sequences for perceptual-model checks, each (T_i, width)."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        t = np.linspace(0, 1, lengths[i % len(lengths)])[:, None]
        freq = rng.uniform(0.5, 2.0, size=width)
        phase = rng.uniform(0, 2 * np.pi, size=width)
        out.append(0.5 * np.sin(2 * np.pi * freq * t + phase))
    return out


# -- PerceptualModel -----------------------------------------------------------

def _pm_data(m: Any) -> list[np.ndarray]:
    return synthetic_sequences(3, int(m.input_size))


def pm_protocol(make: Factory) -> None:
    m = make(0)
    _has(m, "input_size", "pb_size", "train", "recognize", "generate", "prediction_error",
         "state", "load_state")
    assert int(m.input_size) >= 1 and int(m.pb_size) >= 1, "sizes must be positive"


def pm_shapes_and_dtypes(make: Factory) -> None:
    m = make(0)
    seqs = _pm_data(m)
    pbs = np.asarray(m.train(seqs, None, 5))
    assert pbs.shape == (3, m.pb_size), f"train returned shape {pbs.shape}"
    assert pbs.dtype == np.float64 and np.all(np.isfinite(pbs)), "train: float64, finite"
    rec = np.asarray(m.recognize(seqs))
    assert rec.shape == (3, m.pb_size) and rec.dtype == np.float64, \
        f"recognize returned {rec.shape} {rec.dtype}"
    gen = m.generate(pbs, np.stack([s[0] for s in seqs]), [len(s) for s in seqs])
    assert len(gen) == 3, "generate must return one sequence per PB"
    for g, s in zip(gen, seqs):
        g = np.asarray(g)
        assert g.shape == s.shape and g.dtype == np.float64, f"generate gave {g.shape}"
        np.testing.assert_allclose(g[0], s[0], err_msg="generate: row 0 is the initial input")
    err = np.asarray(m.prediction_error(seqs, pbs))
    assert err.shape == (3,) and np.all(err >= 0), f"prediction_error gave {err}"


def pm_deterministic(make: Factory) -> None:
    a, b = make(3), make(3)
    seqs = _pm_data(a)
    pa, pb = np.asarray(a.train(seqs, None, 5)), np.asarray(b.train(seqs, None, 5))
    np.testing.assert_allclose(pa, pb, rtol=0, atol=1e-9,
                               err_msg="same seed, same data: train must give the same PBs")
    np.testing.assert_allclose(a.recognize(seqs), b.recognize(seqs), rtol=0, atol=1e-9,
                               err_msg="same seed: recognize must agree")


def pm_state_round_trip(make: Factory) -> None:
    a = make(0)
    seqs = _pm_data(a)
    pbs = np.asarray(a.train(seqs, None, 5))
    state = a.state()
    assert isinstance(state, dict) and state, "state() must be a non-empty dict"
    # Must survive a pickle-free file round trip.
    buf = io.BytesIO()
    np.savez(buf, allow_pickle=False, **{k: np.asarray(v) for k, v in state.items()})
    buf.seek(0)
    with np.load(buf, allow_pickle=False) as f:
        loaded = {k: f[k] for k in f.files}
    b = make(99)
    b.load_state(loaded)
    x0 = np.stack([s[0] for s in seqs])
    lengths = [len(s) for s in seqs]
    for ga, gb in zip(a.generate(pbs, x0, lengths), b.generate(pbs, x0, lengths)):
        np.testing.assert_allclose(ga, gb, rtol=0, atol=1e-9,
                                   err_msg="load_state(state()) must reproduce generate")
    np.testing.assert_allclose(a.prediction_error(seqs, pbs), b.prediction_error(seqs, pbs),
                               rtol=0, atol=1e-9, err_msg="state round trip: prediction_error")


def pm_batch_vs_single(make: Factory) -> None:
    m = make(0)
    seqs = _pm_data(m)
    pbs = np.asarray(m.train(seqs, None, 5))
    x0 = np.stack([s[0] for s in seqs])
    lengths = [len(s) for s in seqs]
    batch = m.generate(pbs, x0, lengths)
    for i in range(3):
        one = m.generate(pbs[i:i + 1], x0[i:i + 1], lengths[i:i + 1])[0]
        np.testing.assert_allclose(batch[i], one, rtol=1e-6, atol=1e-8,
                                   err_msg="generate of a batch differs from one at a time")
    err = m.prediction_error(seqs, pbs)
    for i in range(3):
        np.testing.assert_allclose(err[i], m.prediction_error(seqs[i:i + 1], pbs[i:i + 1])[0],
                                   rtol=1e-6, atol=1e-9,
                                   err_msg="prediction_error: batch vs single")


def pm_bad_input(make: Factory) -> None:
    m = make(0)
    seqs = _pm_data(m)
    nan = [s.copy() for s in seqs]
    nan[1][3, 0] = np.nan
    wide = [np.zeros((10, m.input_size + 1))]
    short = [np.zeros((1, m.input_size))]
    for name, fn in [
        ("train([])", lambda: m.train([], None, 1)),
        ("train with NaN", lambda: m.train(nan, None, 1)),
        ("train with wrong width", lambda: m.train(wide, None, 1)),
        ("train with a length-1 sequence", lambda: m.train(short, None, 1)),
        ("recognize([])", lambda: m.recognize([])),
        ("recognize with NaN", lambda: m.recognize(nan)),
        ("recognize with wrong width", lambda: m.recognize(wide)),
    ]:
        _expect_error(fn, name, (InvalidInputError,))


PERCEPTUAL_MODEL_CHECKS: list[Check] = [pm_protocol, pm_shapes_and_dtypes, pm_deterministic,
                                        pm_state_round_trip, pm_batch_vs_single, pm_bad_input]


# -- Clusterer ---------------------------------------------------------------

def _complete_link_ok(x: np.ndarray, labels: np.ndarray, t: float) -> None:
    from scipy.spatial.distance import pdist, squareform
    d = squareform(pdist(x))
    groups = [np.flatnonzero(labels == k) for k in np.unique(labels)]
    for g in groups:
        assert d[np.ix_(g, g)].max() <= t + 1e-12, "a cluster's diameter exceeds the threshold"
    for i, g in enumerate(groups):
        for h in groups[i + 1:]:
            assert d[np.ix_(g, h)].max() > t, \
                "two clusters could still merge under complete link (distance <= threshold)"


def cl_protocol(make: Factory) -> None:
    """The clusterer has ``cluster(points, distance_threshold)``."""
    _has(make(0), "cluster")


def cl_shapes_and_labels(make: Factory) -> None:
    """Labels: integer, shape (M,), ``0..K-1`` in order of first appearance; one point, one cluster.

    Says nothing about which partition: ``cl_complete_link`` checks that.
    """
    c = make(0)
    rng = np.random.default_rng(0)
    x = rng.normal(size=(15, 4))
    labels = np.asarray(c.cluster(x, 1.5))
    assert labels.shape == (15,), f"labels shape {labels.shape}"
    assert np.issubdtype(labels.dtype, np.integer), f"labels dtype {labels.dtype}"
    firsts = [int(labels[np.flatnonzero(labels == k)[0]]) for k in labels]
    seen: list[int] = []
    for v in firsts:
        if v not in seen:
            seen.append(v)
    assert seen == list(range(len(seen))), "labels must be 0.. in order of first appearance"
    assert np.asarray(c.cluster(x[:1], 1.0)).tolist() == [0], "one point is one cluster"


def cl_complete_link(make: Factory) -> None:
    """The partition is complete link's at the cut (the Clusterer contract).

    On 20 random point sets (2 to 24 points in 3-D, thresholds 0.3 to 3):
    every cluster's diameter is ``<= threshold`` and every two clusters'
    complete-link distance is ``> threshold``. Complete link only: a
    single-link, average-link, k-means or (H)DBSCAN clusterer fails here,
    since its partitions differ.
    """
    c = make(0)
    rng = np.random.default_rng(1)
    for _ in range(20):
        x = rng.normal(size=(int(rng.integers(2, 25)), 3))
        t = float(rng.uniform(0.3, 3.0))
        _complete_link_ok(x, np.asarray(c.cluster(x, t)), t)


def cl_deterministic(make: Factory) -> None:
    """Two clusterers made with the same seed give the same labels for the same points."""
    rng = np.random.default_rng(2)
    x = rng.normal(size=(20, 4))
    a = np.asarray(make(0).cluster(x, 1.2))
    b = np.asarray(make(0).cluster(x, 1.2))
    assert np.array_equal(a, b), "same input must give the same labels"


def cl_bad_input(make: Factory) -> None:
    """NaN points, 1-D points and a negative threshold raise ``InvalidInputError``."""
    c = make(0)
    x = np.zeros((4, 2))
    x[1, 1] = np.nan
    _expect_error(lambda: c.cluster(x, 1.0), "cluster with NaN", (InvalidInputError,))
    _expect_error(lambda: c.cluster(np.zeros(4), 1.0), "cluster 1-D points",
                  (InvalidInputError,))
    _expect_error(lambda: c.cluster(np.zeros((3, 2)), -1.0), "negative threshold",
                  (InvalidInputError,))


CLUSTERER_CHECKS: list[Check] = [cl_protocol, cl_shapes_and_labels, cl_complete_link,
                                 cl_deterministic, cl_bad_input]


# -- Teacher -----------------------------------------------------------------

def _demo(shape: str = "GShape", index: int = 0, concept: str | None = "GShape") -> Demonstration:
    t = np.linspace(0, 1, 30)
    pos = np.column_stack([np.cos(3 * t + index), np.sin(2 * t)])
    return Demonstration(pos, t, shape=shape, index=index, true_concept=concept)


def _response(source: str) -> Response:
    t = np.linspace(0, 1, 30)
    return Response(concept="c0", motion=np.column_stack([t, t ** 2]), source=source,
                    sources=(source,))


def te_protocol(make: Factory) -> None:
    _has(make(0), "feedback")


def te_feedback_values(make: Factory) -> None:
    t = make(0)
    for i, src in enumerate(["GShape/1", "Sine/2", "GShape/3", "Angle/0"]):
        v = t.feedback(_demo(index=i), _response(src))
        assert isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v in (1, -1), \
            f"feedback must be the int +1 or -1, got {v!r}"


def te_deterministic(make: Factory) -> None:
    def run(teacher: Any) -> list[int]:
        return [int(teacher.feedback(_demo(index=i), _response(s)))
                for i, s in enumerate(["GShape/1", "Sine/2"] * 10)]
    assert run(make(5)) == run(make(5)), "same seed must give the same feedback sequence"


TEACHER_CHECKS: list[Check] = [te_protocol, te_feedback_values, te_deterministic]


# -- IKSolver ----------------------------------------------------------------

def _q_path(ik: Any, n: int = 40, seed: int = 0) -> np.ndarray:
    lo, hi = np.asarray(ik.lower, float), np.asarray(ik.upper, float)
    mid, half = (lo + hi) / 2, (hi - lo) / 2
    s = np.linspace(0, 1, n)[:, None]
    rng = np.random.default_rng(seed)
    phase = rng.uniform(0, 2 * np.pi, size=len(lo))
    return mid + 0.3 * half * np.sin(2 * np.pi * s + phase)


def ik_protocol(make: Factory) -> None:
    ik = make(0)
    _has(ik, "joint_names", "lower", "upper", "solve", "forward")
    j = len(ik.joint_names)
    assert np.shape(ik.lower) == (j,) and np.shape(ik.upper) == (j,), "limits shape (J,)"
    assert np.all(np.asarray(ik.lower) < np.asarray(ik.upper)), "lower < upper"


def ik_forward_shapes_batch_vs_single(make: Factory) -> None:
    ik = make(0)
    q = _q_path(ik)
    p = np.asarray(ik.forward(q))
    assert p.shape == (len(q), 3) and p.dtype == np.float64, f"forward gave {p.shape}"
    for i in (0, 17, len(q) - 1):
        one = np.asarray(ik.forward(q[i]))
        assert one.shape == (3,), f"forward of one configuration gave {one.shape}"
        np.testing.assert_allclose(one, p[i], atol=1e-12, err_msg="forward: batch vs single")


def ik_solve_reaches_targets(make: Factory) -> None:
    ik = make(0)
    q = _q_path(ik)
    targets = np.asarray(ik.forward(q))
    sol = np.asarray(ik.solve(targets, q[0]))
    assert sol.shape == q.shape, f"solve gave {sol.shape}"
    err = np.linalg.norm(np.asarray(ik.forward(sol)) - targets, axis=1)
    assert err.max() < 1e-3, f"solve misses its targets by up to {err.max():.2e} m"
    assert np.all(sol >= np.asarray(ik.lower) - 1e-9) and \
        np.all(sol <= np.asarray(ik.upper) + 1e-9), "solve violates joint limits"


def ik_deterministic(make: Factory) -> None:
    a, b = make(0), make(0)
    q = _q_path(a)
    t = np.asarray(a.forward(q))
    np.testing.assert_array_equal(a.solve(t, q[0]), b.solve(t, q[0]),
                                  err_msg="solve must be deterministic")


def ik_bad_input(make: Factory) -> None:
    ik = make(0)
    q = _q_path(ik)
    t = np.asarray(ik.forward(q))
    far = t.copy()
    far[5] = [10.0, 10.0, 10.0]
    nan = t.copy()
    nan[2, 1] = np.nan
    _expect_error(lambda: ik.solve(far, q[0]), "unreachable target", (UnreachableTargetError,))
    _expect_error(lambda: ik.solve(nan, q[0]), "NaN target", (InvalidInputError,))
    _expect_error(lambda: ik.solve(t[:, :2], q[0]), "targets of width 2", (InvalidInputError,))
    _expect_error(lambda: ik.forward(q[:, :2]), "forward of wrong width", (InvalidInputError,))


#: Largest joint step along a continuous path, relative to the median step per
#: metre of target motion (see :func:`ik_continuous_path`).
CONTINUITY_RATIO = 4.0


def ik_continuous_path(make: Factory) -> None:
    """Along a continuous target path the joint path is continuous too.

    The IKSolver contract: consecutive targets close together give
    consecutive postures close together (a warm-started solver picks the
    solution nearest the previous one), otherwise the network's motor
    inputs carry jumps that are not in the demonstration. The targets are
    the forward kinematics of a smooth joint path (120 points); per step
    ``t`` the joint jump ``|q[t+1] - q[t]|`` (max over joints) is divided by
    the target step ``|x[t+1] - x[t]|``. The largest of these ratios must
    stay within ``CONTINUITY_RATIO`` times their median: a solver that
    switches solution branches (0.4 rad between points where a continuous
    one moves 0.03-0.05 rad) fails.
    """
    ik = make(0)
    q = _q_path(ik, n=120)
    targets = np.asarray(ik.forward(q))
    sol = np.asarray(ik.solve(targets, q[0]))
    jump = np.abs(np.diff(sol, axis=0)).max(axis=1)
    step = np.linalg.norm(np.diff(targets, axis=0), axis=1)
    moving = step > 1e-6
    assert moving.sum() > 10, "the test path does not move the pen tip"
    ratio = jump[moving] / step[moving]
    worst, typical = float(ratio.max()), float(np.median(ratio))
    t = int(np.flatnonzero(moving)[int(ratio.argmax())])
    assert worst <= CONTINUITY_RATIO * typical, (
        f"joint path jumps {jump[t]:.3f} rad between targets {t} and {t + 1}, "
        f"{step[t] * 1000:.2f} mm apart: {worst:.1f} rad/m against a median of "
        f"{typical:.1f} rad/m (limit {CONTINUITY_RATIO:g} x the median). Warm-start each "
        "point from the previous solution and keep the nearest solution.")


IK_SOLVER_CHECKS: list[Check] = [ik_protocol, ik_forward_shapes_batch_vs_single,
                                 ik_solve_reaches_targets, ik_deterministic,
                                 ik_continuous_path, ik_bad_input]


# -- Simulator ---------------------------------------------------------------

def _sim_path(n: int = 60, sim: Any = None) -> np.ndarray:
    robot = getattr(sim, "robot", None) or get_robot()
    lo, hi = np.asarray(robot.lower, float), np.asarray(robot.upper, float)
    s = np.linspace(0, 1, n)[:, None]
    return (lo + hi) / 2 + 0.2 * (hi - lo) / 2 * np.sin(2 * np.pi * s)


def sim_protocol(make: Factory) -> None:
    sim = make(0)
    try:
        # render is optional: an executor driving a real arm has none
        _has(sim, "execute", "close")
    finally:
        getattr(sim, "close", lambda: None)()


def sim_execute_shapes_deterministic(make: Factory) -> None:
    a, b = make(0), make(0)
    q = _sim_path(sim=a)
    try:
        ea, eb = a.execute(q, 0.02), b.execute(q, 0.02)
        assert isinstance(ea, Execution), "execute must return an Execution"
        assert np.shape(ea.joint_path) == q.shape, f"joint_path {np.shape(ea.joint_path)}"
        assert np.shape(ea.end_effector) == (len(q), 3), \
            f"end_effector {np.shape(ea.end_effector)}"
        np.testing.assert_allclose(ea.end_effector, eb.end_effector, atol=1e-9,
                                   err_msg="execute must be deterministic")
        np.testing.assert_allclose(ea.joint_path, q, atol=0.05,
                                   err_msg="the arm does not track the joint path")
    finally:
        a.close()
        b.close()


def sim_render(make: Factory) -> None:
    sim = make(0)
    if not callable(getattr(sim, "render", None)):
        sim.close()
        return  # optional: nothing to check
    try:
        ex = sim.execute(_sim_path(20, sim), 0.02)
        img = np.asarray(sim.render(ex, 64, 48))
        assert img.shape == (48, 64, 3) and img.dtype == np.uint8, \
            f"render gave {img.shape} {img.dtype}"
        assert img.std() > 0, "render gave a blank image"
    finally:
        sim.close()


def sim_bad_input(make: Factory) -> None:
    sim = make(0)
    try:
        q = _sim_path(10, sim)
        nan = q.copy()
        nan[3, 0] = np.nan
        out = q.copy()
        out[4, 1] = 10.0
        _expect_error(lambda: sim.execute(nan, 0.02), "NaN joint path", (InvalidInputError,))
        _expect_error(lambda: sim.execute(q[:, :-1], 0.02), "joint path of wrong width",
                      (InvalidInputError,))
        _expect_error(lambda: sim.execute(out, 0.02), "joint path outside limits",
                      (InvalidInputError,))
        _expect_error(lambda: sim.execute(q, 0.0), "dt = 0", (InvalidInputError,))
    finally:
        sim.close()


SIMULATOR_CHECKS: list[Check] = [sim_protocol, sim_execute_shapes_deterministic, sim_render,
                                 sim_bad_input]


CHECKS: dict[str, list[Check]] = {
    "perceptual_model": PERCEPTUAL_MODEL_CHECKS,
    "clusterer": CLUSTERER_CHECKS,
    "teacher": TEACHER_CHECKS,
    "ik": IK_SOLVER_CHECKS,
    "simulator": SIMULATOR_CHECKS,
    "robot": ROBOT_CHECKS,
}
