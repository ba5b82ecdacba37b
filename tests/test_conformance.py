"""The conformance suite on iloci's own components, and on broken ones."""

from __future__ import annotations

import numpy as np
import pytest

from iloci.errors import InvalidInputError
from iloci.teachers import NoisyTeacher, OracleTeacher
from iloci.testing import ConformanceError, check_component, parametrize_with_checks

BUILTIN = [
    ("teacher", lambda seed: OracleTeacher()),
    ("teacher", lambda seed: NoisyTeacher(p=0.3, seed=seed)),
]


@parametrize_with_checks(BUILTIN)
def test_builtin_teachers_conform(component, check):
    check(component)


# -- deliberately broken components: each fault must be reported ---------------

class WrongShapeClusterer:
    def cluster(self, points, distance_threshold):
        return np.zeros((len(points), 1), dtype=int)  # (M, 1) instead of (M,)


class RandomClusterer:
    """Non-deterministic: labels depend on an unseeded generator."""

    def __init__(self):
        self.rng = np.random.default_rng()

    def cluster(self, points, distance_threshold):
        from iloci.concepts.labels import canonical_labels, check_points
        x, _ = check_points(points, distance_threshold)
        return canonical_labels(self.rng.integers(0, 3, size=len(x)))


class SingleLinkClusterer:
    """Single link cut at the threshold: diameters exceed it."""

    def cluster(self, points, distance_threshold):
        from scipy.cluster.hierarchy import fcluster, linkage
        from iloci.concepts.labels import canonical_labels, check_points
        x, t = check_points(points, distance_threshold)
        if len(x) == 1:
            return np.zeros(1, dtype=int)
        return canonical_labels(fcluster(linkage(x, "single"), t, "distance"))


class SilentOnNaNClusterer(SingleLinkClusterer):
    def cluster(self, points, distance_threshold):
        x = np.nan_to_num(np.asarray(points, float))  # swallows bad input
        return super().cluster(x, abs(distance_threshold))


class TrueFalseTeacher:
    def __init__(self, seed=0):
        pass

    def feedback(self, demo, response):
        return True  # a bool, not +1


class CoinTeacher:
    """Ignores its seed: not reproducible."""

    def __init__(self, seed=0):
        self.rng = np.random.default_rng()

    def feedback(self, demo, response):
        return int(self.rng.choice([-1, 1]))


@pytest.mark.parametrize("make, kind, expected", [
    (lambda s: WrongShapeClusterer(), "clusterer", "cl_shapes_and_labels"),
    (lambda s: RandomClusterer(), "clusterer", "cl_deterministic"),
    (lambda s: SingleLinkClusterer(), "clusterer", "cl_complete_link"),
    (lambda s: SilentOnNaNClusterer(), "clusterer", "cl_bad_input"),
    (TrueFalseTeacher, "teacher", "te_feedback_values"),
    (CoinTeacher, "teacher", "te_deterministic"),
])
def test_suite_reports_the_fault(make, kind, expected):
    with pytest.raises(ConformanceError) as exc:
        check_component(make, kind)
    assert expected in exc.value.failed
    assert expected in str(exc.value)


class LossyStateModel:
    """A tiny linear 'RNNPB' whose state() forgets its weights."""

    input_size = 2
    pb_size = 2

    def __init__(self, seed=0):
        self.w = np.random.default_rng(seed).normal(size=(4, 2))

    def _check(self, seqs):
        if not len(seqs):
            raise InvalidInputError("empty")
        for s in seqs:
            s = np.asarray(s, float)
            if s.ndim != 2 or s.shape[1] != 2 or len(s) < 2 or not np.isfinite(s).all():
                raise InvalidInputError("bad sequence")

    def train(self, seqs, pbs_init=None, epochs=None):
        self._check(seqs)
        return np.array([np.asarray(s, float).mean(0) for s in seqs])

    def recognize(self, seqs, candidate_pbs=None):
        return self.train(seqs)

    def generate(self, pbs, x0, lengths):
        out = []
        for pb, x, n in zip(np.asarray(pbs, float), np.asarray(x0, float), lengths):
            rows = [x]
            for _ in range(n - 1):
                rows.append(np.tanh(np.concatenate([rows[-1], pb]) @ self.w))
            out.append(np.array(rows))
        return out

    def prediction_error(self, seqs, pbs):
        gen = self.generate(pbs, np.stack([s[0] for s in seqs]), [len(s) for s in seqs])
        return np.array([np.mean((g - s) ** 2) for g, s in zip(gen, seqs)])

    def state(self):
        return {"version": np.array(1)}  # weights not saved

    def load_state(self, state):
        pass


def test_suite_catches_lossy_state():
    results = check_component(LossyStateModel, "perceptual_model", raise_on_failure=False)
    failed = {r.check for r in results if not r.passed}
    assert failed == {"pm_state_round_trip"}, results


def test_scipy_and_sklearn_clusterers_conform():
    pytest.importorskip("iloci_scipy")
    from iloci.testing import registry_factory
    check_component(registry_factory("clusterer", "scipy"), "clusterer")
    pytest.importorskip("iloci_sklearn")
    check_component(registry_factory("clusterer", "sklearn"), "clusterer")
