"""The ILoCI learning and inference phases on real LASA demonstrations.

Each branch of the learning phase (docs/method.md, "Learning phase") is driven with a real RNNPB
(``native-rnnpb``), the real IK and real clusterers, kept small: few
demonstrations, few epochs (set through the config). Learner constants are
set through the config to make a branch certain (e.g. a similarity
threshold larger than any PB distance makes every rewarded guess a
strengthening).
"""

from __future__ import annotations

import os
import warnings

import numpy as np
import pytest

import iloci
from iloci import hookimpl
from iloci.agent import SkippedDemonstrationWarning
from iloci.concepts import rehearsal
from iloci.concepts.inference import (COMPARES, PATH_WARP, as_positions, path_distances,
                                      path_scale, pen_path)
from iloci.concepts.learner import (novelty_scale, pattern_distances,
                                    regenerated_patterns, regeneration_scale)
from iloci.concepts.memory import entries_equal
from iloci.data import load_lasa
from iloci.errors import FeedbackError, MissingBackendError, NotFittedError
from iloci.interfaces import Response
from iloci.plugins import get_plugin_manager

#: The RNNPB back end under test (ILOCI_TEST_RNNPB=jax-rnnpb runs these on JAX).
RNNPB = os.environ.get("ILOCI_TEST_RNNPB", "native-rnnpb")
pytest.importorskip({"native-rnnpb": "iloci_native", "torch-rnnpb": "torch",
                     "jax-rnnpb": "jax"}[RNNPB])
pytest.importorskip("pinocchio")

EPOCHS = 30


def small_config(**learner) -> dict:
    return {"perceptual_model": {"name": RNNPB, "epochs": EPOCHS,
                                 "recognition_steps": EPOCHS},
            "learner": {"rehearsal_epochs": EPOCHS, **learner},
            "evaluation": {"seed": 0}}


class Recorder:
    """An observer plugin keeping every event."""

    def __init__(self) -> None:
        self.interactions: list = []
        self.rehearsals: list = []

    @hookimpl
    def iloci_on_interaction(self, event) -> None:
        self.interactions.append(event)

    @hookimpl
    def iloci_on_rehearsal(self, event) -> None:
        self.rehearsals.append(event)


class ScriptedTeacher:
    """A teacher replaying fixed feedback, like a recorded session."""

    def __init__(self, feedback) -> None:
        self.feedback_values = list(feedback)
        self.responses: list[Response] = []

    def feedback(self, demo, response):
        self.responses.append(response)
        return self.feedback_values.pop(0)


def make_agent(recorder: Recorder | None = None, pm=None, **learner) -> iloci.Agent:
    pm = pm or get_plugin_manager()
    if recorder is not None:
        pm.register(recorder)
    try:
        return iloci.build(small_config(**learner), plugin_manager=pm)
    except MissingBackendError as exc:
        pytest.skip(str(exc))


@pytest.fixture(scope="module")
def lasa():
    demos = {d.key: d for d in load_lasa(["GShape", "Angle", "Sine"])}
    return demos


def net_state(agent) -> dict:
    return {k: np.array(v, copy=True) for k, v in agent.perceptual_model.state().items()}


def same_state(a: dict, b: dict) -> bool:
    return set(a) == set(b) and all(np.array_equal(a[k], b[k]) for k in a)


# -- the learning phase, branch by branch -------------------------------------------

def test_first_demonstration_becomes_the_first_concept_without_feedback(lasa):
    rec = Recorder()
    agent = make_agent(rec)
    demo = lasa["GShape/0"]
    outcome = agent.learn(demo)
    assert (outcome.action, outcome.concept, outcome.feedbacks) == ("new_concept", "c1", ())
    mem = agent.memory
    assert len(mem) == 1 and mem.concepts() == ["c1"] and mem.demonstrations_seen == 1
    e = mem.entries[0]
    seq, start = mem.encoder.encode(agent.motion(demo))
    assert (e.num_samples, e.num_steps, e.source, e.sources) == (1, 49, "GShape/0",
                                                                 ("GShape/0",))
    np.testing.assert_array_equal(e.initial_input, seq[0])
    np.testing.assert_array_equal(e.start, start)
    assert e.exemplar and e.pb.shape == e.pb_rec.shape == (4,)
    assert np.isfinite(e.generation_error) and e.generation_error >= 0
    assert [ev.action for ev in rec.interactions] == ["new_concept"]
    assert rec.interactions[0].feedback == 0 and rec.interactions[0].guessed is None
    (r,) = rec.rehearsals
    assert (r.entries, r.epochs, r.reason) == (1, EPOCHS, "new_concept")
    assert r.seconds > 0 and np.isfinite(r.loss)


def test_punished_guesses_then_a_new_concept_when_all_are_tried(lasa):
    rec = Recorder()
    agent = make_agent(rec)
    agent.teach([lasa["GShape/0"], lasa["Angle/0"]])       # oracle teacher
    assert agent.memory.concepts() == ["c1", "c2"]
    outcome = agent.learn(lasa["Sine/0"])
    assert outcome.action == "new_concept" and outcome.concept == "c3"
    assert outcome.feedbacks == (-1, -1)
    guesses = [ev.guessed for ev in outcome.events[:2]]
    assert sorted(guesses) == ["c1", "c2"]
    assert [ev.action for ev in outcome.events] == ["next_guess", "next_guess", "new_concept"]
    assert outcome.events[1].tried == (guesses[0],) and outcome.events[1].attempt == 2
    assert set(outcome.events[2].tried) == {"c1", "c2"}
    assert [e.concept for e in agent.memory.entries] == ["c1", "c2", "c3"]
    assert agent.memory.entries[2].sources == ("Sine/0",)
    # every interaction and rehearsal reached the observer
    assert len(rec.interactions) == 1 + 2 + 3
    assert [r.reason for r in rec.rehearsals] == ["new_concept"] * 3
    assert [r.entries for r in rec.rehearsals] == [1, 2, 3]


def test_punished_first_guess_then_rewarded_second_guess(lasa):
    agent = make_agent(similarity_threshold=0.0)
    agent.teach([lasa["GShape/0"], lasa["Angle/0"]])
    teacher = ScriptedTeacher([-1, 1])
    agent.teacher = teacher
    outcome = agent.learn(lasa["GShape/1"])
    first, second = (r.concept for r in teacher.responses)
    assert first != second and outcome.concept == second
    assert [r.attempt for r in teacher.responses] == [1, 2]
    assert outcome.feedbacks == (-1, 1) and outcome.action == "new_exemplar"
    assert outcome.first_guess_correct is False
    new = agent.memory.entries[-1]
    assert (new.concept, new.source, new.num_samples) == (second, "GShape/1", 1)


def test_response_is_the_guessed_concepts_lowest_error_entry(lasa):
    agent = make_agent(similarity_threshold=0.0)
    agent.teach([lasa["GShape/0"], lasa["GShape/1"]])    # two exemplars of c1
    errors = [e.generation_error for e in agent.memory.entries]
    best = int(np.argmin(errors))
    best_entry = agent.memory.entries[best].copy()
    teacher = ScriptedTeacher([1])
    agent.teacher = teacher
    agent.learn(lasa["GShape/2"])
    (response,) = teacher.responses
    assert response.extra["entry"] == best and response.source == best_entry.source
    assert response.concept == "c1" and response.attempt == 1
    assert response.motion.shape == (50, 2) and response.joint_path.shape == (50, 4)
    # the motion is the entry regenerated from its start pose, not the demonstration
    np.testing.assert_array_equal(response.motion[0], best_entry.start[:2])
    np.testing.assert_array_equal(response.joint_path[0], best_entry.start[2:])
    assert response.execution is None                       # no simulator configured


def test_rewarded_similar_demonstration_strengthens_the_nearest_entry(lasa):
    # PB values lie in [-1, 1]^4, so no distance reaches 10: every reward strengthens
    agent = make_agent(similarity_threshold=10.0)
    agent.teach([lasa["GShape/0"], lasa["Angle/0"]])
    before = net_state(agent)
    outcome = agent.learn(lasa["GShape/1"])                # oracle: rewarded on c1
    assert outcome.action == "strengthen" and outcome.concept == "c1"
    assert outcome.rehearsals == ()                        # no retraining
    assert same_state(before, net_state(agent))
    e = agent.memory.entries[0]
    assert (e.num_samples, e.sources) == (2, ("GShape/0", "GShape/1"))
    assert len(agent.memory) == 2 and agent.memory.demonstrations_seen == 3


def test_rewarded_dissimilar_demonstration_becomes_a_new_exemplar(lasa):
    rec = Recorder()
    agent = make_agent(rec, similarity_threshold=0.0)
    agent.teach([lasa["GShape/0"], lasa["Angle/0"]])
    old = [e.copy() for e in agent.memory.entries]
    outcome = agent.learn(lasa["GShape/1"])
    assert outcome.action == "new_exemplar" and outcome.concept == "c1"
    assert outcome.feedbacks[-1] == 1
    mem = agent.memory
    assert [e.concept for e in mem.entries] == ["c1", "c2", "c1"]
    assert mem.num_samples_of("c1") == 2 and all(e.exemplar for e in mem.entries)
    assert rec.rehearsals[-1].entries == 3 and rec.rehearsals[-1].reason == "new_exemplar"
    # the rehearsal retrained everything: PBs, PB_recs and errors were recomputed
    for e, o in zip(mem.entries[:2], old):
        assert not np.array_equal(e.pb, o.pb)
        assert not np.array_equal(e.pb_rec, o.pb_rec)
        assert e.generation_error != o.generation_error
    assert np.all(np.abs(mem.pbs) <= 1.0) and np.all(np.isfinite(mem.pbs_rec))


def test_clustering_replaces_a_valid_cluster_by_its_medoid(lasa):
    # K_cutoff = 0 puts D_cutoff at the mean distance mu of the concept's PBs. With
    # three exemplars the closest pair lies below mu (unless all three distances are
    # equal) and complete link cannot add the third one, so that pair is the one
    # valid cluster once numSamples exceed num_threshold = 1.
    rec = Recorder()
    agent = make_agent(rec, similarity_threshold=0.0, k_cutoff=0.0, num_threshold=1)
    report = agent.teach([lasa["GShape/0"], lasa["GShape/1"]])
    assert [o.action for o in report.outcomes] == ["new_concept", "new_exemplar"]
    assert report.outcomes[1].clustered == 0                # two entries: mean == D_cutoff
    pbs = agent.memory.pbs
    outcome = agent.learn(lasa["GShape/2"])
    assert outcome.action == "new_exemplar" and outcome.clustered == 1
    assert [r.reason for r in outcome.rehearsals] == ["new_exemplar", "clustering"]
    assert rec.rehearsals[-1].entries == 2
    mem = agent.memory
    assert len(mem) == 2 and mem.num_samples_of("c1") == 3
    (proto,) = [e for e in mem.entries if e.prototype]
    (exemplar,) = [e for e in mem.entries if e.exemplar]
    assert proto.num_samples == 2 and len(proto.sources) == 2
    assert proto.source == proto.sources[0]                 # the medoid kept its pattern
    assert exemplar.num_samples == 1 and exemplar.source not in proto.sources
    assert set(proto.sources) | {exemplar.source} == {"GShape/0", "GShape/1", "GShape/2"}
    d_cutoff = outcome.events[-1].extra["d_cutoff"]
    assert d_cutoff > 0 and np.isfinite(d_cutoff)
    assert pbs.shape == (2, 4)


def test_rehearsal_regenerates_entries_and_retrains_from_current_weights(lasa):
    agent = make_agent(rehearse_from="regenerated")   # the paper's temporal memory
    agent.teach([lasa["GShape/0"], lasa["Angle/0"]])
    entries = agent.memory.entries
    regenerated = rehearsal.regenerate(agent.perceptual_model, entries)
    assert [r.shape for r in regenerated] == [(49, 6), (49, 6)]
    np.testing.assert_allclose(regenerated[0][0], entries[0].initial_input)
    before = net_state(agent)
    seq, _ = agent.memory.encoder.encode(agent.motion(lasa["Sine/0"]))
    result = rehearsal.rehearse(agent.perceptual_model, entries, seq, epochs=EPOCHS)
    assert len(result.patterns) == 3
    for got, want in zip(result.patterns[:2], regenerated):
        np.testing.assert_array_equal(got, want)            # the temporal memory
    np.testing.assert_array_equal(result.patterns[2], seq)
    assert result.pbs.shape == result.pbs_rec.shape == (3, 4)
    assert result.generation_errors.shape == (3,) and np.all(result.generation_errors >= 0)
    assert np.isfinite(result.loss) and result.loss >= 0
    assert not same_state(before, net_state(agent))
    assert len(agent.memory) == 2                           # rehearse() alone changes no entry


@pytest.mark.parametrize("rate", [None, 0.002])
def test_rehearsals_of_a_trained_network_take_the_rehearsal_learning_rate(lasa, rate,
                                                                          monkeypatch):
    """The founding of the first concept trains a fresh network at ``learning_rate``;
    every later training rehearses it at ``rehearsal_learning_rate`` (passed to train)."""
    agent = (make_agent() if rate is None else
             iloci.build({**small_config(), "perceptual_model": {
                 **small_config()["perceptual_model"], "rehearsal_learning_rate": rate}}))
    model = agent.perceptual_model
    calls: list = []
    train = model.train

    def recording(*args, **kwargs):
        calls.append(kwargs.get("learning_rate"))
        return train(*args, **kwargs)

    monkeypatch.setattr(model, "train", recording)
    agent.teach([lasa["GShape/0"], lasa["Angle/0"], lasa["Sine/0"]])
    expected = 0.001 if rate is None else rate
    assert model.params.learning_rate == 0.005
    assert calls[0] is None and len(calls) >= 3
    assert calls[1:] == [expected] * (len(calls) - 1)
    # the same rule for a memory rehearsed by hand through the learner
    before = len(calls)
    agent.learner.rehearse("clustering", list(agent.memory.entries))
    assert calls[before:] == [expected]


def test_a_model_whose_train_takes_no_learning_rate_rehearses_at_its_own(lasa, monkeypatch):
    """A third-party model may reuse RNNPBParams (so it has a rehearsal_learning_rate)
    and define train with the interface's three arguments alone: teaching works, says
    once that the setting is not honoured, and calls train without the keyword."""
    agent = make_agent()
    model = agent.perceptual_model
    calls: list = []
    train = model.train

    def three_arguments(sequences, pbs_init=None, epochs=None):
        calls.append(epochs)
        return train(sequences, pbs_init, epochs)

    monkeypatch.setattr(model, "train", three_arguments)
    with pytest.warns(RuntimeWarning, match="takes no learning_rate.*rehearsal_learning_rate"):
        agent.teach([lasa["GShape/0"], lasa["Angle/0"]])
    assert len(calls) >= 2 and len(agent.memory) == 2
    assert rehearsal.takes_learning_rate(agent.perceptual_model) is False
    monkeypatch.undo()
    assert rehearsal.takes_learning_rate(agent.perceptual_model) is True


# -- inference ----------------------------------------------------------------------

def test_recognize_before_learning_is_a_not_fitted_error(lasa):
    agent = make_agent()
    with pytest.raises(NotFittedError, match="learned nothing yet"):
        agent.recognize([lasa["GShape/0"]])


def test_batched_recognition(lasa):
    agent = make_agent()
    agent.teach([lasa["GShape/0"], lasa["Angle/0"], lasa["Sine/0"]])
    snapshot = [e.copy() for e in agent.memory.entries]
    test = [lasa["GShape/4"], lasa["Angle/4"], lasa["Sine/4"], lasa["Sine/5"]]
    answers = agent.recognize(test)
    assert [a.demo for a in answers] == [d.key for d in test]
    for a in answers:
        assert a.concept in agent.memory.concepts()
        assert 0.0 <= a.confidence <= 1.0 and a.distance >= 0
        assert agent.memory.entries[a.entry].concept == a.concept
        assert a.source == agent.memory.entries[a.entry].source
        assert a.pb_obs.shape == (4,)
    single = agent.recognize(lasa["Sine/5"])
    assert single.concept == answers[3].concept
    # batch composition changes float32 rounding, which 30 LM steps amplify
    # (measured: 7.1e-4 on this PB distance of 0.06), not the answer
    assert single.distance == pytest.approx(answers[3].distance, abs=2e-3)
    assert entries_equal(agent.memory.entries, snapshot)    # inference changes nothing


def test_batched_recognition_is_independent_of_the_batch_in_float64(lasa):
    """In float64 a sequence's PB_obs does not depend on what else is in the batch."""
    config = small_config()
    config["perceptual_model"]["dtype"] = "float64"
    try:
        agent = iloci.build(config)
    except MissingBackendError as exc:
        pytest.skip(str(exc))
    agent.teach([lasa["GShape/0"], lasa["Angle/0"], lasa["Sine/0"]])
    batch = agent.recognize([lasa["GShape/4"], lasa["Sine/4"], lasa["Sine/5"]])
    single = agent.recognize(lasa["Sine/5"])
    np.testing.assert_allclose(single.pb_obs, batch[2].pb_obs, atol=1e-6)
    assert single.distance == pytest.approx(batch[2].distance, abs=1e-6)


# -- bad input ----------------------------------------------------------------------

def test_invalid_demonstration_mid_stream_is_skipped_and_changes_nothing(lasa, tmp_path):
    bad = np.ones((20, 2))
    bad[7, 1] = np.nan
    empty_csv = tmp_path / "empty.csv"
    empty_csv.write_text("x,y\n")
    stream = [lasa["GShape/0"], bad, str(empty_csv), lasa["Angle/0"]]
    agent = make_agent()
    with pytest.warns(SkippedDemonstrationWarning) as caught:
        report = agent.teach(stream)
    messages = [str(w.message) for w in caught]
    assert any("#1 of the stream" in m and "NaN" in m for m in messages)
    assert any("empty.csv" in m for m in messages)
    assert [s[0] for s in report.skipped] == ["#1 of the stream", repr(str(empty_csv))]
    assert [o.demo for o in report.outcomes] == ["GShape/0", "Angle/0"]
    # the same stream without the bad items gives exactly the same memory (seeded)
    clean = make_agent()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        clean.teach([lasa["GShape/0"], lasa["Angle/0"]])
    assert entries_equal(agent.memory.entries, clean.memory.entries)
    assert same_state(net_state(agent), net_state(clean))


def test_learn_raises_for_a_non_demonstration(lasa):
    agent = make_agent()
    with pytest.raises(iloci.errors.InvalidInputError, match="expected a Demonstration"):
        agent.learn(np.zeros((5, 2)))
    assert len(agent.memory) == 0


class BadTeacherPlugin:
    """A third-party teacher plugin whose feedback is not +1/-1."""

    class Teacher:
        def __init__(self, value: int = 0) -> None:
            self.value = value

        def feedback(self, demo, response):
            return self.value

    @hookimpl
    def iloci_register_teachers(self, registry) -> None:
        registry.add("says-zero", BadTeacherPlugin.Teacher, summary="broken on purpose")


@pytest.mark.parametrize("value", [0, 2, True, "yes", 1.0])
def test_feedback_other_than_plus_minus_one_is_an_error_and_changes_nothing(lasa, value):
    pm = get_plugin_manager()
    pm.register(BadTeacherPlugin(), name="bad-teacher")
    cfg = small_config()
    cfg["teacher"] = {"name": "says-zero"}
    try:
        agent = iloci.build(cfg, plugin_manager=pm)
    except MissingBackendError as exc:
        pytest.skip(str(exc))
    agent.teacher.value = value
    agent.learn(lasa["GShape/0"])                           # first: no feedback asked
    snapshot = agent.memory.copy()
    state = net_state(agent)
    with pytest.raises(FeedbackError, match=r"must be\s+\+1 \(reward\) or -1"):
        agent.learn(lasa["Angle/0"])
    assert entries_equal(agent.memory.entries, snapshot.entries)
    assert agent.memory.demonstrations_seen == 1 and agent.memory.concept_count == 1
    assert same_state(state, net_state(agent))


def test_response_is_performed_in_the_simulator(lasa):
    pytest.importorskip("pybullet")
    pm = get_plugin_manager()
    cfg = small_config(similarity_threshold=0.0)
    cfg["simulator"] = {"name": "pybullet"}
    try:
        agent = iloci.build(cfg, plugin_manager=pm)
    except MissingBackendError as exc:
        pytest.skip(str(exc))
    agent.learn(lasa["GShape/0"])
    teacher = ScriptedTeacher([1])
    agent.teacher = teacher
    agent.learn(lasa["GShape/1"])
    (response,) = teacher.responses
    ex = response.execution
    assert ex is not None and ex.end_effector.shape == (50, 3) and ex.joint_path.shape == (50, 4)
    lower, upper = np.asarray(agent.ik_solver.lower), np.asarray(agent.ik_solver.upper)
    assert np.all(response.joint_path >= lower) and np.all(response.joint_path <= upper)
    # the arm starts where the entry's pattern starts
    np.testing.assert_allclose(ex.joint_path[0], response.joint_path[0], atol=1e-6)


# -- the novelty answer and "unknown" -------------------------------------------------

def test_novelty_answer_founds_a_concept_in_one_interaction_or_goes_back_to_guessing(lasa):
    rec = Recorder()
    agent = make_agent(rec, novelty_below=1.0)  # every demonstration looks new
    teacher = ScriptedTeacher([-1, 1, -1, 1])
    agent.teacher = teacher
    agent.learn(lasa["GShape/0"])
    # one entry cannot calibrate "unlike": the robot guesses as the paper's does
    second = agent.learn(lasa["Angle/0"])
    assert second.feedbacks == (-1,) and not teacher.responses[0].novel
    third = agent.learn(lasa["Sine/0"])
    assert (third.action, third.feedbacks, third.concept) == ("new_concept", (1,), "c3")
    novel = teacher.responses[1]
    assert novel.novel and novel.source is None and novel.concept == "c3"
    assert set(novel.sources) == {"GShape/0", "Angle/0"}
    assert 0 < novel.extra["familiarity"] < 1
    seq, start = agent.memory.encoder.encode(agent.motion(lasa["Sine/0"]))
    # it imitated the demonstration back as it perceived it
    np.testing.assert_allclose(novel.motion, agent.memory.encoder.decode(seq, start)[0])
    fourth = agent.learn(lasa["GShape/1"])
    assert fourth.feedbacks == (-1, 1) and fourth.action in ("strengthen", "new_exemplar")
    assert teacher.responses[2].novel and not teacher.responses[3].novel
    assert [e.extra.get("novel") for e in rec.interactions[-2:]] == [True, None]
    assert fourth.first_guess_correct is False and third.first_guess_correct is True


@pytest.mark.parametrize("kind", ["path", "reproduction", "prediction"])
def test_novelty_answer_asks_the_configured_familiarity(lasa, kind):
    # "path" (default): the pen path against the nearest regenerated pen path;
    # "reproduction": how well the best known entry's PB reproduces the
    # demonstration; "prediction": the error from its own PB_obs
    agent = make_agent(novelty_below=1.0, familiarity=kind)
    teacher = ScriptedTeacher([-1, 1])
    agent.teacher = teacher
    agent.teach([lasa["GShape/0"], lasa["Angle/0"]])
    seq = agent.memory.encoder.encode(agent.motion(lasa["Sine/0"]))[0]
    learner = agent.learner
    scale = novelty_scale(learner.model, agent.memory)
    if kind == "path":
        patterns = regenerated_patterns(learner.model, agent.memory)
        error = path_distances([seq], patterns).min()
        scale = path_scale(patterns, agent.memory.concept_labels)
    elif kind == "reproduction":
        error = learner.entry_errors([seq]).min()
    else:
        error = learner.model.prediction_error([seq], learner.recognize_pbs([seq]))[0]
    agent.learn(lasa["Sine/0"])
    novel = teacher.responses[-1]
    assert novel.novel
    np.testing.assert_allclose(novel.extra["familiarity"], scale / (scale + error), rtol=1e-6)


def test_familiarity_setting_is_checked():
    with pytest.raises(iloci.errors.ConfigError, match="familiarity must be one of 'path', "
                                                       "'reproduction', 'prediction', "
                                                       "'regeneration', got 'pb'"):
        iloci.build(small_config(familiarity="pb"))


def test_recognition_answers_unknown_below_its_familiarity_threshold(lasa):
    agent = make_agent(unknown_below=0.999, familiarity="reproduction")
    agent.teach([lasa["GShape/0"], lasa["Angle/0"]])
    recs = agent.recognize([lasa["GShape/1"], lasa["Sine/0"]])
    for r in recs:
        assert 0 < r.familiarity <= 1 and r.unknown == (r.familiarity < 0.999)
        assert np.isfinite(r.error) and r.error >= 0
    # familiarity asks how well the best known entry reproduces it, on the
    # memory's own scale
    seqs = [agent.memory.encoder.encode(agent.motion(lasa[k]))[0] for k in ("GShape/1", "Sine/0")]
    best = agent.learner.entry_errors(seqs).min(axis=1)
    scale = novelty_scale(agent.learner.model, agent.memory)
    np.testing.assert_allclose([r.reproduction_error for r in recs], best, rtol=1e-6)
    np.testing.assert_allclose([r.familiarity for r in recs], scale / (scale + best), rtol=1e-6)
    off = make_agent()
    off.teach([lasa["GShape/0"], lasa["Angle/0"]])
    plain = off.recognize([lasa["Sine/0"]])[0]
    assert not plain.unknown and np.isnan(plain.reproduction_error)


def test_recognition_familiarity_by_default_is_the_pen_paths_distance(lasa):
    """``familiarity = "path"`` (default): the drawing's pen path against the
    pen paths the network regenerates from the entries, on the memory's scale."""
    agent = make_agent(unknown_below=0.9, tilts=())
    assert agent.config.learner.familiarity == "path"
    agent.teach([lasa["GShape/0"], lasa["Angle/0"], lasa["Sine/0"]])
    demos = [lasa["GShape/1"], lasa["Sine/2"], lasa["Angle/3"]]
    seqs = [agent.memory.encoder.encode(agent.motion(d))[0] for d in demos]
    patterns = regenerated_patterns(agent.perceptual_model, agent.memory)
    nearest = path_distances(seqs, patterns).min(axis=1)
    scale = path_scale(patterns, agent.memory.concept_labels)
    assert np.isfinite(scale) and scale > 0
    recs = agent.recognize(demos)
    np.testing.assert_allclose([r.familiarity for r in recs], scale / (scale + nearest),
                               rtol=1e-9)
    assert [r.unknown for r in recs] == [r.familiarity < 0.9 for r in recs]
    # no closed-loop run per entry for it
    assert all(np.isnan(r.reproduction_error) for r in recs)


def test_pen_path_and_path_distances():
    rng = np.random.default_rng(0)
    seq = rng.normal(size=(12, 6))
    p = pen_path(seq)
    assert p.shape == (13, 2)
    np.testing.assert_allclose(p.mean(axis=0), 0.0, atol=1e-12)
    assert np.sqrt((p ** 2).sum(axis=1).mean()) == pytest.approx(1.0)
    # where and how large a shape is drawn does not count; the joints do not either
    bigger = seq * 3.0
    bigger[:, 2:] = rng.normal(size=(12, 4))
    np.testing.assert_allclose(pen_path(bigger), p, atol=1e-12)
    assert np.all(pen_path(np.zeros((4, 6))) == 0)
    other = rng.normal(size=(12, 6))
    d = path_distances([seq, other], [bigger, other])
    np.testing.assert_allclose(np.diag(d), 0.0, atol=1e-12)
    assert d[0, 1] == pytest.approx(pattern_distances([p], [pen_path(other)], PATH_WARP)[0, 0])
    assert d[0, 1] > 0
    assert path_scale([seq, bigger, other], ["a", "a", "b"]) == pytest.approx(
        np.median([d[0, 1], d[0, 1], d[1, 0]]))
    assert np.isnan(path_scale([seq, other], ["a", "a"]))


@pytest.mark.parametrize("confirmation", [-1, 1])
def test_a_reward_after_a_no_is_kept_only_when_the_teacher_confirms_it(lasa, confirmation):
    rec = Recorder()
    agent = make_agent(rec, confirm_rewards=True)
    agent.teacher = ScriptedTeacher([-1, -1, 1, confirmation])
    agent.learn(lasa["GShape/0"])
    agent.learn(lasa["Angle/0"])  # -1: a second concept
    outcome = agent.learn(lasa["Angle/1"])
    assert outcome.feedbacks == (-1, 1, confirmation)
    actions = [e.action for e in rec.interactions if e.demo == "Angle/1"]
    assert actions[:2] == ["next_guess", "confirm"]
    if confirmation == 1:
        assert outcome.action in ("strengthen", "new_exemplar")
        assert len(agent.memory.concepts()) == 2
    else:  # the slip is caught: no merge, a concept of its own
        assert outcome.action == "new_concept" and len(agent.memory.concepts()) == 3


@pytest.mark.parametrize("confirmation", [-1, 1])
def test_a_reward_that_makes_a_new_exemplar_is_confirmed_first(lasa, confirmation):
    # similarity_threshold 0: every reward would make a new exemplar
    rec = Recorder()
    agent = make_agent(rec, confirm_new_exemplars=True, similarity_threshold=0.0)
    agent.teacher = ScriptedTeacher([-1, 1, confirmation, -1])
    agent.learn(lasa["GShape/0"])
    agent.learn(lasa["Angle/0"])  # -1: a second concept
    outcome = agent.learn(lasa["GShape/1"])  # +1 on the first guess: asked to confirm
    actions = [e.action for e in rec.interactions if e.demo == "GShape/1"]
    assert actions[0] == "confirm"
    if confirmation == 1:
        assert outcome.feedbacks == (1, 1) and outcome.action == "new_exemplar"
        assert len(agent.memory.concepts()) == 2
    else:  # not confirmed: the other concept is refused too, a concept of its own
        assert outcome.feedbacks == (1, -1, -1) and outcome.action == "new_concept"
        assert len(agent.memory.concepts()) == 3
    # a reward that only strengthens an entry is kept as given
    plain = make_agent(confirm_new_exemplars=True, similarity_threshold=10.0)
    plain.teacher = ScriptedTeacher([-1, 1])
    plain.teach([lasa["GShape/0"], lasa["Angle/0"]])
    assert plain.learn(lasa["GShape/1"]).feedbacks == (1,)


def test_refused_guesses_bring_the_novelty_answer_back_once(lasa):
    # [learner] novelty_after = 2 without novelty_below: the novelty answer is
    # first offered after two refused guesses, and only while a guess is left
    rec = Recorder()
    agent = make_agent(rec, novelty_after=2)
    teacher = ScriptedTeacher([-1, -1, -1, -1, -1, 1])
    agent.teacher = teacher
    agent.learn(lasa["GShape/0"])
    agent.learn(lasa["Angle/0"])
    # two refused guesses and no concept left to guess: founded, nothing asked
    third = agent.learn(lasa["Sine/0"])
    assert third.feedbacks == (-1, -1) and third.action == "new_concept"
    assert not any(r.novel for r in teacher.responses)
    fourth = agent.learn(lasa["GShape/1"])
    assert fourth.feedbacks == (-1, -1, 1)
    assert (fourth.action, fourth.concept) == ("new_concept", "c4")
    novel = teacher.responses[-1]
    assert novel.novel and novel.attempt == 3 and novel.concept == "c4"
    assert [r.attempt for r in teacher.responses[-3:-1]] == [1, 2]
    assert rec.interactions[-1].extra["novel"] is True


def test_a_refused_novelty_answer_is_offered_again_after_refused_guesses(lasa):
    # every demonstration looks new (novelty_below 1); novelty_after 1: after
    # the refusal and one refused guess it is asked again, then never more
    rec = Recorder()
    agent = make_agent(rec, novelty_below=1.0, novelty_after=1)
    teacher = ScriptedTeacher([-1, 1] + [-1] * 5)
    agent.teacher = teacher
    agent.learn(lasa["GShape/0"])
    agent.learn(lasa["Angle/0"])   # one concept: nothing to calibrate on, a guess
    assert agent.learn(lasa["Sine/0"]).feedbacks == (1,)
    asked = len(teacher.responses)
    outcome = agent.learn(lasa["GShape/1"])
    assert outcome.feedbacks == (-1,) * 5 and outcome.action == "new_concept"
    responses = teacher.responses[asked:]
    assert [r.novel for r in responses] == [True, False, True, False, False]
    assert [r.attempt for r in responses] == [1, 2, 3, 4, 5]
    # the same familiarity both times; the guesses are three different concepts
    assert responses[0].extra["familiarity"] == responses[2].extra["familiarity"]
    assert len({r.concept for r in responses if not r.novel}) == 3
    events = [e for e in rec.interactions if e.demo == "GShape/1"]
    assert [e.attempt for e in events if e.extra.get("novel")] == [1, 3]
    assert events[2].tried == (responses[1].concept,)


def test_oracle_and_console_teachers_answer_the_novelty_answer_asked_again(lasa):
    from iloci.teachers import ConsoleTeacher, OracleTeacher

    class Oracle(OracleTeacher):
        def __init__(self) -> None:
            super().__init__()
            self.asked: list[tuple[str, Response, int]] = []

        def feedback(self, demo, response):
            value = super().feedback(demo, response)
            self.asked.append((demo.key, response, value))
            return value

    # novelty_after 1 and no first novelty answer: every wrong first guess
    # brings the novelty answer; the oracle must found each shape once and
    # never merge or split one
    agent = make_agent(novelty_after=1)
    oracle = Oracle()
    agent.teacher = oracle
    keys = [f"{s}/{i}" for i in range(3) for s in ("GShape", "Angle", "Sine")]
    agent.teach([lasa[k] for k in keys])
    by_concept: dict[str, set[str]] = {}
    for e in agent.memory.entries:
        by_concept.setdefault(e.concept, set()).update(k.split("/")[0] for k in e.sources)
    assert sorted(map(sorted, by_concept.values())) == [["Angle"], ["GShape"], ["Sine"]]
    novel = [(k, r, v) for k, r, v in oracle.asked if r.novel]
    assert novel and all(r.attempt == 2 for _, r, _ in novel)
    # "yes" exactly when the memory held no demonstration of the shape
    for key, response, value in novel:
        shape = key.split("/")[0]
        assert (value == 1) == all(not k.startswith(shape + "/") for k in response.sources)
    # a person at the console is asked whether it is new, at that attempt
    prompts: list[str] = []
    answers = iter(["n", "y"])
    console = make_agent(novelty_after=1)
    console.teacher = ConsoleTeacher("", ask=lambda text: prompts.append(text) or next(answers))
    console.learn(lasa["GShape/0"])
    assert console.learn(lasa["Angle/0"]).action == "new_concept"
    assert "Is that right?" in prompts[0] and len(prompts) == 1
    console.teacher = ConsoleTeacher("", ask=lambda text: prompts.append(text) or "n")
    # Sine/0 with two concepts: a refused guess, then "is it new?" (refused),
    # then the last guess refused: a new concept
    outcome = console.learn(lasa["Sine/0"])
    assert outcome.feedbacks == (-1, -1, -1) and outcome.action == "new_concept"
    assert ["new concept" in t for t in prompts[1:]] == [False, True, False]
    assert "(attempt 1)" in prompts[1] and "(attempt 3)" in prompts[3]


@pytest.mark.parametrize("second", [-1, 1])
def test_a_reward_after_the_novelty_answer_asked_again_is_confirmed_twice(lasa, second):
    rec = Recorder()
    agent = make_agent(rec, novelty_after=1, confirm_rewards=True,
                       confirm_twice_after_novelty=True)
    # Sine/0: a refused guess, "new?" refused, then the last guess: +1 and
    # two confirmations (the second +1 or -1)
    agent.teacher = ScriptedTeacher([-1, -1, -1, 1, 1, second])
    agent.learn(lasa["GShape/0"])
    agent.learn(lasa["Angle/0"])
    outcome = agent.learn(lasa["Sine/0"])
    assert outcome.feedbacks == (-1, -1, 1, 1, second)
    actions = [e.action for e in rec.interactions if e.demo == "Sine/0"]
    assert actions[:4] == ["next_guess", "next_guess", "confirm", "confirm"]
    if second == 1:
        assert outcome.action in ("strengthen", "new_exemplar")
        assert len(agent.memory.concepts()) == 2
    else:  # the double slip is caught: a concept of its own
        assert outcome.action == "new_concept" and len(agent.memory.concepts()) == 3
    # without it, one confirmation is enough there
    once = make_agent(novelty_after=1, confirm_rewards=True)
    once.teacher = ScriptedTeacher([-1, -1, -1, 1, 1])
    once.teach([lasa["GShape/0"], lasa["Angle/0"]])
    assert once.learn(lasa["Sine/0"]).feedbacks == (-1, -1, 1, 1)


def test_novelty_after_is_checked():
    with pytest.raises(iloci.errors.ConfigError, match="novelty_after must be >= 0, got -1"):
        iloci.build(small_config(novelty_after=-1))
    with pytest.raises(iloci.errors.ConfigError, match="confirm_twice_after_novelty needs "
                                                       "novelty_after > 0"):
        iloci.build(small_config(confirm_twice_after_novelty=True))


def test_reproduction_decision_answers_with_the_entry_that_reproduces_best(lasa):
    agent = make_agent(decision="reproduction")
    agent.teach([lasa["GShape/0"], lasa["Angle/0"], lasa["Sine/0"]])
    demos = [lasa["GShape/2"], lasa["Sine/3"]]
    seqs = [agent._encode(agent.motion(d))[0] for d in demos]
    errors = agent.learner.entry_errors(seqs)
    assert errors.shape == (2, len(agent.memory))
    # each pair's error is the model's own prediction error from that entry's PB
    for b, seq in enumerate(seqs):
        for m, e in enumerate(agent.memory.entries):
            assert errors[b, m] == pytest.approx(
                agent.perceptual_model.prediction_error([seq], e.pb[None])[0], rel=1e-5)
    for r, row in zip(agent.recognize(demos), errors):
        assert r.entry == int(np.argmin(row))
        assert r.concept == agent.memory.entries[r.entry].concept
    with pytest.raises(iloci.errors.ConfigError, match="decision must be"):
        iloci.build(small_config(decision="nearest"))


def test_regeneration_decision_answers_with_the_nearest_regenerated_pattern(lasa):
    agent = make_agent(decision="regeneration", familiarity="regeneration", tilts=(), warp=0,
                       compare="displacements")
    agent.teach([lasa["GShape/0"], lasa["Angle/0"], lasa["Sine/0"]])
    demos = [lasa["GShape/2"], lasa["Sine/3"], lasa["Angle/5"]]
    seqs = [agent._encode(agent.motion(d))[0] for d in demos]
    mem, model = agent.memory, agent.perceptual_model
    # what the network regenerates from each entry's PB, not the kept demonstration
    patterns = regenerated_patterns(model, mem)
    for g, e in zip(patterns, mem.entries):
        np.testing.assert_allclose(g, model.generate(e.pb[None], e.initial_input[None],
                                                     [e.num_steps])[0])
        assert not np.array_equal(g, e.pattern)
    d = agent.learner.regeneration_distances(seqs)
    assert d.shape == (3, len(mem))
    for b, seq in enumerate(seqs):
        for m, g in enumerate(patterns):
            assert d[b, m] == pytest.approx(np.mean((seq - g) ** 2), rel=1e-9)
    recs = agent.recognize(demos)
    for r, row in zip(recs, d):
        assert r.entry == int(np.argmin(row))
        assert r.concept == mem.entries[r.entry].concept
        # familiarity on the memory's own scale of regenerated patterns
        scale = regeneration_scale(patterns, mem.concept_labels)
        assert r.familiarity == pytest.approx(scale / (scale + row.min()))
    with pytest.raises(iloci.errors.ConfigError, match="familiarity must be"):
        iloci.build(small_config(familiarity="regenerated"))


def test_default_regeneration_compares_positions_and_displacements_warped(lasa):
    """The default compare = "both-distances", warp = 8: each entry's distance is
    pattern_distances of the encoded drawing, as positions and displacements, to its
    regenerated pattern."""
    agent = make_agent(familiarity="regeneration", tilts=())
    assert (agent.config.learner.compare, agent.config.learner.warp) == ("both-distances", 8)
    agent.teach([lasa["GShape/0"], lasa["Angle/0"], lasa["Sine/0"]])
    demos = [lasa["GShape/2"], lasa["Sine/3"]]
    seqs = [agent._encode(agent.motion(d))[0] for d in demos]
    patterns = regenerated_patterns(agent.perceptual_model, agent.memory)
    d = agent.learner.regeneration_distances(seqs)
    np.testing.assert_allclose(d, pattern_distances(seqs, patterns, 8, "both-distances"))
    assert not np.allclose(d, pattern_distances(seqs, patterns, 8, "displacements"))
    assert not np.allclose(d, pattern_distances(seqs, patterns, 8, "both"))
    scale = regeneration_scale(patterns, agent.memory.concept_labels, 8, "both-distances")
    for r, row in zip(agent.recognize(demos), d):
        assert r.entry == int(np.argmin(row))
        assert r.familiarity == pytest.approx(scale / (scale + row.min()))
    with pytest.raises(iloci.errors.ConfigError, match="compare must be"):
        iloci.build(small_config(compare="path"))


def test_the_kept_distance_weight_is_the_one_of_the_memory_as_it_is_now(lasa, monkeypatch):
    """compare = "both-distances" keeps its weight (two M x M DTWs over the regenerated
    patterns) for the memory state it was computed on: given again while the memory is
    unchanged, computed afresh after a rehearsal (same entries, another network)."""
    from iloci.concepts import inference
    agent = make_agent(tilts=())
    agent.teach([lasa["GShape/0"], lasa["Angle/0"], lasa["Sine/0"]])
    seq = agent._encode(agent.motion(lasa["GShape/2"]))[0]
    learner, mem = agent.learner, agent.memory
    computed = []
    real = inference.pattern_distances

    def counting(sequences, patterns, warp=0, compare="displacements"):
        computed.append(compare)
        return real(sequences, patterns, warp, compare)

    monkeypatch.setattr(inference, "pattern_distances", counting)
    monkeypatch.setattr(inference, "_LAST_WEIGHT", None)
    first = learner.regeneration_distances([seq])
    assert computed.count("positions") == 1
    np.testing.assert_array_equal(learner.regeneration_distances([seq]), first)
    assert computed.count("positions") == 1            # same memory: the weight kept
    old = inference._distance_weight(regenerated_patterns(agent.perceptual_model, mem), 8)
    learner.rehearse("test", list(mem.entries))        # same entries, retrained network
    assert len(mem) == 3
    after = learner.regeneration_distances([seq])
    assert computed.count("positions") == 2            # another memory: computed afresh
    patterns = regenerated_patterns(agent.perceptual_model, mem)
    assert inference._distance_weight(patterns, 8) != old
    monkeypatch.setattr(inference, "_LAST_WEIGHT", None)
    fresh = learner.regeneration_distances([seq])
    np.testing.assert_array_equal(after, fresh)        # bit for bit what no keeping gives
    assert not np.array_equal(after, first)


def _naive_dtw(x: np.ndarray, y: np.ndarray, band: int) -> float:
    """Textbook DTW (Sakoe and Chiba 1978, symmetric steps, band) of summed squared steps."""
    n = len(x)
    acc = np.full((n + 1, n + 1), np.inf)
    acc[0, 0] = 0.0
    for i in range(1, n + 1):
        for j in range(max(1, i - band), min(n, i + band) + 1):
            acc[i, j] = np.sum((x[i - 1] - y[j - 1]) ** 2) + min(acc[i - 1, j], acc[i, j - 1],
                                                                 acc[i - 1, j - 1])
    return float(acc[n, n])


def test_pattern_distances_as_positions_both_and_warp_against_a_plain_loop():
    rng = np.random.default_rng(3)
    seqs = [rng.normal(size=(7, 3)) for _ in range(3)]
    pats = [rng.normal(size=(7, 3)) for _ in range(4)]
    # positions: the displacements summed from a zero first row, centred over the steps
    p = as_positions(seqs[0])
    assert p.shape == (8, 3)
    np.testing.assert_allclose(p.mean(axis=0), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.diff(p, axis=0), seqs[0])
    d = pattern_distances(seqs, pats, compare="positions")
    assert d[1, 2] == pytest.approx(np.mean((as_positions(seqs[1]) - as_positions(pats[2])) ** 2))
    # both: positions (weighed by the patterns' RMS displacement over RMS position) beside
    # the displacements
    w = np.sqrt(np.mean(np.stack(pats) ** 2)) / np.sqrt(
        np.mean(np.stack([as_positions(q) for q in pats]) ** 2))

    def both(s):
        return np.hstack([w * as_positions(s)[1:], s])

    d = pattern_distances(seqs, pats, compare="both")
    assert d[2, 3] == pytest.approx(np.mean((both(seqs[2]) - both(pats[3])) ** 2))
    # both-distances: positions weighed so that both halves' distances between the
    # patterns (with the same band) have the same median
    for band in (0, 3):
        off = ~np.eye(4, dtype=bool)
        pp = pattern_distances(pats, pats, band, "positions")[off]
        dd = pattern_distances(pats, pats, band, "displacements")[off]
        wd = np.sqrt(np.median(dd) / np.median(pp))
        assert np.median(wd ** 2 * pp) == pytest.approx(np.median(dd))

        def both_d(s, wd=wd):
            return np.hstack([wd * as_positions(s)[1:], s])

        d = pattern_distances(seqs, pats, band, "both-distances")
        ref = pattern_distances([both_d(q) for q in seqs], [both_d(q) for q in pats], band,
                                "displacements")
        np.testing.assert_allclose(d, ref, rtol=1e-12)
    assert pattern_distances(seqs[:1], pats[:1], 0, "both-distances")[0, 0] == pytest.approx(
        np.mean((np.hstack([as_positions(seqs[0])[1:], seqs[0]])
                 - np.hstack([as_positions(pats[0])[1:], pats[0]])) ** 2))   # one pattern: w = 1
    # the banded DTW, vectorised over pairs, is the textbook recursion
    for compare, f in (("displacements", lambda s: s), ("both", both)):
        for band in (1, 3, 7):
            d = pattern_distances(seqs, pats, band, compare)
            for b, s in enumerate(seqs):
                for m, q in enumerate(pats):
                    assert d[b, m] == pytest.approx(
                        _naive_dtw(f(s), f(q), band) / (7 * f(s).shape[1]), rel=1e-10)
    with pytest.raises(iloci.errors.InvalidInputError, match="compare must be one of"):
        pattern_distances(seqs, pats, compare="path")


def test_the_patterns_against_themselves_are_aligned_once_per_pair_bit_for_bit():
    """pattern_distances(pats, pats) (the memory's own scales, the both-distances weight)
    aligns each unordered pair once, in a layout of its own: the same bits as the
    (B, M) alignment of every ordered pair, for any band, length and feature count
    (the einsum's summation order of 1 to 17 features, zeros of either sign)."""
    from iloci.concepts.inference import _warped, _warped_itself
    rng = np.random.default_rng(7)
    for m, t, d, band in [(1, 5, 2, 3), (2, 0, 6, 8), (5, 1, 1, 2), (7, 12, 3, 1), (9, 20, 6, 8),
                          (4, 9, 8, 30), (6, 15, 9, 4), (3, 11, 12, 5), (8, 16, 17, 8),
                          (40, 10, 2, 3)]:
        P = rng.normal(size=(m, t, d)) * 10.0 ** rng.integers(-3, 4, size=(m, 1, 1))
        if t:
            P[:, :, 0] = 0.0
            P[:, ::2, -1] = -0.0
        if m > 2:
            P[2] = P[1]
        assert _warped_itself(P, band).tobytes() == _warped(P, P, band).tobytes(), (m, t, d, band)
    pats = [np.cumsum(rng.normal(size=(49, 6)), axis=0) * 0.01 for _ in range(12)]
    for compare in COMPARES:
        for warp in (0, 8):
            assert (pattern_distances(pats, pats, warp, compare).tobytes()
                    == pattern_distances(pats, list(pats), warp, compare).tobytes())


def test_pattern_distances_and_regeneration_scale():
    a = np.zeros((5, 2))
    b = np.ones((5, 2))
    c = np.stack([np.linspace(0, 1, 9)] * 2, axis=1)
    d = pattern_distances([a, b], [a, b, c])
    np.testing.assert_allclose(d[:, :2], [[0.0, 1.0], [1.0, 0.0]])
    # a pattern of another length is resampled in time to the sequence's
    assert d[0, 2] == pytest.approx(np.mean(np.linspace(0, 1, 5) ** 2))
    assert pattern_distances([a], []).shape == (1, 0)
    # warped: a step pattern shifted by two steps costs only where it jumps
    x = np.zeros((8, 1))
    x[3:] = 1.0
    y = np.zeros((8, 1))
    y[5:] = 1.0
    assert pattern_distances([x], [y])[0, 0] == pytest.approx(2 / 8)
    assert pattern_distances([x], [y], warp=1)[0, 0] == pytest.approx(1 / 8)
    assert pattern_distances([x], [y], warp=2)[0, 0] == pytest.approx(0.0)
    with pytest.raises(iloci.errors.ConfigError, match="warp must be"):
        iloci.build(small_config(warp=-1))
    assert np.isnan(regeneration_scale([a, b], ["c1", "c1"]))
    # nearest pattern of another concept: a -> c (0.375), b -> a (1), c -> a (on c's 9 steps)
    to_c = np.mean(np.linspace(0, 1, 9) ** 2)
    assert regeneration_scale([a, b, c], ["c1", "c2", "c2"]) == pytest.approx(
        np.median([0.375, 1.0, to_c]))


def test_rehearsal_from_kept_demonstrations(lasa, tmp_path):
    """rehearse_from = "demonstrations": each entry keeps its encoded demonstration,
    rehearsal trains on it (not on a regeneration), and it survives save/load."""
    assert make_agent().config.learner.rehearse_from == "demonstrations"   # iloci's default
    agent = make_agent(rehearse_from="demonstrations")
    demos = [lasa["GShape/0"], lasa["Angle/0"], lasa["Sine/0"], lasa["GShape/3"]]
    agent.teach(demos)
    by_key = {d.key: d for d in demos}
    for e in agent.memory.entries:
        seq = agent._encode(agent.motion(by_key[e.source]))[0]
        np.testing.assert_array_equal(e.pattern, seq)
    patterns = rehearsal.regenerate(agent.perceptual_model, agent.memory.entries)
    for p, e in zip(patterns, agent.memory.entries):
        np.testing.assert_array_equal(p, e.pattern)
    # the paper's setting keeps nothing and regenerates
    plain = make_agent(rehearse_from="regenerated")
    plain.teach(demos[:2])
    assert all(e.pattern is None for e in plain.memory.entries)
    regen = rehearsal.regenerate(plain.perceptual_model, plain.memory.entries)
    assert not np.array_equal(regen[0], plain._encode(plain.motion(demos[0]))[0])
    path = agent.save(tmp_path / "kept.npz")
    back = iloci.Agent.load(path)
    assert entries_equal(back.memory.entries, agent.memory.entries)
    assert all(e.pattern is not None for e in back.memory.entries)
    with pytest.raises(iloci.errors.ConfigError, match="rehearse_from must be"):
        iloci.build(small_config(rehearse_from="raw"))
