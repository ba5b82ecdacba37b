"""The step-wise learning phase (Agent.observe / Turn.feedback), its worker process, rename.

Real RNNPB (native-rnnpb, few epochs), real IK, real LASA demonstrations.
``Agent.learn`` with a teacher and the same feedback given step by step
must do exactly the same thing: they are one code path.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading

import numpy as np
import pytest
from scipy.spatial.distance import cdist

import iloci
from iloci.concepts.learner import Answer, LearnOutcome
from iloci.concepts.memory import entries_equal
from iloci.concepts.rehearsal import PHASES
from iloci.data import load_lasa
from iloci.concepts.learner import show_to_teacher
from iloci.errors import FeedbackError, InvalidInputError, MissingBackendError, StaleAnswerError
from iloci.sensorimotor.frames import TeacherFrame

pytest.importorskip("iloci_native")
pytest.importorskip("pinocchio")

EPOCHS = 30


def config() -> dict:
    return {"perceptual_model": {"name": "native-rnnpb", "epochs": EPOCHS,
                                 "recognition_steps": EPOCHS},
            "learner": {"rehearsal_epochs": EPOCHS}, "evaluation": {"seed": 0}}


def make_agent(**overrides) -> iloci.Agent:
    try:
        return iloci.build(config(), **overrides)
    except MissingBackendError as exc:
        pytest.skip(str(exc))


@pytest.fixture(scope="module")
def lasa():
    return {d.key: d for d in load_lasa(["GShape", "Angle", "Sine"])}


def state(agent) -> dict:
    return {k: np.array(v, copy=True) for k, v in agent.perceptual_model.state().items()}


def same_state(a: dict, b: dict) -> bool:
    return set(a) == set(b) and all(np.array_equal(a[k], b[k]) for k in a)


def test_step_by_step_is_the_same_as_learn_with_a_teacher(lasa):
    stream = [lasa[k] for k in ("GShape/0", "Angle/0", "GShape/1", "Sine/0")]
    with_teacher = make_agent()
    outcomes = [with_teacher.learn(d) for d in stream]  # oracle teacher
    oracle = with_teacher.teacher
    stepped = make_agent()
    for demo, expected in zip(stream, outcomes):
        turn = stepped.observe(demo)
        answers, step = [], turn.outcome
        while not turn.done:
            answers.append(turn.answer)
            step = turn.feedback(oracle.feedback(demo, turn.answer.response), turn.answer.id)
            assert isinstance(step, (Answer, LearnOutcome))
        assert turn.answer is None and step is turn.outcome
        got = turn.outcome
        assert (got.action, got.concept, got.feedbacks) == (expected.action, expected.concept,
                                                            expected.feedbacks)
        assert [a.attempt for a in answers] == list(range(1, len(answers) + 1))
    assert entries_equal(stepped.memory.entries, with_teacher.memory.entries)
    assert same_state(state(stepped), state(with_teacher))


def test_an_answer_carries_what_a_person_and_a_controller_need(lasa):
    agent = make_agent()
    agent.learn(lasa["GShape/0"])
    demo = lasa["GShape/1"]
    turn = agent.observe(demo)
    a = turn.answer
    assert (a.demo, a.concept, a.attempt) == ("GShape/1", "c1", 1)
    assert a.confidence == 1.0                      # the only concept
    entry = agent.memory.entries[a.entry]
    assert a.dt == entry.dt == a.response.dt > 0
    assert a.joint_path.shape == (50, 4)
    np.testing.assert_array_equal(a.start_posture, a.joint_path[0])
    lower, upper = np.asarray(agent.ik_solver.lower), np.asarray(agent.ik_solver.upper)
    assert np.all(a.joint_path >= lower) and np.all(a.joint_path <= upper)
    # the drawing is in the demonstration's frame: LASA units, where the demonstration is
    motion = agent.motion(demo)
    frame = TeacherFrame.of(demo, motion.plane_points)
    np.testing.assert_allclose(a.drawing, frame.to_teacher(a.response.drawing))
    # every motion point, mapped back, lies on the drawn path (whatever the resampling)
    back = frame.to_teacher(motion.plane_points)
    assert cdist(back, demo.positions).min(axis=1).max() < 0.05 * np.ptp(demo.positions)
    lo, hi = demo.positions.min(axis=0), demo.positions.max(axis=0)
    span = hi - lo
    assert np.all(a.drawing.min(axis=0) > lo - 0.6 * span)
    assert np.all(a.drawing.max(axis=0) < hi + 0.6 * span)


def test_a_bad_feedback_or_a_stale_turn_changes_nothing(lasa):
    agent = make_agent()
    agent.learn(lasa["GShape/0"])
    turn = agent.observe(lasa["Angle/0"])
    before, net = agent.memory.copy(), state(agent)
    for bad in (0, 2, True, "yes", 1.0):
        with pytest.raises(FeedbackError, match=r"must be \+1 \(reward\) or -1"):
            turn.feedback(bad, turn.answer.id)
    assert entries_equal(agent.memory.entries, before.entries) and same_state(net, state(agent))
    other = agent.observe(lasa["GShape/1"])
    pending = other.answer.id
    other.feedback(1, pending)                      # the memory changes under `turn`
    with pytest.raises(InvalidInputError, match="memory changed since 'Angle/0'"):
        turn.feedback(-1, turn.answer.id)
    assert other.done
    with pytest.raises(InvalidInputError, match="is over"):
        other.feedback(1, pending)


def test_a_turn_observed_before_an_undo_start_over_or_load_is_refused(lasa, tmp_path):
    """An audit: a turn observed, then agent.restore(snapshot) (or start_over, or
    replace_memory): its feedback still went on, into the memory the agent no longer used
    (the new concept lost), and retrained the network the current memory relies on."""
    agent = make_agent()
    agent.learn(lasa["GShape/0"])
    agent.save(tmp_path / "m.npz")
    snap = agent.snapshot()
    for replace in (lambda: agent.restore(snap),
                    lambda: agent.replace_memory(tmp_path / "m.npz"), agent.start_over):
        turn = agent.observe(lasa["Angle/0"])
        replace()
        current, net = agent.memory.copy(), state(agent)
        with pytest.raises(InvalidInputError, match="the memory was replaced since 'Angle/0' "
                                                    "was observed .* observe it again"):
            turn.feedback(-1, turn.answer.id)
        assert entries_equal(agent.memory.entries, current.entries)
        assert same_state(net, state(agent))
    agent.replace_memory(tmp_path / "m.npz")
    turn = agent.observe(lasa["Angle/0"])              # observed again: learned as usual
    while not turn.done:
        turn.feedback(-1, turn.answer.id)
    assert turn.outcome.action == "new_concept"


def test_a_step_that_fails_half_way_is_put_back_whole(lasa):
    """An audit: a clusterer that raised after the rehearsal had installed the new
    exemplar left 3 entries for 2 demonstrations, the turn not done, the same feedback then
    refused ("memory changed"), and the demonstration counted twice when learned again. A
    failed step now puts back the memory, the network and the turn."""

    class Failing:
        calls = 0

        def cluster(self, points, d_cutoff):
            Failing.calls += 1
            raise RuntimeError("the clusterer's own bug")

    settings = config()
    settings["learner"].update(num_threshold=1, similarity_threshold=1e-9)
    try:
        agent = iloci.build(settings, clusterer=Failing())
    except MissingBackendError as exc:
        pytest.skip(str(exc))
    agent.learn(lasa["GShape/0"])
    agent.learn(lasa["Angle/0"])
    turn = agent.observe(lasa["GShape/1"])
    while turn.answer.concept != agent.memory.entries[0].concept:
        turn.feedback(-1, turn.answer.id)
    before, net, seen = agent.memory.copy(), state(agent), agent.memory.demonstrations_seen
    revision, answer = agent.memory.revision, turn.answer
    for _ in range(2):  # the same feedback, given again, fails the same way: nothing stale
        with pytest.raises(RuntimeError, match="the clusterer's own bug"):
            turn.feedback(1, answer.id)
        assert entries_equal(agent.memory.entries, before.entries)
        assert agent.memory.demonstrations_seen == seen and agent.memory.revision == revision
        assert same_state(net, state(agent))                 # the rehearsal undone too
        assert not turn.done and turn.answer == answer and turn.feedbacks.count(1) == 0
    assert Failing.calls == 2


def counters(agent) -> tuple:
    m = agent.memory
    return (m.concept_count, m.demonstrations_seen, [e.num_samples for e in m.entries],
            [e.sources for e in m.entries])


def test_every_answer_has_an_id_and_a_duplicate_or_late_feedback_is_refused(lasa):
    """Issue 30: a stack that sends every feedback twice, and late ones for answers
    already judged or of earlier turns, ends with the memory of one that sent each once."""
    stream = [lasa[k] for k in ("GShape/0", "Angle/0", "GShape/1", "Sine/0", "Angle/1")]
    once, twice = make_agent(), make_agent()
    ids, refused = [], 0
    for demo in stream:
        for agent in (once, twice):
            show_to_teacher(agent.teacher, demo)
        turn = once.observe(demo)
        while not turn.done:
            turn.feedback(once.teacher.feedback(demo, turn.answer.response), turn.answer.id)
        twice.observe(demo)
        while twice.pending is not None:
            answer = twice.pending
            assert answer.id and answer.id not in ids
            value = twice.teacher.feedback(demo, answer.response)
            twice.feedback(value, answer.id)
            before = (counters(twice), state(twice))
            for late in [answer.id] + ids[-3:]:      # the duplicate, then late ones
                with pytest.raises(StaleAnswerError, match="not waiting") as info:
                    twice.feedback(-value, late)
                assert info.value.answer_id == late
                refused += 1
            assert counters(twice) == before[0] and same_state(state(twice), before[1])
            ids.append(answer.id)
    assert refused >= 2 * len(ids)
    assert entries_equal(twice.memory.entries, once.memory.entries)
    assert counters(twice) == counters(once) and same_state(state(twice), state(once))


def test_a_feedback_must_name_the_pending_answer(lasa):
    agent = make_agent()
    with pytest.raises(StaleAnswerError, match="no demonstration has been observed"):
        agent.feedback(1, "0123abcd-1")
    agent.learn(lasa["GShape/0"])
    turn = agent.observe(lasa["Angle/0"])
    with pytest.raises(FeedbackError, match="must name the answer"):
        turn.feedback(-1)
    with pytest.raises(StaleAnswerError, match="not an answer of this turn"):
        turn.feedback(-1, "0123abcd-1")
    first = turn.answer
    newer = agent.observe(lasa["Angle/0"])            # the stack observed again
    with pytest.raises(StaleAnswerError, match="not an answer of this turn"):
        agent.feedback(-1, first.id)                  # the old turn's answer
    outcome = agent.feedback(-1, newer.answer)        # an Answer stands for its id
    assert outcome.action == "new_concept" and newer.done
    with pytest.raises(StaleAnswerError, match="is over"):
        newer.feedback(-1, first.id.replace(turn.token, newer.token))


def test_a_demonstration_taught_twice_is_learned_once(lasa, tmp_path):
    """Issue 30: the same stroke (same key, same samples) shown again is recognized as
    learned and not learned again: one entry, every count unchanged, nothing asked."""
    agent = make_agent()
    first = agent.teach([lasa[k] for k in ("GShape/0", "Angle/0", "GShape/1")])
    before, counts, net = agent.memory.copy(), counters(agent), state(agent)
    again = agent.teach([lasa["GShape/1"], lasa["GShape/0"]])
    assert [o.action for o in again.outcomes] == ["already_learned"] * 2
    assert again.already_learned == ["GShape/1", "GShape/0"] and again.feedbacks == []
    assert [o.concept for o in again.outcomes] == [first.outcomes[2].concept, "c1"]
    turn = agent.observe(lasa["Angle/0"])
    assert turn.done and turn.answer is None and turn.outcome.action == "already_learned"
    assert entries_equal(agent.memory.entries, before.entries)
    assert counters(agent) == counts and same_state(state(agent), net)
    assert sum(e.sources.count("GShape/1") for e in agent.memory.entries) == 1
    # the record is saved with the memory
    back = iloci.Agent.load(agent.save(tmp_path / "m.npz"))
    assert back.learn(lasa["GShape/0"]).action == "already_learned"
    # the same key with other samples is another demonstration
    g = lasa["GShape/1"]
    other = iloci.Demonstration(g.positions * 1.01, times=g.times, shape="GShape", index=1,
                                true_concept="GShape")
    assert agent.learn(other).action != "already_learned"
    assert agent.memory.demonstrations_seen == counts[1] + 1


def test_the_same_stroke_sent_again_in_float32_or_restamped_is_learned_once(lasa):
    """What a stack sends again is rarely bit for bit the same: a transport in float32
    (ROS's Point32), new time stamps (a replay), float noise far below float32's
    precision. Each is the same demonstration (same key): learned once."""
    agent = make_agent()
    agent.teach([lasa[k] for k in ("GShape/0", "Angle/0")])
    counts, net = counters(agent), state(agent)
    g = lasa["GShape/0"]
    variants = [g.positions.astype(np.float32).astype(np.float64),
                g.positions, g.positions]
    times = [g.times, g.times + 1.7e9, g.times * 1.5]
    for pos, t in zip(variants, times):
        again = iloci.Demonstration(pos, times=t, shape="GShape", index=0,
                                    true_concept="GShape")
        assert agent.learn(again).action == "already_learned"
    noisy = iloci.Demonstration(np.nextafter(g.positions, np.inf), times=g.times,
                                shape="GShape", index=0,     # one float64 step away
                                true_concept="GShape")
    assert agent.learn(noisy).action == "already_learned"
    assert counters(agent) == counts and same_state(state(agent), net)
    assert sum(e.sources.count("GShape/0") for e in agent.memory.entries) == 1
    # a memory saved with the earlier digest (key, positions and times bit for bit)
    from iloci.concepts.entry import _digest_v1
    old = agent.memory.copy()
    old.learned = {_digest_v1(lasa[k]) for k in ("GShape/0", "Angle/0")}
    assert old.learned_concept(lasa["Angle/0"]) == agent.memory.learned_concept(lasa["Angle/0"])


def test_the_first_demonstration_ends_its_turn_at_once(lasa):
    agent = make_agent()
    phases = []
    agent.on_progress = phases.append
    turn = agent.observe(lasa["GShape/0"])
    assert turn.done and turn.answer is None and turn.outcome.action == "new_concept"
    assert [p.phase for p in phases] == list(PHASES)
    assert [p.fraction for p in phases] == sorted(p.fraction for p in phases)
    assert phases[-1].fraction == 1.0 and phases[-1].reason == "new_concept"
    # the last report is taken just after the rehearsal's own clock stops (same clock)
    assert 0 < turn.outcome.rehearsals[0].seconds <= phases[-1].elapsed


def test_on_progress_set_after_observe_applies_to_that_turn(lasa):
    agent = make_agent()
    agent.learn(lasa["GShape/0"])
    turn = agent.observe(lasa["Angle/0"])          # guesses GShape's concept: wrong
    phases = []
    agent.on_progress = phases.append              # set while the turn waits
    while not turn.done:
        turn.feedback(-1, turn.answer.id)
    assert turn.outcome.action == "new_concept"
    assert [p.phase for p in phases] == list(PHASES)
    agent.on_progress = None                       # and unset: no more reports
    turn = agent.observe(lasa["Sine/0"])
    while not turn.done:
        turn.feedback(-1, turn.answer.id)
    assert len(phases) == len(PHASES)


def test_an_on_progress_that_raises_loses_its_reports_not_the_learning(lasa):
    from iloci.errors import ProgressCallbackWarning

    def broken(progress):
        raise ValueError("the progress bar's bug")
    plain, with_bug = make_agent(), make_agent()
    with_bug.on_progress = broken
    for key in ("GShape/0", "Angle/0"):
        for agent in (plain, with_bug):
            with pytest.warns(ProgressCallbackWarning, match="progress bar's bug") \
                    if agent is with_bug else contextlib.nullcontext():
                turn = agent.observe(lasa[key])
                while not turn.done:
                    turn.feedback(-1, turn.answer.id)
    # learned as it is without the callback: the same memory, the same network
    assert entries_equal(with_bug.memory.entries, plain.memory.entries)
    assert with_bug.memory.demonstrations_seen == plain.memory.demonstrations_seen == 2
    assert same_state(state(with_bug), state(plain))


def test_the_worker_process_gives_the_same_results_and_its_network_comes_back(lasa):
    stream = [lasa[k] for k in ("GShape/0", "Angle/0", "GShape/1")]
    local = make_agent()
    for d in stream:
        local.learn(d)
    agent = make_agent()
    with agent.start_worker() as a:
        assert a is agent and type(agent.perceptual_model).__name__ == "WorkerModel"
        pid = agent.perceptual_model.pid
        for d in stream:
            agent.learn(d)
        assert same_state(state(agent), state(local))   # state() read from the worker
        recognized = agent.recognize(lasa["GShape/2"])
    assert pid is not None and type(agent.perceptual_model) is type(local.perceptual_model)
    assert entries_equal(agent.memory.entries, local.memory.entries)
    assert same_state(state(agent), state(local))
    assert recognized.concept == local.recognize(lasa["GShape/2"]).concept


def test_the_worker_models_params_follow_a_loaded_state(lasa):
    """The learner reads the rehearsal's rate from the model's params: a state loaded
    into the worker brings its own, and the worker's stand-in says so."""
    agent = make_agent()
    agent.learn(lasa["GShape/0"])
    st = dict(agent.perceptual_model.state())
    st["param.rehearsal_learning_rate"] = np.array(0.0025)
    with agent.start_worker():
        model = agent.perceptual_model
        assert model.params.rehearsal_learning_rate == 0.001
        model.load_state(st)
        assert model.params.rehearsal_learning_rate == 0.0025
        assert agent.learner.rehearsal_learning_rate == 0.0025


def test_an_error_in_the_worker_reaches_the_caller_as_itself(lasa):
    agent = make_agent()
    with agent.start_worker():
        with pytest.raises(InvalidInputError):
            agent.perceptual_model.train([np.full((5, 6), np.nan)])
        agent.learn(lasa["GShape/0"])                  # the worker still serves
    assert len(agent.memory) == 1


def test_asyncio_steps_leave_the_event_loop_free(lasa):
    # No timing: the rehearsal's first progress report (in aobserve's worker thread) asks
    # the event loop to run a callback and waits for it. Were the loop blocked by the
    # step, the callback could not run and the wait would time out.
    agent = make_agent()
    served: list[bool] = []
    threads: list[int] = []

    async def main():
        loop = asyncio.get_running_loop()

        def on_progress(progress):
            if served:
                return
            threads.append(threading.get_ident())
            ran = threading.Event()
            loop.call_soon_threadsafe(ran.set)
            served.append(ran.wait(timeout=60))

        agent.on_progress = on_progress
        turn = await agent.aobserve(lasa["GShape/0"])   # a rehearsal, in a thread
        turn = await agent.aobserve(lasa["Angle/0"])
        outcome = await turn.afeedback(-1, turn.answer.id)
        return threading.get_ident(), outcome

    loop_thread, outcome = asyncio.run(main())
    assert outcome.action == "new_concept" and outcome.concept == "c2"
    assert served == [True]                             # the loop ran while the step worked
    assert threads and threads[0] != loop_thread


def test_rename_is_kept_in_the_file_and_used_by_recognition(lasa, tmp_path):
    agent = make_agent()
    agent.teach([lasa["GShape/0"], lasa["Angle/0"]])
    agent.rename("c1", "  my G ")
    assert agent.memory.concepts() == ["my G", "c2"]
    for bad, match in (("c2", "already named"), ("", "1 to 40"), ("a/b", "without '/'"),
                       ("x" * 41, "1 to 40"), ("new\nline", "printable")):
        with pytest.raises(InvalidInputError, match=match):
            agent.rename("my G", bad)
    with pytest.raises(InvalidInputError, match="no concept 'c9'"):
        agent.rename("c9", "x")
    agent.save(tmp_path / "m.npz")
    loaded = iloci.Agent.load(tmp_path / "m.npz")
    assert loaded.memory.concepts() == ["my G", "c2"]
    assert loaded.recognize(lasa["GShape/1"]).concept == "my G"
    loaded.rename("c2", "c3")                            # a name that looks like a label
    outcome = loaded.learn(lasa["Sine/0"])
    assert outcome.action == "new_concept" and outcome.concept == "c4"
