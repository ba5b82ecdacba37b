"""Mem, D_cutoff / cluster validity / medoids, and the inference confidence.

These use the real clusterer plugins on PB vectors given directly; the
learner tests drive the same code through a real network on LASA data.
"""

from __future__ import annotations

import numpy as np
import pytest

from iloci.concepts.clustering import d_cutoff, medoid, plan_clusters
from iloci.concepts.learner import confidence
from iloci.concepts.memory import Entry, Memory, entries_equal, save_memory
from iloci.errors import InvalidInputError, MemoryFileError
from iloci.plugins import get_registry


@pytest.fixture(scope="module", params=["scipy", "sklearn"])
def clusterer(request):
    registry = get_registry()
    if ("clusterer", request.param) not in registry:
        pytest.skip(f"clusterer {request.param!r} is not installed")
    try:
        return registry.build("clusterer", request.param)
    except ImportError:
        pytest.skip(f"back end of clusterer {request.param!r} is not installed")


def entry(pb, concept="c1", num_samples=1, prototype=False, key="S/0") -> Entry:
    pb = np.asarray(pb, dtype=np.float64)
    return Entry(pb=pb, pb_rec=pb + 0.01, num_samples=num_samples, num_steps=49,
                 initial_input=np.arange(6.0), start=np.ones(6), dt=0.1, concept=concept,
                 generation_error=0.5, source=key, sources=(key,), prototype=prototype)


# -- D_cutoff and medoid ------------------------------------------------------------

def test_d_cutoff_is_mean_minus_k_std_of_pairwise_distances():
    pbs = np.array([[0.0, 0.0], [3.0, 0.0], [0.0, 4.0]])  # distances 3, 4, 5
    assert d_cutoff(pbs, 0.0) == pytest.approx(4.0)
    assert d_cutoff(pbs, 0.5) == pytest.approx(4.0 - 0.5 * np.std([3.0, 4.0, 5.0]))
    assert np.isnan(d_cutoff(pbs[:1], 0.5))


def test_medoid_minimises_summed_distance_and_ties_go_to_the_oldest():
    pbs = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0], [3.0, 3.0]])
    # summed distances 7.24, 6.84, 7.40, 11.01
    assert medoid(pbs) == 1
    assert medoid(np.array([[0.0], [1.0]])) == 0


# -- cluster validity -------------------------------------------------------------------

def test_close_pair_of_exemplars_is_a_valid_cluster(clusterer):
    # two tight pairs and a far point: cut = mu - 0.5 sigma falls between scales
    pbs = np.array([[0.0, 0.0], [0.05, 0.0], [1.0, 1.0], [1.0, 1.05], [-1.0, 1.0]])
    plan = plan_clusters(pbs, [2, 2, 2, 2, 1], [True] * 5, clusterer=clusterer,
                         k_cutoff=0.5, num_threshold=3)
    assert plan.valid == ((0, 1), (2, 3))
    assert plan.medoids == (0, 2)
    assert list(plan.labels) == [0, 0, 1, 1, 2]
    assert 0.05 < plan.d_cutoff < 1.4


class _Returns:
    """A clusterer plugin with a fault: returns ``labels`` whatever it is asked."""

    def __init__(self, labels):
        self.labels = labels

    def cluster(self, points, distance_threshold):
        return self.labels


@pytest.mark.parametrize("labels, said", [
    ([np.nan, 0, 1, 1, 2], r"returned label nan \(point 0\); labels are whole numbers"),
    ([0.5, 0, 1, 1, 2], r"returned label 0.5 \(point 0\)"),
    ([-1, -1, 0, 0, 1], r"returned a negative label \(-1\)"),
    ([True, True, False, False, True], "returned labels of dtype bool, not integers"),
    (["a", "a", "b", "b", "c"], "returned labels of dtype <U1, not integers"),
    ([0, 0, 0, 0, 0], r"put points 2\.\d+ apart into one cluster, over the cut"),
    ([0, 0, 1], r"returned labels of shape \(3,\) for 5 points"),
    ([0, 1, 2, 3, 4], r"kept apart two clusters \(points \[0\] and \[1\]\) whose farthest "
                      r"pair is 0.05 apart, within the cut"),
])
def test_a_clusterers_labels_are_checked_not_cast(labels, said):
    """A plugin audit: NaN labels were cast to a huge int, 0.5 to 0, and a cluster wider
    than the cut was taken: other prototypes were learned, with exit 0."""
    pbs = np.array([[0.0, 0.0], [0.05, 0.0], [1.0, 1.0], [1.0, 1.05], [-1.0, 1.0]])
    with pytest.raises(InvalidInputError, match=f"clusterer _Returns {said}"):
        plan_clusters(pbs, [2, 2, 2, 2, 1], [True] * 5, clusterer=_Returns(labels),
                      k_cutoff=0.5, num_threshold=3)
    # labels in another order, or numbered with gaps, are fine: they only group
    plan = plan_clusters(pbs, [2, 2, 2, 2, 1], [True] * 5,
                         clusterer=_Returns(np.array([7.0, 7.0, 3.0, 3.0, 9.0])),
                         k_cutoff=0.5, num_threshold=3)
    assert plan.valid == ((0, 1), (2, 3))


def test_cluster_needs_num_samples_above_threshold(clusterer):
    pbs = np.array([[0.0, 0.0], [0.05, 0.0], [1.0, 1.0], [1.0, 1.05], [-1.0, 1.0]])
    plan = plan_clusters(pbs, [1, 2, 2, 2, 1], [True] * 5, clusterer=clusterer,
                         k_cutoff=0.5, num_threshold=3)
    assert plan.valid == ((2, 3),)          # 1 + 2 = 3 does not exceed 3


def test_cluster_of_prototypes_only_is_not_valid(clusterer):
    pbs = np.array([[0.0, 0.0], [0.05, 0.0], [1.0, 1.0], [1.0, 1.05], [-1.0, 1.0]])
    plan = plan_clusters(pbs, [2, 2, 2, 2, 1], [False, False, True, False, True],
                         clusterer=clusterer, k_cutoff=0.5, num_threshold=3)
    assert plan.valid == ((2, 3),)
    assert plan.medoids == (2,)


def test_cluster_with_mean_distance_not_below_cutoff_is_not_valid(clusterer):
    # two points: the cut equals their distance, so they merge, but their
    # mean pairwise distance is not *below* D_cutoff
    pbs = np.array([[0.0, 0.0], [0.3, 0.0]])
    plan = plan_clusters(pbs, [3, 3], [True, True], clusterer=clusterer, k_cutoff=0.0,
                         num_threshold=3)
    assert plan.d_cutoff == pytest.approx(0.3)
    assert list(plan.labels) == [0, 0]
    assert plan.valid == ()


def test_a_large_k_cutoff_clusters_nothing(clusterer):
    pbs = np.random.default_rng(0).normal(size=(8, 4))
    plan = plan_clusters(pbs, [2] * 8, [True] * 8, clusterer=clusterer, k_cutoff=50.0,
                         num_threshold=3)
    assert plan.d_cutoff < 0 and plan.valid == () and (plan.labels == -1).all()


def test_plan_clusters_checks_lengths(clusterer):
    with pytest.raises(InvalidInputError, match="length 3"):
        plan_clusters(np.zeros((3, 4)), [1, 1], [True] * 3, clusterer=clusterer,
                      k_cutoff=0.5, num_threshold=3)


def test_scipy_and_sklearn_plans_agree_on_random_pbs():
    registry = get_registry()
    try:
        a = registry.build("clusterer", "scipy")
        b = registry.build("clusterer", "sklearn")
    except Exception:  # noqa: BLE001 - either back end missing
        pytest.skip("needs both clusterer back ends")
    rng = np.random.default_rng(1)
    for _ in range(20):
        m = int(rng.integers(2, 12))
        pbs = rng.uniform(-1, 1, size=(m, 4))
        ns = rng.integers(1, 4, size=m)
        ex = rng.random(m) < 0.7
        pa = plan_clusters(pbs, ns, ex, clusterer=a, k_cutoff=0.5, num_threshold=3)
        pb = plan_clusters(pbs, ns, ex, clusterer=b, k_cutoff=0.5, num_threshold=3)
        assert np.array_equal(pa.labels, pb.labels)
        assert pa.valid == pb.valid and pa.medoids == pb.medoids


def test_scipy_and_sklearn_give_identical_partitions_on_real_pbs():
    """PBs a real network learned from real LASA demos, clustered both ways."""
    registry = get_registry()
    try:
        a = registry.build("clusterer", "scipy")
        b = registry.build("clusterer", "sklearn")
        model = registry.build("perceptual_model", "jax-rnnpb",
                               {"epochs": 300, "recognition_steps": 30}, seed=0)
        ik = registry.build("ik", "pinocchio")
    except Exception:  # noqa: BLE001 - a back end missing
        pytest.skip("needs scipy, sklearn, jax-rnnpb and pinocchio")
    from iloci.config import SensorimotorConfig
    from iloci.data import load_lasa
    from iloci.sensorimotor.encoding import SensorimotorEncoder
    from iloci.sensorimotor.pipeline import to_motions

    demos = load_lasa(["GShape", "Angle", "Sshape", "Leaf_1"])
    motions = to_motions(demos, SensorimotorConfig(), ik)
    seqs, _ = SensorimotorEncoder().fit(motions).encode_all(motions)
    pbs = model.train(seqs)
    rng = np.random.default_rng(0)
    compared = 0
    for k_cutoff in (0.0, 0.25, 0.5, 1.0):
        for shape in range(4):  # one shape's 7 PBs: a concept's entries
            rows = slice(7 * shape, 7 * shape + 7)
            ns = rng.integers(1, 3, size=7)
            ex = ns == 1
            pa = plan_clusters(pbs[rows], ns, ex, clusterer=a, k_cutoff=k_cutoff,
                               num_threshold=3)
            pb = plan_clusters(pbs[rows], ns, ex, clusterer=b, k_cutoff=k_cutoff,
                               num_threshold=3)
            assert np.array_equal(pa.labels, pb.labels), (k_cutoff, shape)
            assert pa.valid == pb.valid and pa.medoids == pb.medoids
            compared += len(set(pa.labels.tolist())) > 1
        # all 28 together: PBs of different shapes in one clustering
        pa = plan_clusters(pbs, np.ones(28, int), np.ones(28, bool), clusterer=a,
                           k_cutoff=k_cutoff, num_threshold=3)
        pb = plan_clusters(pbs, np.ones(28, int), np.ones(28, bool), clusterer=b,
                           k_cutoff=k_cutoff, num_threshold=3)
        assert np.array_equal(pa.labels, pb.labels)
    assert compared > 0, "no PB set was split: the comparison would be vacuous"


# -- confidence -------------------------------------------------------------------------

def test_confidence_is_the_margin_to_the_nearest_other_concept():
    dist = np.array([[0.1, 0.4, 0.2],     # nearest c1 (0.1); other concept at 0.2
                     [0.5, 0.5, 0.1],     # nearest c2 (0.1); other at 0.5
                     [0.3, 0.3, 0.3]])    # tie: nearest entry 0, other concept at 0.3
    nearest, conf = confidence(dist, ["c1", "c1", "c2"])
    assert list(nearest) == [0, 2, 0]
    np.testing.assert_allclose(conf, [1 - 0.1 / 0.2, 1 - 0.1 / 0.5, 0.0])
    _, single = confidence(np.array([[0.2, 0.7]]), ["c1", "c1"])
    assert single[0] == 1.0


# -- Mem -----------------------------------------------------------------------------

def make_memory() -> Memory:
    from iloci.sensorimotor.encoding import SensorimotorEncoder
    enc = SensorimotorEncoder.from_state({"scale": np.full(6, 0.01), "limit": np.array(0.9)})
    entries = [entry([0.1, 0.2, 0.3, 0.4], "c1", 1, False, "GShape/0"),
               entry([0.5, 0.2, 0.3, 0.4], "c2", 3, True, "Angle/1"),
               entry([0.1, 0.9, 0.3, 0.4], "c1", 2, False, "JShape_2/4")]
    entries[1].sources = ("Angle/1", "Angle/2", "Sine/0")
    return Memory(entries, enc, concept_count=2, demonstrations_seen=6)


def test_memory_views():
    mem = make_memory()
    assert mem.n_entries == len(mem) == 3
    assert mem.pbs.shape == mem.pbs_rec.shape == (3, 4)
    assert mem.concepts() == ["c1", "c2"]
    assert mem.indices_of("c1") == [0, 2]
    assert mem.num_samples_of("c1") == 3 and mem.num_samples_of("c2") == 3
    assert mem.entries[1].prototype and mem.entries[0].exemplar
    assert mem.new_concept_label() == "c3" and mem.concept_count == 3
    assert "c2: 1 entries (1 prototypes), numSamples 3" in mem.summary()
    empty = Memory()
    assert empty.pbs.shape == (0, 0) and empty.concepts() == []


def test_majority_names_of_a_memory_take_the_majority_true_concept():
    from iloci.data.concepts import GroundTruth, majority_names
    mem = make_memory()
    names = majority_names(mem.concept_members(GroundTruth()))
    # c1: GShape/0 and JShape_2/4 tie, the first seen wins; c2: 2 Angle, 1 Sine
    assert names == {"c1": "GShape", "c2": "Angle"}
    assert majority_names(Memory([entry([0, 0, 0, 0], key="x/0")]).concept_members(
        lambda k: None)) == {"c1": None}


def test_memory_arrays_round_trip():
    mem = make_memory()
    arrays, meta = mem.to_arrays()
    assert all(a.dtype != object for a in arrays.values())
    back = Memory.from_arrays(arrays, meta)
    assert entries_equal(back.entries, mem.entries)
    np.testing.assert_array_equal(back.encoder.scale_, mem.encoder.scale_)
    assert (back.concept_count, back.demonstrations_seen) == (2, 6)
    copy = mem.copy()
    copy.entries[0].num_samples += 1
    assert not entries_equal(copy.entries, mem.entries)


def test_kept_patterns_round_trip_and_are_checked():
    """[learner] rehearse_from = "demonstrations": an entry's pattern is saved with it."""
    mem = make_memory()
    mem.entries[1].pattern = np.linspace(0.0, 1.0, 49 * 6).reshape(49, 6)
    arrays, meta = mem.to_arrays()
    back = Memory.from_arrays(arrays, meta)
    assert back.entries[0].pattern is None and back.entries[2].pattern is None
    np.testing.assert_array_equal(back.entries[1].pattern, mem.entries[1].pattern)
    assert entries_equal(back.entries, mem.entries)
    assert not entries_equal(make_memory().entries, mem.entries)
    arrays["mem/pattern/1"] = arrays["mem/pattern/1"][:10]
    with pytest.raises(MemoryFileError, match="pattern has shape"):
        Memory.from_arrays(arrays, meta)


def test_inconsistent_arrays_are_a_memory_file_error():
    arrays, meta = make_memory().to_arrays()
    arrays["mem/pb"] = arrays["mem/pb"][:2]
    with pytest.raises(MemoryFileError, match="inconsistent"):
        Memory.from_arrays(arrays, meta)


def test_every_output_counts_exemplars_and_prototypes_alike(tmp_path, cli):
    """metrics.json's counts, the memory summary (`iloci teach`) and `iloci show MEMORY` agree.

    The memory holds a strengthened exemplar (numSamples 2, not a medoid): an
    exemplar for every one of them (evaluation once counted it a prototype).
    """
    import re

    from iloci.evaluation.evaluate import memory_counts

    mem = make_memory()
    want = {"entries": 3, "exemplars": 2, "prototypes": 1, "concepts": 2}
    assert memory_counts(mem) == want

    def counts(text: str) -> dict[str, int]:
        m = re.search(r"(\d+) entries \((\d+) exemplars, (\d+) prototypes\), (\d+) concepts",
                      text)
        assert m, text
        return dict(zip(("entries", "exemplars", "prototypes", "concepts"),
                        map(int, m.groups())))

    assert counts(mem.summary()) == want
    path = save_memory(tmp_path / "m.npz", mem, {})
    res = cli("show", str(path))
    assert res.returncode == 0, res.stderr
    assert counts(res.stdout) == want
    per_concept = re.findall(r"(c\d): (\d+) entries \((\d+) prototypes\)", res.stdout)
    assert per_concept == [("c1", "2", "0"), ("c2", "1", "1")]


# -- condensing: the medoid replaces only the members it stands for ---------------------

def _two_concepts() -> Memory:
    """c1: a tight pair (0, 1) and a far exemplar; c2: one entry nearer c1's entry 1 than c1's
    medoid (entry 0) is."""
    from iloci.sensorimotor.encoding import SensorimotorEncoder
    enc = SensorimotorEncoder.from_state({"scale": np.full(6, 0.01), "limit": np.array(0.9)})
    entries = [entry([0.0, 0.0], "c1", 2, key="A/0"), entry([0.06, 0.0], "c1", 2, key="A/1"),
               entry([1.0, 1.0], "c1", 2, key="A/2"), entry([-1.0, 1.0], "c1", 1, key="A/3"),
               entry([0.1, 0.0], "c2", 1, key="B/0")]
    return Memory(entries, enc, concept_count=2, demonstrations_seen=8)


def test_a_medoid_replaces_only_the_members_stands_for_says(clusterer):
    mem = _two_concepts()
    paper, n, _ = mem.clustered("c1", clusterer, k_cutoff=0.5, num_threshold=3)
    assert n == 1 and [e.source for e in paper] == ["A/0", "A/2", "A/3", "B/0"]
    assert paper[0].prototype and paper[0].num_samples == 4
    kept, n, _ = mem.clustered("c1", clusterer, k_cutoff=0.5, num_threshold=3,
                               stands_for=lambda member, medoid: member != 1)
    assert n == 0 and [e.source for e in kept] == ["A/0", "A/1", "A/2", "A/3", "B/0"]
    assert not any(e.prototype for e in kept)


@pytest.mark.parametrize("condense, sources", [
    ("paper", ["A/0", "A/2", "A/3", "B/0"]),
    # A/1 (PB 0.06) lies nearer c2's B/0 (0.04 away) than its medoid A/0 (0.06): kept
    ("consistent", ["A/0", "A/1", "A/2", "A/3", "B/0"]),
])
def test_consistent_condensing_keeps_a_member_the_medoid_would_lose_to_another_concept(
        clusterer, condense, sources):
    from iloci.concepts.learner import Learner
    from iloci.config import LearnerConfig

    learner = Learner(_two_concepts(), None, clusterer, None,
                      LearnerConfig(decision="pb_distance", condense=condense))
    entries, n, _ = learner.cluster("c1")
    assert [e.source for e in entries] == sources
    assert n == (1 if condense == "paper" else 0)
