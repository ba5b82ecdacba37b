"""iloci-ros's transport-neutral core: drawings in, guesses with answer ids, stale ids refused.

No ROS needed: this is the object every transport adapter (ROS 1, ROS 2, a
web socket) drives. Real RNNPB (few epochs), real IK, real LASA drawings.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("iloci_ros", reason="the iloci-ros plugin is not installed")
pytest.importorskip("iloci_native")
pytest.importorskip("pinocchio")

from iloci.concepts.memory import entries_equal, load_memory  # noqa: E402
from iloci.errors import FeedbackError, InvalidDemonstrationError  # noqa: E402
from iloci_ros.session import Guess, Placed, StaleAnswerError, TeachingSession  # noqa: E402


def test_answer_ids_refuse_duplicate_late_and_unknown_feedback(lasa, small_agent, tmp_path):
    save = tmp_path / "m.npz"
    session = TeachingSession(small_agent(), save_to=save)
    first = session.drawing(lasa["GShape/0"].positions)
    assert isinstance(first, Placed) and first.action == "new_concept" and save.exists()
    assert session.pending is None
    with pytest.raises(StaleAnswerError, match="no answer is pending"):
        session.feedback("anything", 1)

    guess = session.drawing(lasa["Angle/0"].positions)
    assert isinstance(guess, Guess) and session.pending is guess
    assert guess.joint_path.shape[1] == 4 and guess.joint_names[0] == "RShoulderPitch"
    assert guess.to_dict()["answer_id"] == guess.answer_id
    with pytest.raises(FeedbackError):
        session.feedback(guess.answer_id, 0)            # bad value: still pending
    assert session.pending is guess
    with pytest.raises(StaleAnswerError, match=guess.answer_id):
        session.feedback("x-1", -1)
    placed = session.feedback(guess.answer_id, -1)      # only one concept: a new one
    assert isinstance(placed, Placed) and placed.action == "new_concept"
    saved = load_memory(save)[0]
    # the same feedback again (a bouncing button), and late: refused, nothing changes
    with pytest.raises(StaleAnswerError):
        session.feedback(guess.answer_id, -1)
    assert entries_equal(session.agent.memory.entries, saved.entries)
    assert session.agent.memory.demonstrations_seen == 2

    # a new drawing abandons the pending turn: its id goes stale
    g1 = session.drawing(lasa["GShape/1"].positions)
    g2 = session.drawing(lasa["GShape/2"].positions)
    assert g1.answer_id != g2.answer_id
    with pytest.raises(StaleAnswerError):
        session.feedback(g1.answer_id, 1)
    out = session.feedback(g2.answer_id, 1 if g2.concept == "c1" else -1)
    assert isinstance(out, (Guess, Placed))


def test_a_bad_drawing_keeps_the_pending_answer(lasa, small_agent):
    session = TeachingSession(small_agent())
    session.drawing(lasa["GShape/0"].positions)
    guess = session.drawing(lasa["Angle/0"].positions)
    with pytest.raises(InvalidDemonstrationError, match="zero extent"):
        session.drawing(np.zeros((30, 2)))
    assert session.pending is guess
    assert isinstance(session.feedback(guess.answer_id, -1), Placed)


def test_every_feedback_twice_and_some_late_leaves_the_memory_of_each_once(lasa, small_agent):
    """A stack that delivers every yes/no twice, and replays old ones late, learns what one
    that sent each once learns: the duplicates and late ones are refused."""
    stream = [lasa[k] for k in ("GShape/0", "Angle/0", "GShape/1", "Angle/1", "GShape/2")]

    def teach(bouncy: bool):
        session = TeachingSession(small_agent())
        sent, refused, resent = [], 0, 0
        for demo in stream:
            step = session.drawing(demo.positions)
            while isinstance(step, Guess):
                right = {"c1": "GShape", "c2": "Angle"}.get(step.concept) == demo.shape
                value = 1 if right else -1
                nxt = session.feedback(step.answer_id, value)
                sent.append((step.answer_id, value))
                if bouncy:
                    for answer_id, v in [(step.answer_id, value), *sent[:2]]:  # twice, late
                        resent += 1
                        try:
                            session.feedback(answer_id, v)
                        except StaleAnswerError:
                            refused += 1
                step = nxt
        return session.agent.memory, refused, resent

    once, _, _ = teach(False)
    twice, refused, resent = teach(True)
    assert refused == resent > 0                   # every duplicate and late one refused
    assert entries_equal(once.entries, twice.entries)
    assert (once.demonstrations_seen, once.concepts()) == (twice.demonstrations_seen,
                                                          twice.concepts())


def test_a_drawing_delivered_twice_or_late_is_not_learned_twice(lasa, small_agent):
    """A message delivered twice while its guess waits keeps that guess (its id stays the
    one to judge); delivered again after it was learned, with its key (the node's: the
    message's stamp), in float32 (a Point32) or re-stamped, it changes nothing."""
    session = TeachingSession(small_agent())
    session.drawing(lasa["GShape/0"].positions, key="drawing/1001")
    angle = lasa["Angle/0"]
    guess = session.drawing(angle.positions, angle.times, key="drawing/1002")
    again = session.drawing(angle.positions, angle.times, key="drawing/1002")
    assert again is guess and session.pending is guess
    placed = session.feedback(guess.answer_id, -1)
    assert placed.action == "new_concept"
    memory = session.agent.memory
    counts = (len(memory.entries), memory.demonstrations_seen,
              [e.num_samples for e in memory.entries])
    for positions, times in [(angle.positions, angle.times),
                             (angle.positions.astype(np.float32), angle.times),
                             (angle.positions, angle.times + 1.7e9)]:
        late = session.drawing(positions, times, key="drawing/1002")
        assert isinstance(late, Placed) and late.action == "already_learned"
        assert session.pending is None
    memory = session.agent.memory
    assert (len(memory.entries), memory.demonstrations_seen,
            [e.num_samples for e in memory.entries]) == counts
    assert sum(e.sources.count("drawing/1002") for e in memory.entries) == 1


def test_a_save_that_fails_says_so_with_the_drawing_learned(lasa, small_agent, tmp_path):
    """An audit: a memory path that could not be written gave the node's callback a raw
    traceback and no reply; the drawing was learned in the session only, without a word."""
    blocker = tmp_path / "afile"
    blocker.write_text("a file, where a folder was meant")
    session = TeachingSession(small_agent(), save_to=blocker / "m.npz")
    out = session.drawing(lasa["GShape/0"].positions, key="GShape/0")
    assert isinstance(out, Placed) and out.action == "new_concept"
    assert out.save_error and "could not save the memory to" in out.save_error
    assert "GShape/0 is learned in this session but not saved" in out.save_error
    assert out.to_dict()["save_error"] == out.save_error
    session.save_to = tmp_path / "m.npz"                   # the next placed drawing saves
    out = session.drawing(lasa["Angle/0"].positions, key="Angle/0")
    while isinstance(out, Guess):
        out = session.feedback(out.answer_id, -1)
    assert out.save_error is None and len(load_memory(tmp_path / "m.npz")[0]) == 2


def test_a_memory_file_replaced_under_the_session_is_not_saved_over(lasa, small_agent,
                                                                    tmp_path):
    """An audit: a memory file copied over while the node ran (another memory put in its
    place) was overwritten at the next drawing placed, without a word."""
    save = tmp_path / "m.npz"
    session = TeachingSession(small_agent(), save_to=save)
    assert session.drawing(lasa["GShape/0"].positions, key="GShape/0").save_error is None
    theirs = b"another memory, put here by hand"
    save.write_bytes(theirs)
    out = session.drawing(lasa["Angle/0"].positions, key="Angle/0")
    while isinstance(out, Guess):
        out = session.feedback(out.answer_id, -1)
    assert out.save_error and f"the memory file {save} was changed on disk" in out.save_error
    assert save.read_bytes() == theirs
    beside = [p for p in tmp_path.iterdir() if p.name.startswith("m.session-")]
    assert len(beside) == 1 and str(beside[0]) in out.save_error
    assert len(load_memory(beside[0])[0]) == 2
    # the session goes on saving there, and never over the file it left
    out = session.drawing(lasa["GShape/1"].positions, key="GShape/1")
    while isinstance(out, Guess):
        out = session.feedback(out.answer_id, 1 if out.concept == "c1" else -1)
    assert out.save_error is None and save.read_bytes() == theirs
    assert load_memory(beside[0])[0].demonstrations_seen == 3
